"""``haptic-anfis view BAG``: the debrief of a recorded session in a browser (``haptic_anfis.view``).

Also the small hooks the session commands call for ``--view`` (``sim --view``, ``exam run
--view``): :func:`add_view_arguments`, :func:`web_view_arguments` (the web_view node's ROS
arguments for a side process) and :func:`exam_debrief` (the end of ``exam run --view``: the page
turns into the debrief of the exam just run, on the same URL).
"""
from __future__ import annotations

import argparse
import math

NAME = 'view'
HELP = ("the trainee's screen in a browser: the debrief of a recorded session (coverage per "
        'level, path, marks, lesions revealed, score, replay)')

DEFAULT_PORT = 8080


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument('bag', metavar='BAG', help='recorded session (haptic-anfis sim / exam run '
                   '--record, or the recorder node)')
    p.add_argument('--case', default=None, metavar='NAME',
                   help='case of the library (its surface and lesions) or a scene file the '
                        'session is scored against (default: default)')
    p.add_argument('--port', type=int, default=DEFAULT_PORT,
                   help=f'TCP port of the page (default {DEFAULT_PORT})')
    p.add_argument('--host', default='127.0.0.1',
                   help="address to listen on (default 127.0.0.1; '0.0.0.0' for other machines)")
    p.add_argument('--exam-config', metavar='YAML', default=None,
                   help='scoring settings (default config/exam.yaml)')
    p.add_argument('--trainee', default='', metavar='ID',
                   help="show this trainee's history beside the debrief (with the trainee record)")
    p.add_argument('--duration', type=float, default=None,
                   help='serve this many seconds, then exit (default: until Ctrl-C)')


def run(args: argparse.Namespace) -> int:
    if args.duration is not None and not (args.duration > 0 and math.isfinite(args.duration)):
        raise ValueError(f'--duration: expected > 0 s, got {args.duration}')
    from ..view.build import open_bag_view, serve
    app = open_bag_view(args.bag, args.case, args.port, args.host, args.exam_config,
                        args.trainee)
    n = app.debrief.numbers()
    print(f"debrief of {args.bag}: score {n['score']} ({n['verdict']}), hits {n['hits']}, "
          f"misses {n['misses']}, false marks {n['false_marks']}", flush=True)
    print(f'open {app.url} in a browser (Ctrl-C to stop)', flush=True)
    serve(app, args.duration)
    return 0


# -- hooks for the session commands (sim, exam run; launch starts the web_view node itself) ----

def add_view_arguments(p: argparse.ArgumentParser, hold: bool = False) -> None:
    """``--view`` and ``--view-port`` (and, with ``hold``, ``--view-hold``) on a command."""
    p.add_argument('--view', action='store_true',
                   help="open the trainee's screen in a browser (the web_view node in a process "
                        'of its own)')
    p.add_argument('--view-port', type=int, default=DEFAULT_PORT,
                   help=f'TCP port of the page with --view (default {DEFAULT_PORT})')
    if hold:
        p.add_argument('--view-hold', type=float, default=None, metavar='S',
                       help='with --view: serve the debrief this many seconds after the exam '
                            '(default: until Ctrl-C)')


def web_view_arguments(args: argparse.Namespace, common: list[str],
                       controls: bool = True) -> list[str] | None:
    """The web_view node's ``--ros-args`` arguments for ``args`` (None without ``--view``):
    ``common`` (parameter files, case) plus its port. Checks the port first (one line naming
    it when it is in use)."""
    if not getattr(args, 'view', False):
        return None
    from ..view.app import check_port
    check_port(args.view_port)
    return [*common, '-p', f'port:={int(args.view_port)}',
            '-p', f"controls:={'true' if controls else 'false'}"]


def start_side_view(args: argparse.Namespace, common: list[str], timeout: float = 300.0):
    """With ``--view``: the web_view node started in a process of its own (a
    :class:`~haptic_anfis.nodes.side_nodes.SideNodes`, started), else None."""
    wv = web_view_arguments(args, common, controls=False)
    if wv is None:
        return None
    from ..nodes.side_nodes import SideNodes
    side = SideNodes({'web_view': wv})
    side.start(timeout)
    print(f'view: open http://127.0.0.1:{args.view_port}/ in a browser', flush=True)
    return side


def exam_debrief(args: argparse.Namespace, report: dict, session, side=None) -> None:
    """After ``exam run --view``: stop the live page's node (``side``), then serve the debrief
    of ``report`` / ``session`` on the same port (the open page reconnects to it) for
    ``--view-hold`` seconds or until Ctrl-C."""
    if not getattr(args, 'view', False):
        return
    if side is not None:
        side.stop()
    from ..view.app import ViewApp
    from ..view.build import serve
    from ..view.debrief import Debrief
    import time
    end = time.monotonic() + 10.0
    while True:   # the node's process has just released the port
        try:
            app = ViewApp(session.surface.vertices, session.surface.faces,
                          session.grid.faces_index, session.config.thresholds,
                          port=args.view_port, title='haptic_anfis debrief')
            break
        except ValueError:
            if time.monotonic() > end:
                raise
            time.sleep(0.2)
    app.show_debrief(Debrief(report, session))
    print(f'debrief at {app.url} (Ctrl-C to stop)', flush=True)
    serve(app, getattr(args, 'view_hold', None))
