"""What the scheduler did with the graph while its local models came late (issue 32).

On a busy machine without real-time priority the force server's local models sometimes stop for
half a second while /contact goes on; the servo loop then holds the last one and, past
``model_hold_time`` or ``model_hold_radius``, renders 0 N. This lines such episodes up with a
scheduler trace of the same run, to tell a starved thread (runnable, waiting for a CPU) from one
with nothing to do (asleep: no input) and from one that was busy computing.

Record the scheduler beside a run kept by ``bench_servo_load --keep DIR`` (as root; the monotonic
clock, which the driver's trace uses; a large buffer, since the recording process is itself
starved now and then)::

    perf sched record -k mono -m 256M -o DIR/perf.data &   # then the run; then kill -INT it

    .venv/bin/python bench/sched_episodes.py DIR/trace_*.npz DIR/perf.data [--bag BAG]
        [--late-ms 200] [--top 10] [--threads 8]

An episode: a gap longer than ``--late-ms`` between two local models as the recorder received
them (the bag's ``/falcon/servo_cf_local``), whether /contact reached the recorder in it. For each
of the ``--top`` longest, per process of the graph (its threads summed) the milliseconds spent
running, runnable but waiting for a CPU, and asleep in the episode, with the longest single wait
for a CPU; then the ``--threads`` threads of the whole machine that waited longest for a CPU, and
how long the CPUs were idle. From ``perf sched timehist`` (read as ``bench_sched_trace`` reads
it): for each switch out, the thread ran ``run`` ms before it, waited ``sch delay`` ms runnable
before that and slept the rest of ``wait time``. Prints only (a diagnosis, not a benchmark: no
page).
"""
from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench_sched_trace import TIMEHIST_LINE  # noqa: E402
from trace_episodes import clock_offset, topic_times  # noqa: E402
from haptic_anfis.device.trace import DISABLED, load_trace  # noqa: E402

#: the graph's processes by their command name (the entry point's name, cut to 15 characters)
GRAPH = ('falcon_driver', 'contact_detecto', 'force_server', 'recorder', 'web_view')
LOCAL_MODEL, CONTACT = '/falcon/servo_cf_local', '/contact'



@dataclass
class Use:
    """Milliseconds a thread (or a process) spent in an episode."""
    run: float = 0.0
    runnable: float = 0.0
    asleep: float = 0.0
    longest_wait: float = 0.0   # [ms] the longest single runnable stretch overlapping it


@dataclass
class Episode:
    start: float   # [s, monotonic] the last local model before it, as the recorder got it
    end: float     # [s, monotonic] the first after it
    contacts: int  # /contact messages the recorder got in it
    threads: dict[tuple[int, int], Use] = field(default_factory=dict)  # (pid, tid) -> use
    idle: float = 0.0   # [ms] CPU time idle in it (both CPUs summed)


def overlap(a: float, b: float, lo: float, hi: float) -> float:
    """[ms] of [a, b] inside [lo, hi] (seconds)."""
    return max(0.0, min(b, hi) - max(a, lo)) * 1e3


def find_episodes(recv_lm: np.ndarray, recv_contact: np.ndarray, late: float, top: int,
                  offset: float) -> list[Episode]:
    """The ``top`` longest gaps > ``late`` [s] between local models (receive times [s, wall]),
    as monotonic windows, in time order."""
    gaps = np.diff(recv_lm)
    idx = np.flatnonzero(gaps > late)
    idx = idx[np.argsort(-gaps[idx])][:top]
    out = []
    for i in sorted(idx):
        a, b = recv_lm[i], recv_lm[i + 1]
        n = int(np.searchsorted(recv_contact, b) - np.searchsorted(recv_contact, a, 'right'))
        out.append(Episode(a - offset, b - offset, n))
    return out


def timehist_lines(perf_data: Path):
    """(t [s], cpu, name, tid, pid, wait, sch delay, run [ms]) for every switch out in the
    recording (``perf sched timehist``)."""
    cmd = ['perf', 'sched', 'timehist', '-i', str(perf_data)]
    with subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                          bufsize=1 << 20) as p:
        for line in p.stdout:
            m = TIMEHIST_LINE.match(line)
            if m:
                t, cpu, name, tid, pid, wait, delay, run = m.groups()
                tid = int(tid)
                yield (float(t), int(cpu), name.strip(), tid, int(pid) if pid else tid,
                       float(wait), float(delay), float(run))


