"""Servo tick workers under load (issue 32): the compiled loop alone, one worker or two.

The compiled servo loop (``NativeServoLoop``, simulated Falcon, no ROS) runs beside ``--busy``
processes spinning on the machine's cores, under the normal scheduler (no real-time priority), on
a thread of this process or in a servo process of its own session, with 1 or 2 tick workers
(``workers``: threads serving one schedule, each pinned to its own core; the first to wake runs
the tick). Each configuration runs ``--repeat`` times, interleaved, for ``--duration`` seconds;
it prints the periods lost (1 ms periods with no tick, % of the periods) and the longest time
between two ticks, as the median and the worst of the repeats.

Why: under the normal scheduler a thread that wakes on a busy core is sometimes not run for
milliseconds (here up to 80-130 ms: a core held by a long kernel path or another task), which no
single thread can avoid; two workers on two cores are rarely both held.

Usage: ``python bench/bench_servo_wake.py [--duration 15] [--busy 8] [--repeat 4]
[--background-sim] [--busy-sessions] [--page servo_wake] [--no-page]``.
``--busy-sessions``: each busy process in a session of its own, as other programs on a desktop
are (Linux's autogroup then gives each its own fair share; by default they share this one's).
``--background-sim``: a ``haptic-anfis sim`` session (with the recorder) runs beside it too, as
a second trainee's session would. Writes ``docs/measurements/<page>.md``.
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / 'bench'))

import numpy as np  # noqa: E402

from haptic_anfis.device import HandParams, WorkspaceMapping  # noqa: E402
from haptic_anfis.device.palpation import PalpationScript  # noqa: E402
from haptic_anfis.device.servo_native import NativeServoLoop  # noqa: E402

from _busy import busy  # noqa: E402

CONFIGS = (('thread', 1), ('thread', 2), ('process', 1), ('process', 2))


def still() -> PalpationScript:
    p = (0.06, 0.0, 0.0)
    return PalpationScript(np.array([0.0, 1.0]), np.array([p, p]), np.array([False]), loop=True)


def one(kind: str, workers: int, duration: float) -> tuple[float, float, int]:
    """(periods lost %, longest gap ms, ticks taken over) of one run of ``duration`` s after a
    1 s start."""
    lp = NativeServoLoop(still(), WorkspaceMapping(1.5, (0.03, 0.0, 0.0), 1.0), HandParams(),
                         process=kind == 'process', workers=workers)
    lp.start()
    try:
        time.sleep(1.0)
        lp.stats.reset()
        time.sleep(duration)
        s = lp.stats.summary()
    finally:
        lp.stop()
    periods = s['ticks'] + s['periods_lost']
    return (100.0 * s['periods_lost'] / max(periods, 1), s['max_gap_ms'],
            s['ticks_taken_over'])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--duration', type=float, default=15.0)
    ap.add_argument('--busy', type=int, default=8)
    ap.add_argument('--repeat', type=int, default=4)
    ap.add_argument('--background-sim', action='store_true',
                    help='a haptic-anfis sim session with the recorder beside it as well')
    ap.add_argument('--busy-sessions', action='store_true',
                    help='each busy process in a session of its own (other programs)')
    ap.add_argument('--page', default='servo_wake',
                    help='page name: docs/measurements/<page>.md (default servo_wake)')
    ap.add_argument('--no-page', action='store_true', help='print only')
    a = ap.parse_args()
    results: dict[tuple[str, int], list[tuple[float, float, int]]] = {c: [] for c in CONFIGS}
    with busy(a.busy, a.busy_sessions), tempfile.TemporaryDirectory(prefix='bench-wake-') as td:
        bg = None
        try:
            if a.background_sim:
                bg = subprocess.Popen(
                    [sys.executable, '-m', 'haptic_anfis.cli', 'sim', '--duration', '100000',
                     '--record', str(Path(td) / 'bag')], stdout=subprocess.DEVNULL,
                    stderr=subprocess.DEVNULL, env=dict(os.environ, PYTHONPATH=str(ROOT)))
                time.sleep(20.0)  # its graph up and pressing
            for r in range(a.repeat):
                for c in CONFIGS:
                    results[c].append(one(*c, a.duration))
                    print(f'run {r + 1}/{a.repeat} {c[0]:>7} workers {c[1]}: lost '
                          f'{results[c][-1][0]:.2f} %, max gap {results[c][-1][1]:.2f} ms, '
                          f'taken over {results[c][-1][2]}', flush=True)
        finally:
            if bg is not None:
                bg.terminate()
                bg.wait(30)
    lines = ['| loop | workers | lost % median | lost % worst | max gap ms median | '
             'max gap ms worst | taken over |', '|---|---|---|---|---|---|---|']
    for (kind, w), rs in results.items():
        lost, gap = [x[0] for x in rs], [x[1] for x in rs]
        lines.append(f'| {kind} | {w} | {statistics.median(lost):.2f} | {max(lost):.2f} | '
                     f'{statistics.median(gap):.2f} | {max(gap):.2f} | {sum(x[2] for x in rs)} |')
    table = '\n'.join(lines)
    print(table)
    if not a.no_page:
        from _page import write_page
        notes = (f'\n\n{a.repeat} runs of {a.duration:g} s per configuration, interleaved, '
                 f'beside {a.busy} busy processes'
                 + (' (each in a session of its own)' if a.busy_sessions else
                    ' (in this session)')
                 + (' and a `haptic-anfis sim` session with the recorder' if a.background_sim
                    else '') + f' on the machine\'s {os.cpu_count()} cores; the normal scheduler '
                 '(no real-time priority; a 0.1 ms time slice requested). `thread`: the '
                 'compiled loop on threads of this process; `process`: in a servo process of its '
                 'own session. `workers`: threads serving the one schedule, each pinned to its '
                 'own core. Lost: 1 ms periods with no tick. Taken over: ticks one worker '
                 'computed again, all runs together, because the other, preempted in the middle '
                 'of its tick, had not committed it a period after claiming it. Target (issue 32): '
                 'rate >= 995 Hz '
                 '(lost <= 0.5 %), no gap longer than the 10 ms watchdog.\n')
        cmd = ('.venv/bin/python bench/bench_servo_wake.py ' + ' '.join(sys.argv[1:])).strip()
        print('page:', write_page(a.page, 'Servo tick workers under load', table + notes,
                                  command=cmd))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
