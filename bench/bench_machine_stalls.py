"""Machine stalls: how late a highest-priority thread on each core wakes, under what load.

A canary process per core (SCHED_FIFO 99, pinned: nothing of the guest's user space can delay
it) sleeps to 1 ms deadlines and records every wake-up later than 2 ms, and when the steal
counter of its core (``/proc/stat``: time the host ran something else) moved. Loads, each
``--seconds``: none; 8 processes spinning (pure computation, no system call); a file written
and synced (``dd ... conv=fsync``); memory taken and given back (512 MB arrays in a loop);
and ``launch --record`` as the soak runs it (real-time defaults), whose driver trace gives the
servo loop's gaps, each matched with the canaries' stalls at that time.

A stall of both canaries at once stops every thread of the machine, the servo's tick workers
at real-time priority included: no priority, no second worker can ride it out. This script
measures how often the machine itself does that; it needs the right to run SCHED_FIFO 99
(root, or an rtprio limit of 99) and ends with exit 0 and no page where it has not.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from _page import run_with_page  # noqa: E402

from haptic_anfis.realtime.processes import node_env  # noqa: E402

LATE_S = 0.002      # a wake-up later than this is a stall
TOGETHER_S = 0.003  # two cores' stalls this close are one stall of both

CANARY = r'''
import json, os, sys, time
cpu, seconds, out = int(sys.argv[1]), float(sys.argv[2]), sys.argv[3]
os.sched_setaffinity(0, {cpu})
os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(99))
def steal():
    for line in open('/proc/stat'):
        if line.startswith(f'cpu{cpu} '):
            return int(line.split()[8])
late, steals, s0, k = [], [], steal(), 0
t0 = nxt = time.monotonic()
while nxt - t0 < seconds:
    nxt += 0.001
    d = nxt - time.monotonic()
    if d > 0:
        time.sleep(d)
    now = time.monotonic()
    if now - nxt > LATE:
        late.append((now, now - nxt))
        nxt = now
    k += 1
    if k % 10 == 0:
        s = steal()
        if s != s0:
            steals.append((now, s - s0))
            s0 = s
json.dump({'cpu': cpu, 'late': late, 'steal': steals}, open(out, 'w'))
'''.replace('LATE', repr(LATE_S))

LOADS = {
    'none': None,
    '8 spinning': [[sys.executable, '-c', 'while True: pass']] * 8,
    'file written and synced': [['sh', '-c', 'while true; do dd if=/dev/zero of={tmp}/w.bin '
                                 'bs=1M count=300 conv=fsync status=none; done']],
    'memory taken and given back': [[sys.executable, '-c', 'import numpy as np\nwhile True:\n'
                                     '    a = np.ones(64_000_000); del a']],
}


def can_run_canary() -> str:
    """'' when SCHED_FIFO 99 is allowed here, else why not."""
    code = 'import os; os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(99))'
    r = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True)
    return '' if r.returncode == 0 else 'SCHED_FIFO 99 is refused here (root or rtprio 99 needed)'


def together(late0: list, late1: list, window: float = TOGETHER_S) -> list[tuple[float, float]]:
    """The stalls of core 0 with a stall of core 1 within ``window`` s: (time, the shorter of
    the two lengths) [s], in time order."""
    t1 = np.array([t for t, _ in late1]) if late1 else np.zeros(0)
    out = []
    for t, length in sorted(late0):
        if len(t1):
            j = int(np.argmin(np.abs(t1 - t)))
            if abs(t1[j] - t) <= window:
                out.append((t, min(length, late1[j][1])))
    return out


def gaps_matched(gaps: list[tuple[float, float]], stalls: list[tuple[float, float]],
                 window: float = TOGETHER_S) -> int:
    """How many servo ``gaps`` (end time, length) [s] end within ``window`` of a stall of both
    cores that ends then (a stall's time is when the canary woke, its end)."""
    ends = np.array([t for t, _ in stalls]) if stalls else np.zeros(0)
    return sum(1 for t, _ in gaps if len(ends) and float(np.min(np.abs(ends - t))) <= window)


def canaries(seconds: float, d: Path) -> list[subprocess.Popen]:
    return [subprocess.Popen([sys.executable, '-c', CANARY, str(c), str(seconds),
                              str(d / f'canary{c}.json')]) for c in range(2)]


def read(d: Path) -> list[dict]:
    return [json.loads((d / f'canary{c}.json').read_text()) for c in range(2)]


def summary(name: str, runs: list[dict], seconds: float, gaps=None) -> str:
    both = together(runs[0]['late'], runs[1]['late'])
    longest = lambda xs: max((x[1] for x in xs), default=0.0) * 1e3  # noqa: E731
    steal = sum(s for r in runs for _, s in r['steal']) * 10  # /proc/stat counts 10 ms
    row = (f'| {name} | {seconds:g} | {len(runs[0]["late"])} / {len(runs[1]["late"])} | '
           f'{longest(runs[0]["late"]):.1f} / {longest(runs[1]["late"]):.1f} | {len(both)} | '
           f'{sum(1 for _, x in both if x > 0.010)} | {longest(both):.1f} | {steal} |')
    if gaps is None:
        return row + ' |'
    big = [g for g in gaps if g[1] > 0.004]
    return row + f' {gaps_matched(big, both)} of {len(big)} |'


def launch_gaps(trace: Path) -> list[tuple[float, float]]:
    """(end time, length) [s] of every gap between the driver's traced ticks."""
    from haptic_anfis.device.trace import load_trace
    rows, _ = load_trace(trace)
    t = rows[:, 0]
    g = np.diff(t)
    return [(float(t[i + 1]), float(g[i])) for i in np.nonzero(g > 0.0015)[0]]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--seconds', type=float, default=60.0, help='per load [s]')
    ap.add_argument('--launch-seconds', type=float, default=300.0,
                    help='the launch --record run [s] (0: leave it out)')
    ap.add_argument('--no-page', action='store_true', help='print only')
    a = ap.parse_args()
    print('| load | s | stalls > 2 ms (core 0 / 1) | longest ms (core 0 / 1) | both at once | '
          'both > 10 ms | both longest ms | steal ms | servo gaps > 4 ms at a stall of both |')
    print('|---|---|---|---|---|---|---|---|---|')
    with tempfile.TemporaryDirectory(prefix='bench-stalls-') as td:
        for name, cmds in LOADS.items():
            d = Path(td) / name.replace(' ', '_')
            d.mkdir()
            load = [subprocess.Popen([c.format(tmp=td) for c in cmd]) for cmd in cmds or []]
            try:
                time.sleep(1.0 if load else 0.0)
                for p in canaries(a.seconds, d):
                    p.wait()
            finally:
                for p in load:
                    p.kill()
                    p.wait()
            print(summary(name, read(d), a.seconds), flush=True)
        if a.launch_seconds > 0:
            d = Path(td) / 'launch'
            d.mkdir()
            env = node_env(150 + os.getpid() % 40, localhost=True)
            env['PYTHONPATH'] = str(ROOT)
            cmd = [str(Path(sys.executable).parent / 'haptic-anfis'), 'launch', '--nodes',
                   'falcon_driver,contact_detector,force_server', '--localhost', '--record',
                   str(d / 'bag'), '--log-dir', str(d / 'logs'), '--duration',
                   str(a.launch_seconds)]
            cans = canaries(a.launch_seconds + 90.0, d)
            subprocess.run(cmd, capture_output=True, text=True, env=env,
                           timeout=a.launch_seconds + 900)
            for p in cans:
                p.wait()
            gaps = launch_gaps(d / 'logs' / 'falcon_driver_trace.npz')
            print(summary('launch --record (real-time)', read(d), a.launch_seconds, gaps),
                  flush=True)
    print(f'\nCanaries: one process per core, SCHED_FIFO 99, pinned, 1 ms deadlines; a stall: a '
          f'wake-up more than {LATE_S * 1e3:g} ms late; both at once: the two cores\' stalls '
          f'within {TOGETHER_S * 1e3:g} ms. steal: what /proc/stat counted for both cores '
          '(10 ms steps). Last column: the gaps of more than 4 ms between the servo loop\'s '
          'traced ticks that ended at a stall of both canaries.')
    return 0


def run() -> int:
    """The benchmark with its page; where SCHED_FIFO 99 is refused, one line, exit 0 (``make
    bench`` goes on) and no page."""
    why = can_run_canary()
    if why:
        print(f'skipped: {why}')
        return 0
    return run_with_page(main, __file__, __doc__, no_page_flags=('--no-page',))


if __name__ == '__main__':
    sys.exit(run())