def account(episodes: list[Episode], lines, names: dict[int, str]) -> None:
    """Adds each switch out's run / runnable / asleep stretches to the episodes they overlap;
    fills ``names`` (pid -> the command name of its main thread)."""
    starts = np.array([e.start for e in episodes])
    first, last = (starts.min(), max(e.end for e in episodes)) if episodes else (0.0, -1.0)
    for t, _, name, tid, pid, wait, delay, run in lines:
        if tid == pid and tid and pid not in names:
            names[pid] = name
        ran_from = t - run * 1e-3
        waited_from = ran_from - delay * 1e-3
        slept_from = ran_from - wait * 1e-3
        if t < first or slept_from > last:
            continue
        for e in episodes[:np.searchsorted(starts, t, 'right')]:
            if slept_from > e.end or t < e.start:
                continue
            if tid == 0:   # <idle>: one line per CPU
                e.idle += overlap(ran_from, t, e.start, e.end)
                continue
            u = e.threads.setdefault((pid, tid), Use())
            u.run += overlap(ran_from, t, e.start, e.end)
            w = overlap(waited_from, ran_from, e.start, e.end)
            u.runnable += w
            if w > 0:
                u.longest_wait = max(u.longest_wait, delay)
            u.asleep += overlap(slept_from, waited_from, e.start, e.end)


def by_process(e: Episode, names: dict[int, str]) -> dict[str, Use]:
    """The graph's processes' use in ``e``, their threads summed (longest wait: the longest)."""
    out = {}
    for (pid, _), u in e.threads.items():
        name = names.get(pid, '')
        if name in GRAPH:
            s = out.setdefault(f'{name}[{pid}]', Use())
            s.run, s.runnable, s.asleep = s.run + u.run, s.runnable + u.runnable, \
                s.asleep + u.asleep
            s.longest_wait = max(s.longest_wait, u.longest_wait)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('trace', type=Path, help='the run\'s falcon_driver tick trace (.npz)')
    ap.add_argument('perf', type=Path, help='perf sched record -k mono of the same run')
    ap.add_argument('--bag', type=Path, help="the run's bag (default: bench_servo_load --keep's "
                                             'name beside the trace)')
    ap.add_argument('--late-ms', type=float, default=200.0,
                    help='gaps between local models longer than this [ms] (default 200)')
    ap.add_argument('--top', type=int, default=10, help='the longest episodes (default 10)')
    ap.add_argument('--threads', type=int, default=8,
                    help='threads of the machine listed per episode, by time waiting for a CPU')
    a = ap.parse_args()
    rows, meta = load_trace(a.trace)
    rows = rows[rows[:, 7] != DISABLED]
    bag = a.bag or a.trace.with_name(a.trace.name.removeprefix('trace_').removesuffix('.npz'))
    if not (bag / 'metadata.yaml').is_file():
        ap.error(f'{bag}: not a rosbag2 bag (expected a directory with metadata.yaml); '
                 'give the run\'s with --bag')
    if not a.perf.is_file():
        ap.error(f'{a.perf}: no such perf recording')
    if shutil.which('perf') is None:
        ap.error('perf is not installed (Debian: apt-get install linux-perf)')
    offset = clock_offset(rows, meta, bag)
    if offset is None:
        ap.error(f'{bag}: could not be lined up with the trace (no matching pose)')
    topics = topic_times(bag)
    if LOCAL_MODEL not in topics:
        ap.error(f'{bag}: no {LOCAL_MODEL} recorded (the driver\'s force_mode local_model?)')
    recv_contact = topics.get(CONTACT, (np.array([]),))[0]
    eps = find_episodes(topics[LOCAL_MODEL][0], recv_contact, a.late_ms * 1e-3, a.top, offset)
    print(f'{a.trace}: {len(eps)} episodes of local models more than {a.late_ms:g} ms apart '
          f'(the longest {a.top})')
    names: dict[int, str] = {}
    account(eps, timehist_lines(a.perf), names)
    for e in eps:
        ms = (e.end - e.start) * 1e3
        print(f'\n{ms:.0f} ms without a local model at {e.start - rows[0, 0]:.3f} s after the '
              f'first tick; {e.contacts} /contact in it; CPUs idle {e.idle:.0f} ms of '
              f'{2 * ms:.0f}')
        print('  process                 run ms  runnable ms  asleep ms  longest wait ms')
        for name, u in sorted(by_process(e, names).items()):
            print(f'  {name:22s} {u.run:7.0f} {u.runnable:12.0f} {u.asleep:10.0f} '
                  f'{u.longest_wait:16.1f}')
        print('  threads waiting longest for a CPU:')
        worst = sorted(e.threads.items(), key=lambda kv: -kv[1].runnable)[:a.threads]
        for (pid, tid), u in worst:
            print(f'    {names.get(pid, "?")}[{pid}] thread {tid}: runnable {u.runnable:.0f} ms '
                  f'(longest {u.longest_wait:.1f}), ran {u.run:.0f} ms')
    return 0


if __name__ == '__main__':
    sys.exit(main())
