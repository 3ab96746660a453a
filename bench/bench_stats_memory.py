"""Falcon driver memory with the loop statistics (issue 21 item 1), a short measurement: the
in-process graph (driver, contact detector, force server; no visualizer, no recorder) runs for
``--seconds``; the process RSS and the number of recorded latencies are printed every ``--every``
seconds after a warm-up. ``--list`` also appends every latency to a plain list, as the statistics
did before (``_lat.append``), for contrast. The multi-process, every-node soak is
``bench/bench_soak.py``. Printed, never asserted.

    .venv/bin/python bench/bench_stats_memory.py [--seconds 120] [--list]
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from _page import run_with_page  # noqa: E402  (bench/ is sys.path[0])

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def rss_mb() -> float:
    with open('/proc/self/statm') as fh:
        return int(fh.read().split()[1]) * os.sysconf('SC_PAGE_SIZE') / 2**20


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--seconds', type=float, default=120.0)
    ap.add_argument('--every', type=float, default=20.0)
    ap.add_argument('--warmup', type=float, default=10.0)
    ap.add_argument('--list', action='store_true', help='also keep every latency in a list')
    a = ap.parse_args()
    from haptic_anfis.device.stats import LoopStats
    from haptic_anfis.session import open_graph
    if a.list:
        kept: list[float] = []
        real = LoopStats.latency

        def latency(self, seconds):
            kept.append(seconds)
            real(self, seconds)
        LoopStats.latency = latency
    print(f'driver memory, {"with" if a.list else "without"} a latency list, {a.seconds:g} s, '
          f'load average {os.getloadavg()[0]:.2f}')
    g = open_graph(program='bench')
    try:
        if not g.spin_for(60.0, lambda: g.driver.first_command is not None):
            raise RuntimeError('no force command within 60 s')
        g.spin_for(a.warmup)
        r0 = rss_mb()
        n0 = g.driver.servo.stats.summary()['latency_n']
        print(f'{"t s":>6} {"RSS MB":>8} {"growth MB":>10} {"latencies":>10}')
        t = 0.0
        while t < a.seconds:
            g.spin_for(a.every)
            t += a.every
            n = g.driver.servo.stats.summary()['latency_n'] - n0
            print(f'{t:>6.0f} {rss_mb():>8.1f} {rss_mb() - r0:>10.2f} {n:>10}')
    finally:
        g.shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(run_with_page(main, __file__, __doc__))
