"""``haptic-anfis view BAG``: the debrief of a recorded session in a browser (``haptic_anfis.view``).

Also :func:`exam_debrief`, the end of ``exam run --view``: the page turns into the debrief of the
exam just run, on the same URL (``--view`` itself is a session option: :mod:`haptic_anfis.session`
starts the web_view node beside ``sim``, ``exam run`` and ``launch``).
"""
from __future__ import annotations

import argparse
import math
import time

from ..cases.library import add_case_dir_argument, use_case_dir
from ..view.app import ViewApp
from ..view.build import open_bag_view, serve
from ..view.debrief import Debrief

NAME = 'view'

DEFAULT_PORT = 8080


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument('bag', metavar='BAG', help='recorded session (haptic-anfis sim / exam run '
                   '--record, or the recorder node)')
    p.add_argument('--case', default=None, metavar='NAME',
                   help='case of the library (its surface and lesions) or a scene file (its '
                        'lesions) the session is scored against (default: the one the bag was '
                        'recorded with; the default case for a bag that does not say)')
    add_case_dir_argument(p)
    p.add_argument('--port', type=int, default=DEFAULT_PORT,
                   help=f'TCP port of the page (default {DEFAULT_PORT})')
    p.add_argument('--host', default='127.0.0.1',
                   help="address to listen on (default 127.0.0.1; '0.0.0.0' for other machines)")
    p.add_argument('--exam-config', metavar='YAML', default=None,
                   help='scoring settings (default config/exam.yaml)')
    p.add_argument('--trainee', default='', metavar='ID',
                   help="show this trainee's history beside the debrief (from the trainee record)")
    p.add_argument('--db', default=None, metavar='PATH',
                   help='the trainee record file (default $HAPTIC_ANFIS_DB, else '
                        '$XDG_DATA_HOME/haptic_anfis/trainees.sqlite)')
    p.add_argument('--duration', type=float, default=None,
                   help='serve this many seconds, then exit (default: until Ctrl-C)')


def run(args: argparse.Namespace) -> int:
    use_case_dir(args.case_dir)   # before anything reads the library; the nodes inherit it
    if args.duration is not None and not (args.duration > 0 and math.isfinite(args.duration)):
        raise ValueError(f'--duration: expected > 0 s, got {args.duration}')
    app = open_bag_view(args.bag, args.case, args.port, args.host, args.exam_config,
                        args.trainee, args.db)
    n = app.debrief.numbers()
    print(f"debrief of {args.bag}: score {n['score']} ({n['verdict']}), hits {n['hits']}, "
          f"misses {n['misses']}, false marks {n['false_marks']}", flush=True)
    print(f'open {app.url} in a browser (Ctrl-C to stop)', flush=True)
    serve(app, args.duration)
    return 0


# -- the end of exam run --view (sim / exam run / launch start the web_view node through the
# session room: haptic_anfis.session, the --view options) ----------------------------------

def exam_debrief(args: argparse.Namespace, report: dict, session) -> None:
    """After ``exam run --view`` (the live page's node stopped with the session): serve the
    debrief of ``report`` / ``session`` (an :class:`~haptic_anfis.exam.session.ExamSession`) on the same
    port (the open page reconnects to it) for ``--view-hold`` seconds or until Ctrl-C. It is the
    trainee's page: no trainee history there (the instructor's ``view BAG --trainee ID``, or
    ``trainees show``, has it)."""
    if not getattr(args, 'view', False):
        return
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
    # the trainee's page: the debrief alone, never the record (an earlier blind case's name)
    app.show_debrief(Debrief(report, session))
    print(f'debrief at {app.url} (Ctrl-C to stop)', flush=True)
    serve(app, getattr(args, 'view_hold', None))
