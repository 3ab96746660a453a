"""Servo loop candidates (issue 32): where can a 1 kHz tick run so that nothing starves it?

Three candidates, each a 1 kHz loop of ``--ticks`` ticks with a little arithmetic per tick,
sleeping to absolute deadlines:

- ``python thread``: a Python loop on a thread of a process where two other threads keep the
  interpreter lock busy (as executors, a recorder and the garbage collector do);
- ``nogil thread``: the same loop compiled with numba ``nogil`` (libc ``clock_nanosleep`` /
  ``clock_gettime`` through the symbols :mod:`haptic_anfis.device.native_tick` registers), on a
  thread of a process with the same two busy threads;
- ``own process``: the Python loop alone in a process of its own (what a servo process with
  shared memory would run).

Each at SCHED_FIFO 50, under the normal scheduler, and under the normal scheduler with a 0.1 ms
time slice requested (:func:`haptic_anfis.realtime.scheduling.request_short_slice`), with ``--busy``
processes spinning beside it. Prints rate, periods lost and the longest gap, with the load, and
writes docs/measurements/servo_candidates.md.

Usage: ``python bench/bench_servo_candidates.py [--ticks 5000] [--busy 8]``
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from _busy import busy  # noqa: E402

SCHEDULING = ('fifo 50', 'normal', 'normal + slice')


def _numba_loop():
    import numba as nb

    from haptic_anfis.device import native_tick as nt

    @nb.njit(nogil=True, cache=True)
    def loop(ts, gaps, n):
        nt._clock_gettime(1, ts.ctypes.data)
        dl = ts[0] * 1000000000 + ts[1]
        last = dl
        x = 0.0
        for i in range(n):
            dl += 1000000
            ts[0], ts[1] = dl // 1000000000, dl % 1000000000
            nt._clock_nanosleep(1, 1, ts.ctypes.data, 0)
            nt._clock_gettime(1, ts.ctypes.data)
            now = ts[0] * 1000000000 + ts[1]
            gaps[i] = now - last
            last = now
            if now - dl > 1000000:
                dl = now
            for k in range(200):
                x += 1e-9 * k
        return x
    return loop


def _py_loop(gaps, n):
    dl = time.monotonic()
    last = dl
    for i in range(n):
        dl += 0.001
        d = dl - time.monotonic()
        if d > 0:
            time.sleep(d)
        now = time.monotonic()
        gaps[i] = (now - last) * 1e9
        last = now
        if now - dl > 0.001:
            dl = now
        x = 0.0
        for k in range(20):
            x += k


def _schedule(how: str) -> None:
    from haptic_anfis.realtime.scheduling import request_short_slice, set_realtime
    if how == 'fifo 50':
        set_realtime(50)
    elif how == 'normal + slice':
        request_short_slice()


def child(kind: str, how: str, n: int) -> None:
    """One measurement in this process; prints one JSON line."""
    gaps = np.zeros(n, dtype=np.int64 if kind == 'nogil thread' else np.float64)
    stop = [False]

    def hog():
        while not stop[0]:
            sum(range(20000))
    hogs = [] if kind == 'own process' else [threading.Thread(target=hog, daemon=True)
                                              for _ in range(2)]
    if kind == 'nogil thread':
        loop = _numba_loop()
        loop(np.zeros(2, np.int64), np.zeros(2, np.int64), 1)  # compile / load
        body = lambda: loop(np.zeros(2, np.int64), gaps, n)  # noqa: E731
    else:
        body = lambda: _py_loop(gaps, n)  # noqa: E731
    for h in hogs:
        h.start()
    th = threading.Thread(target=lambda: (_schedule(how), body()))
    th.start()
    th.join()
    stop[0] = True
    from haptic_anfis.device.stats import periods_lost_in
    g = np.asarray(gaps[1:], dtype=np.float64) / 1e6   # [ms]: in periods of 1 ms
    print(json.dumps({'rate_hz': 1000.0 * len(g) / g.sum(), 'max_gap_ms': float(g.max()),
                      'periods_lost': sum(periods_lost_in(x, 1.0) for x in g)}), flush=True)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--ticks', type=int, default=5000)
    ap.add_argument('--busy', type=int, default=8)
    ap.add_argument('--child', nargs=2, help=argparse.SUPPRESS)
    ap.add_argument('--no-page', action='store_true')
    a = ap.parse_args()
    if a.child:
        child(a.child[0], a.child[1], a.ticks)
        return 0
    import signal
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(1))
    from _page import write_page
    rows = []
    print(f'{"candidate":<14} {"scheduling":<15} {"busy":>4} {"load":>5} {"rate Hz":>8} '
          f'{"lost":>6} {"max gap ms":>10}', flush=True)
    for nbusy in (0, a.busy):
        for kind in ('python thread', 'nogil thread', 'own process'):
            for how in SCHEDULING:
                with busy(nbusy):
                    time.sleep(0.5)
                    r = subprocess.run([sys.executable, __file__, '--ticks', str(a.ticks),
                                        '--child', kind, how], capture_output=True, text=True,
                                       timeout=600)
                    load = os.getloadavg()[0]
                try:
                    j = json.loads(r.stdout.strip().splitlines()[-1])
                except (ValueError, IndexError):
                    j = {'rate_hz': float('nan'), 'max_gap_ms': float('nan'),
                         'periods_lost': -1}
                    print(r.stderr[-400:], flush=True)
                row = (kind, how, nbusy, load, j['rate_hz'], j['periods_lost'], j['max_gap_ms'])
                rows.append(row)
                print(f'{kind:<14} {how:<15} {nbusy:>4} {load:>5.1f} {row[4]:>8.1f} '
                      f'{row[5]:>6} {row[6]:>10.2f}', flush=True)
    table = ('| candidate | scheduling | busy | load | rate Hz | periods lost | max gap ms |\n'
             '|---|---|---|---|---|---|---|\n'
             + ''.join(f'| {k} | {h} | {b} | {ld:.1f} | {r:.1f} | {lo} | {g:.2f} |\n'
                       for k, h, b, ld, r, lo, g in rows))
    notes = (f'\n{a.ticks} ticks at 1 kHz per row. `python thread` and `nogil thread`: two other '
             'threads of the process keep the interpreter lock busy; `own process`: the loop '
             'alone in a process. `busy`: processes spinning beside it; `load`: the 1-minute '
             'load average after the row (the machine is shared: other users add to it). '
             '`normal + slice`: the normal scheduler with a 0.1 ms time slice requested '
             '(sched_setattr, no privilege needed).\n')
    if not a.no_page:
        print('page:', write_page('servo_candidates', 'Servo loop candidates', table + notes))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
