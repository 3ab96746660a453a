"""Graph pinning against the servo loop: `launch` with each node kept on one CPU, or free (issue 32).

``launch --record`` with the graph's nodes under the normal scheduler (``--graph-priority 0``, as
on an account without an rtprio limit), the browser view (``--view``) and ``--busy`` processes
spinning in this benchmark's session, run in interleaved pairs: ``--graph-pinning on`` (every
node on the haptic path kept on one CPU) and ``off`` (free), ``--repeat`` times, for each servo
priority of ``--servo-priorities`` (0: the servo under the normal scheduler too; 50: real-time).
The rows are ``bench_servo_load``'s (the last ``--duration`` s of each run after ``--settle``);
then the median of each arm. This is what ``--graph-pinning auto`` (launch's default) rests on:
which arm keeps the servo's period and the models fresh, with the servo real-time and without.

Usage: ``python bench/bench_graph_pinning.py [--repeat 3] [--busy 8] [--servo-priorities 0,50]``.
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _busy import busy  # noqa: E402
from _page import markdown_table, run_with_page  # noqa: E402
from bench_servo_load import account, fmt, row, run_one  # noqa: E402

ARMS = ('on', 'off')
COLS = ('config', 'load', 'rate_hz', 'periods_lost', 'max_gap_ms', 'err_rms_pct', 'ripple_pct',
        'ripple_ideal_pct', 'zero_ticks', 'expired', 'held', 'beyond', 'lat_p99_ms',
        'lat_max_ms', 'sched')
#: the columns whose median per arm is printed
MEDIAN_COLS = ('rate_hz', 'periods_lost', 'max_gap_ms', 'err_rms_pct', 'ripple_pct', 'held',
               'lat_p99_ms')


def medians(rows: list[dict]) -> list[dict]:
    """One row per configuration: the median of each of :data:`MEDIAN_COLS` over its runs."""
    out = []
    for name in dict.fromkeys(r['config'] for r in rows):
        runs = [r for r in rows if r['config'] == name and not r.get('error')]
        m = {'config': name, 'runs': len(runs)}
        for c in MEDIAN_COLS:
            vals = [r[c] for r in runs if r.get(c) is not None]
            m[c] = round(statistics.median(vals), 2) if vals else None
        out.append(m)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--repeat', type=int, default=3, help='pairs per servo priority (default 3)')
    ap.add_argument('--busy', type=int, default=8)
    ap.add_argument('--servo-priorities', default='0,50')
    ap.add_argument('--duration', type=float, default=15.0)
    ap.add_argument('--settle', type=float, default=10.0)
    ap.add_argument('--no-view', action='store_true', help='without the browser view')
    ap.add_argument('--page', default='graph_pinning')
    ap.add_argument('--arms', default=','.join(ARMS),
                    help="launch's --graph-pinning values to compare, interleaved (default on,off)")
    a = ap.parse_args()
    prios = [int(p) for p in a.servo_priorities.split(',') if p]
    arms = [x for x in a.arms.split(',') if x]
    print(account())
    print(f'{a.busy} busy processes in this benchmark\'s session; browser view '
          f'{"off" if a.no_view else "on"}; {a.duration:g} s after {a.settle:g} s per run; '
          f'{os.cpu_count()} CPUs')
    rows = []
    with tempfile.TemporaryDirectory(prefix='graph_pinning_') as tmp:
        d = Path(tmp)
        for i in range(a.repeat):
            for prio in prios:
                for arm in (arms if i % 2 == 0 else arms[::-1]):  # no arm always first
                    with busy(a.busy):
                        time.sleep(1.0)
                        load = os.getloadavg()[0]
                        j = run_one('launch', prio, a.duration, 'auto', d, view=not a.no_view,
                                    settle=a.settle, launch_args=(
                                        '--graph-priority', '0', '--graph-pinning', arm))
                        load = max(load, os.getloadavg()[0])
                    r = row(f'servo {prio}, pinning {arm}', a.busy, load, j)
                    rows.append(r)
                    print(' '.join(f'{fmt(r.get(c))}' for c in COLS), flush=True)
                    if r.get('error'):
                        print('  ', r['error'], flush=True)
    print('\nevery run (columns as bench_servo_load\'s: the last --duration s of each run)')
    print(markdown_table(rows, COLS, fmt))
    print('\nthe median of each arm')
    print(markdown_table(medians(rows), ('config', 'runs', *MEDIAN_COLS), fmt))
    return 0


if __name__ == '__main__':
    sys.exit(run_with_page(main, __file__, __doc__,
                           name=next((sys.argv[i + 1] for i, x in enumerate(sys.argv[:-1])
                                      if x == '--page'), 'graph_pinning')))
