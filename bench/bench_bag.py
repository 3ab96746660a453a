"""Bag benchmark: recording overhead on the 1 kHz loop, bag write and read throughput.

  1. the in-process graph (no visualizer) for --seconds, without and then with the recorder
     (all loop topics) in the same run: servo rate, pose -> wrench latency p50/p99/max
  2. BagWriter throughput: PoseStamped CDR messages queued from the caller, written by the thread
  3. read throughput: raw (CDR bytes) and deserialised (rosbags), and re-simulation speed
Printed, never asserted (shared machine).

    .venv/bin/python bench/bench_bag.py [--seconds 5]
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path
from harness import run_with_page  # noqa: E402  (bench/ is sys.path[0])

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def loop_run(seconds: float, bag: Path | None) -> tuple[dict, dict | None]:
    from haptic_anfis.bag.topics import ALL_LOOP_TOPICS
    from haptic_anfis.session import open_graph
    from haptic_anfis.nodes.recorder import Recorder
    extra = [lambda ctx: Recorder(context=ctx, output=str(bag), topics=ALL_LOOP_TOPICS)] if bag else []
    g = open_graph(extra=extra, program='bench')
    try:
        if not g.spin_for(30.0, lambda: g.driver.first_command is not None):
            raise RuntimeError('no force command within 30 s')
        g.driver.servo.stats.reset()
        g.spin_for(seconds)
        s = g.driver.summary()
    finally:
        g.shutdown()
    return s, (g.extra[0].summary() if bag else None)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--seconds', type=float, default=5.0)
    ap.add_argument('--messages', type=int, default=50_000)
    a = ap.parse_args()
    from haptic_anfis.bag import BagWriter, read_messages
    from haptic_anfis.nodes.resim import resimulate
    from haptic_anfis.bag.topics import typestore
    print(f'bag benchmark, {a.seconds:g} s per loop run, {os.cpu_count()} CPUs, '
          f'load average {os.getloadavg()[0]:.2f}')
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        print(f'{"1 kHz loop, one process":<28} {"rate Hz":>8} {"p50 ms":>8} {"p99 ms":>8} '
              f'{"max ms":>8} {"misses":>7} {"recorded":>9} {"dropped":>8}')
        for name, bag in (('without recorder', None), ('with recorder', tmp / 'loop'),
                          ('without recorder (again)', None)):
            s, r = loop_run(a.seconds, bag)
            print(f'{name:<28} {s["rate_hz"]:>8.1f} {s["latency_p50_ms"]:>8.3f} '
                  f'{s["latency_p99_ms"]:>8.3f} {s["latency_max_ms"]:>8.3f} '
                  f'{s["deadline_misses"]:>7} {r["written"] if r else "-":>9} '
                  f'{r["dropped"] if r else "-":>8}')
        if (tmp / 'loop').exists():
            r = resimulate(tmp / 'loop')
            print(f're-simulation of the recorded loop: {r.wrenches} wrenches, max |dF| '
                  f'{r.max_diff_N:.3g} N')

        ts = typestore()
        P = ts.types['geometry_msgs/msg/PoseStamped']
        H, T = ts.types['std_msgs/msg/Header'], ts.types['builtin_interfaces/msg/Time']
        Po, Pt, Q = (ts.types[f'geometry_msgs/msg/{n}'] for n in ('Pose', 'Point', 'Quaternion'))
        data = ts.serialize_cdr(P(H(T(1, 2), 'tissue'), Po(Pt(0.01, 0.02, 0.03),
                                                           Q(0.0, 0.0, 0.0, 1.0))), P.__msgtype__)
        n = a.messages
        path = tmp / 'throughput'
        t0 = time.perf_counter()
        w = BagWriter(path)
        w.add_topic('/falcon/measured_cp', P.__msgtype__)
        t1 = time.perf_counter()
        for i in range(n):
            w.write('/falcon/measured_cp', data, 1_000_000_000 + i * 1000)
        t2 = time.perf_counter()
        w.close()
        t3 = time.perf_counter()
        size = sum(f.stat().st_size for f in path.iterdir())
        print(f'write: {n} PoseStamped ({len(data)} B CDR): enqueue {(t2 - t1) / n * 1e6:.2f} µs/msg '
              f'({n / (t2 - t1):.3g} msg/s from the caller), written to disk {n / (t3 - t1):.3g} msg/s '
              f'({size / 2**20:.1f} MiB)')
        t0 = time.perf_counter()
        k = sum(1 for _ in read_messages(path, deserialize=False))
        t1 = time.perf_counter()
        k2 = sum(1 for _ in read_messages(path))
        t2 = time.perf_counter()
        print(f'read: raw {k / (t1 - t0):.3g} msg/s, deserialised {k2 / (t2 - t1):.3g} msg/s')
    return 0


if __name__ == '__main__':
    sys.exit(run_with_page(main, __file__, __doc__))
