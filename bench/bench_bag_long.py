"""Long-session bag benchmark (issue 21): bag size per hour, MCAP chunk compression, and the
player's memory on a long bag.

A session is synthesised with the recorder's own writer (:class:`haptic_anfis.bag.BagWriter`) at
the 1 kHz loop's message mix when every pose is answered — pose, twist, contact and force command
at 1 kHz, applied force at 100 Hz, buttons at 10 Hz (4110 msg/s, what ``sim --record`` records) —
with values that move like a palpation (smooth probe path + sensor noise, so compression is not
flattered by repeated bytes); no need to run the loop for half an hour.

  1. compression: for none / zstd (level 1) / lz4, ``--compress-minutes`` of session written from
     messages prepared in memory: bag size -> MB per hour, the writing CPU (enqueue + writer
     thread, process CPU time) as a fraction of one core at the loop's rate, the CPU time of a
     chunk flush (compression runs there, in the writer thread; thread CPU time, so the machine's
     load does not inflate it)
  2. a ``--minutes`` (default 30) session written with the default compression; then the player's
     streaming read (the code path of ``player``: ``haptic_anfis.bag.playback.schedule``) over the
     whole bag in a fresh process, RSS sampled as it goes; and, for contrast, the old way (every
     message loaded into a list) over ``--list-minutes`` of it
Printed, never asserted (shared machine).

    .venv/bin/python bench/bench_bag_long.py [--minutes 30] [--compress-minutes 2]
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from harness import run_with_page  # noqa: E402  (bench/ is sys.path[0])

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

RATE = 1000  # servo ticks per second
MIX = {'pose': 1, 'twist': 1, 'contact': 1, 'command': 1, 'applied': 10, 'buttons': 100}


class Templates:
    """CDR templates of the loop's messages with the byte offsets of their numeric fields, so a
    message costs a bytearray copy and a few ``struct.pack_into`` (serialising each through
    rosbags would make a 30-minute bag take an hour)."""

    def __init__(self):
        from haptic_anfis import interfaces as ifc
        from haptic_anfis.bag.topics import absolute, typestore
        ts = typestore()
        T = ts.types
        H, Tm = T['std_msgs/msg/Header'], T['builtin_interfaces/msg/Time']
        V3 = T['geometry_msgs/msg/Vector3']
        S = iter(range(1000, 2000))  # distinct sentinels, found again in the bytes

        def h():
            return H(Tm(0x5EC0_0001, 0x0A0B_0C0D), 'tissue')

        def f():
            return float(next(S)) + 0.25
        P = T['geometry_msgs/msg/PoseStamped']
        pose = P(h(), T['geometry_msgs/msg/Pose'](T['geometry_msgs/msg/Point'](f(), f(), f()),
                                                  T['geometry_msgs/msg/Quaternion'](0.0, 0.0, 0.0,
                                                                                    1.0)))
        tw = T['geometry_msgs/msg/TwistStamped'](h(), T['geometry_msgs/msg/Twist'](
            V3(f(), f(), f()), V3(0.0, 0.0, 0.0)))
        W = T['geometry_msgs/msg/WrenchStamped']
        cmd = W(h(), T['geometry_msgs/msg/Wrench'](V3(f(), f(), f()), V3(0.0, 0.0, 0.0)))
        app = W(h(), T['geometry_msgs/msg/Wrench'](V3(f(), f(), f()), V3(0.0, 0.0, 0.0)))
        js = T['sensor_msgs/msg/JointState'](h(), list(ifc.CONTACT_FIELDS),
                                             np.array([f() for _ in ifc.CONTACT_FIELDS]),
                                             np.zeros(0), np.zeros(0))
        joy = T['sensor_msgs/msg/Joy'](h(), np.zeros(3, dtype=np.float32),
                                       np.array([0, 0, 0, 0], dtype=np.int32))
        self.topics = {'pose': (absolute(ifc.TOPIC_POSE), pose), 'twist': (absolute(ifc.TOPIC_TWIST), tw),
                       'contact': (absolute(ifc.TOPIC_CONTACT), js),
                       'command': (absolute(ifc.TOPIC_COMMAND), cmd),
                       'applied': (absolute(ifc.TOPIC_APPLIED), app),
                       'buttons': (absolute(ifc.TOPIC_BUTTONS), joy)}
        self.raw, self.offsets, self.types = {}, {}, {}
        for k, (topic, m) in self.topics.items():
            b = bytes(ts.serialize_cdr(m, type(m).__msgtype__))
            self.raw[k] = b
            self.types[k] = type(m).__msgtype__
            stamp = b.find(struct.pack('<iI', 0x5EC0_0001, 0x0A0B_0C0D))
            floats = []
            for s in range(1000, 2000):
                i = b.find(struct.pack('<d', s + 0.25))
                if i >= 0:
                    floats.append(i)
            self.offsets[k] = (stamp, floats)

    def make(self, k: str, t_ns: int, values) -> bytes:
        b = bytearray(self.raw[k])
        stamp, floats = self.offsets[k]
        struct.pack_into('<iI', b, stamp, t_ns // 1_000_000_000, t_ns % 1_000_000_000)
        for off, v in zip(floats, values):
            struct.pack_into('<d', b, off, v)
        return bytes(b)


def session(tpl: Templates, seconds: float, seed: int = 0, t0_ns: int = 1_700_000_000 * 10**9):
    """Yield ``(topic, t_ns, cdr bytes)`` of a synthetic palpation session, block by block."""
    rng = np.random.default_rng(seed)
    n = int(seconds * RATE)
    block = 10_000
    for b0 in range(0, n, block):
        k = np.arange(b0, min(b0 + block, n))
        t = k / RATE
        # probe path: slow circles over the surface + presses (m), with 20 µm sensor noise
        pos = np.stack([0.045 + 0.008 * np.sin(2 * np.pi * 0.4 * t) ** 2 - 0.004,
                        0.03 * np.sin(2 * np.pi * 0.05 * t), 0.03 * np.cos(2 * np.pi * 0.07 * t)],
                       axis=1) + rng.normal(0, 2e-5, (len(k), 3))
        vel = np.gradient(pos, 1.0 / RATE, axis=0)
        depth = np.clip(0.049 - pos[:, 0], 0, None)
        force = np.stack([depth * 400.0, depth * 20.0, -depth * 15.0], axis=1) \
            + rng.normal(0, 1e-3, (len(k), 3))
        for i, ki in enumerate(k):
            t_ns = t0_ns + int(ki) * 1_000_000
            yield tpl.topics['pose'][0], t_ns, tpl.make('pose', t_ns, pos[i])
            yield tpl.topics['twist'][0], t_ns + 5000, tpl.make('twist', t_ns, vel[i])
            c = (pos[i, 0], pos[i, 1], pos[i, 2], depth[i], -1.0, 0.0, 0.0,
                 1.0 if depth[i] > 0 else 0.0, 0.0)
            yield tpl.topics['contact'][0], t_ns + 150_000, tpl.make('contact', t_ns, c)
            yield tpl.topics['command'][0], t_ns + 300_000, tpl.make('command', t_ns, force[i])
            if ki % MIX['applied'] == 0:
                yield tpl.topics['applied'][0], t_ns + 10_000, tpl.make('applied', t_ns, force[i])
            if ki % MIX['buttons'] == 0:
                yield tpl.topics['buttons'][0], t_ns + 20_000, tpl.make('buttons', t_ns, ())


def write_session(path: Path, seconds: float, compression: str, messages=None) -> dict:
    """Write a synthetic session (or ``messages``, prepared); sizes and CPU of the writing."""
    from haptic_anfis.bag import BagWriter
    from haptic_anfis.bag import segment as seg_mod
    tpl = Templates()
    flush_times = []
    real_flush = seg_mod.Segment.flush

    def timed_flush(self):  # bench-only: CPU of one chunk close (+ compression), writer thread
        t = time.thread_time()
        real_flush(self)
        flush_times.append(time.thread_time() - t)
    seg_mod.Segment.flush = timed_flush
    try:
        w = BagWriter(path, compression=compression)
        for k in MIX:
            w.add_topic(tpl.topics[k][0], tpl.types[k])
        src = messages if messages is not None else session(tpl, seconds)
        cpu0, wall0 = time.process_time(), time.perf_counter()
        n = 0
        for topic, t_ns, data in src:
            w.write(topic, data, t_ns)
            n += 1
            if n % 20_000 == 0:
                while w.pending > 50_000:  # pace the producer to the writer (never drop)
                    time.sleep(0.01)
        w.close()
        cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
    finally:
        seg_mod.Segment.flush = real_flush
    size = sum(f.stat().st_size for f in path.iterdir())
    return {'messages': n, 'dropped': w.dropped, 'bytes': size, 'cpu_s': cpu, 'wall_s': wall,
            'flush_max_ms': max(flush_times) * 1e3, 'flush_p99_ms':
            float(np.percentile(flush_times, 99)) * 1e3, 'chunks': len(flush_times)}


def gil_stall(name: str, nbytes: int = 16_000_000) -> tuple[float, float]:
    """(seconds one compress of ``nbytes`` of noisy doubles took, the longest gap [s] between
    wake-ups of another thread sleeping 0.2 ms meanwhile): a compressor that holds the GIL stalls
    every other thread of the process (the servo thread included) for the whole call."""
    import threading

    from haptic_anfis.bag.segment import compressor
    data = np.random.default_rng(0).normal(size=nbytes // 8).astype('<f8').tobytes()
    fn = compressor(name)[1]
    done, ticks = threading.Event(), []

    def spin():
        while not done.is_set():
            ticks.append(time.perf_counter())
            time.sleep(0.0002)
    th = threading.Thread(target=spin)
    th.start()
    time.sleep(0.01)
    t0 = time.perf_counter()
    fn(data)
    t1 = time.perf_counter()
    done.set()
    th.join()
    inside = [t0] + [x for x in ticks if t0 <= x <= t1] + [t1]
    return t1 - t0, float(np.max(np.diff(inside)))


def rss_mb() -> float:
    with open('/proc/self/statm') as fh:
        return int(fh.read().split()[1]) * os.sysconf('SC_PAGE_SIZE') / 2**20


def _stream_child(path: str, minutes_list: float) -> None:
    """In a fresh process: RSS while streaming the whole bag, then while listing part of it."""
    from haptic_anfis.bag.playback import schedule, stream
    from haptic_anfis.bag import bag_info
    info = bag_info(path)
    base = rss_mb()
    samples, n = [], 0
    t0 = time.perf_counter()
    for due, r in schedule(path):
        n += 1
        if n % 200_000 == 0:
            samples.append((round(due, 1), round(rss_mb(), 1)))
    wall = time.perf_counter() - t0
    stream_peak = max(s for _, s in samples) if samples else rss_mb()
    # the old player: every message of the first minutes as a list
    stop = info.start_ns + int(minutes_list * 60e9)
    before = rss_mb()
    kept = []
    for r in stream(path):
        if r.t_ns >= stop:
            break
        kept.append(r)
    listed = rss_mb() - before
    print(json.dumps({'messages': n, 'bag_minutes': info.duration_s / 60, 'base_mb': base,
                      'stream_peak_mb': stream_peak, 'samples': samples, 'stream_wall_s': wall,
                      'list_messages': len(kept), 'list_minutes': minutes_list,
                      'list_mb': listed}))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--minutes', type=float, default=30.0)
    ap.add_argument('--compress-minutes', type=float, default=2.0)
    ap.add_argument('--list-minutes', type=float, default=3.0)
    ap.add_argument('--compression', default='none', help='for the long bag')
    ap.add_argument('--dir', default=None, help='where to write the bags (default: a temp dir)')
    ap.add_argument('--stream-child', default=None, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.stream_child:
        _stream_child(a.stream_child, a.list_minutes)
        return 0
    per_s = sum(1 / v for v in MIX.values()) * RATE
    print(f'long-session bag benchmark: loop mix {per_s:.0f} msg/s, {os.cpu_count()} CPUs, '
          f'load average {os.getloadavg()[0]:.2f}')
    with tempfile.TemporaryDirectory(dir=a.dir) as tmp:
        tmp = Path(tmp)
        secs = a.compress_minutes * 60
        tpl = Templates()
        msgs = list(session(tpl, secs))  # prepared: the timing is the writing alone
        print(f'\n1. compression, {a.compress_minutes:g} min of session ({len(msgs)} messages)')
        print(f'{"compression":<12} {"MB/hour":>9} {"ratio":>6} {"CPU % of a core":>16} '
              f'{"flush CPU p99 ms":>17} {"max ms":>7}')
        base = None
        for comp in ('none', 'zstd', 'lz4'):
            r = write_session(tmp / f'c_{comp}', secs, comp, msgs)
            mb_h = r['bytes'] / 1e6 / secs * 3600
            base = base or mb_h
            print(f'{comp:<12} {mb_h:>9.0f} {base / mb_h:>6.2f} {100 * r["cpu_s"] / secs:>16.1f} '
                  f'{r["flush_p99_ms"]:>17.2f} {r["flush_max_ms"]:>7.2f}')
        del msgs
        for comp in ('zstd', 'lz4'):
            el, gap = gil_stall(comp)
            print(f'{comp}: compressing 16 MB took {el * 1e3:.0f} ms; another thread\'s longest '
                  f'stall meanwhile {gap * 1e3:.1f} ms ({100 * gap / el:.0f} % of it: the GIL)')
        print(f'\n2. a {a.minutes:g}-minute session, compression {a.compression}')
        long = tmp / 'long'
        r = write_session(long, a.minutes * 60, a.compression)
        print(f'written: {r["messages"]} messages, {r["bytes"] / 1e6:.0f} MB '
              f'({r["bytes"] / 1e6 / a.minutes * 60:.0f} MB per hour), {r["dropped"]} dropped, '
              f'{r["wall_s"]:.0f} s')
        out = subprocess.run([sys.executable, __file__, '--stream-child', str(long),
                              '--list-minutes', str(a.list_minutes)],
                             capture_output=True, text=True, env=os.environ)
        if out.returncode:
            print(out.stderr)
            return 1
        s = json.loads(out.stdout.strip().splitlines()[-1])
        print(f'player stream over {s["bag_minutes"]:.1f} min ({s["messages"]} messages, '
              f'{s["stream_wall_s"]:.0f} s): RSS {s["base_mb"]:.0f} MB after opening, peak '
              f'{s["stream_peak_mb"]:.0f} MB')
        print('  (bag minute, RSS MB): ' + ', '.join(f'({t / 60:.0f}, {m:.0f})'
                                                     for t, m in s['samples'][::4]))
        print(f'old player (whole bag as a list): {s["list_mb"]:.0f} MB for {s["list_minutes"]:g} '
              f'min ({s["list_messages"]} messages) = {s["list_mb"] / s["list_minutes"] * 60:.0f} '
              f'MB per hour of bag')
        print(f'peak RSS of this process {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB')
    return 0


if __name__ == '__main__':
    sys.exit(run_with_page(main, __file__, __doc__, no_page_flags=('--stream-child',)))
