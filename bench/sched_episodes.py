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
        [--late-ms 200] [--top 10] [--from 30] [--threads 8] [--pids NAME=PID,...]
        [--servo-gaps]

With ``--servo-gaps`` the episodes are the ``--top`` longest gaps between servo ticks longer than
10 ms (the watchdog) instead, summed into one table: who held the CPUs while no tick ran.

The graph's processes are named from the run's node logs beside the trace (each node logs its
process id when it starts, the driver its servo process's), or by ``--pids``.

An episode: the force server answered no pose for longer than ``--late-ms`` (a gap between the
header stamps of consecutive ``/falcon/servo_cf`` in the bag: the force, published with each local
model, stamped with the pose it answers; the recorder's own lateness does not make one). The
driver held its last model through it. /contact in it: poses the contact detector turned into
contacts then (few: the detector or the driver was held up; many: the force server). For each of
the ``--top`` longest, per process of the graph (its threads summed) the milliseconds spent
running, runnable but waiting for a CPU, and asleep in the episode, with the longest single wait
for a CPU; the processes that ran most in it; the ``--threads`` threads of the whole machine that
waited longest for a CPU; and
how long the CPUs were idle. From ``perf sched timehist --state`` (read as ``bench_sched_trace``
reads it): for each switch out, the thread ran ``run`` ms before it, waited ``sch delay`` ms
runnable before that and slept the rest of ``wait time`` (all of it runnable if it had last
left its CPU preempted). Prints only (a diagnosis, not a benchmark: no
page).
"""
from __future__ import annotations

import argparse
import math
import re
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

#: what the nodes' logs say when they start (session.Readiness) and where the servo runs
STARTED = re.compile(r'\[(\w+)\]: started after [\d.]+ s: .*, process (\d+)')
SERVO = re.compile(r'servo thread: compiled tick in servo process (\d+)')
#: the force server's force, published with each local model; what reached it
FORCE_OUT, CONTACT = '/falcon/servo_cf', '/contact'
#: [s] --servo-gaps: gaps between servo ticks longer than this (the watchdog)
GAP_S = 0.010



@dataclass
class Use:
    """Milliseconds a thread (or a process) spent in an episode."""
    run: float = 0.0
    runnable: float = 0.0
    asleep: float = 0.0
    longest_wait: float = 0.0   # [ms] the longest single runnable stretch overlapping it

    def add(self, other: 'Use') -> None:
        """Sums ``other`` into this (longest wait: the longest)."""
        self.run, self.runnable, self.asleep = (self.run + other.run,
                                                self.runnable + other.runnable,
                                                self.asleep + other.asleep)
        self.longest_wait = max(self.longest_wait, other.longest_wait)


@dataclass
class Episode:
    start: float   # [s, monotonic] the pose of the force server's last answer before it
    end: float     # [s, monotonic] the pose of its first answer after it
    contacts: int  # /contact messages for poses in it
    threads: dict[tuple[int, int], Use] = field(default_factory=dict)  # (pid, tid) -> use
    idle: float = 0.0   # [ms] CPU time idle in it (both CPUs summed)


def overlap(a: float, b: float, lo: float, hi: float) -> float:
    """[ms] of [a, b] inside [lo, hi] (seconds)."""
    return max(0.0, min(b, hi) - max(a, lo)) * 1e3


def find_episodes(answered: np.ndarray, contacts: np.ndarray, late: float, top: int,
                  offset: float) -> list[Episode]:
    """The ``top`` longest gaps > ``late`` [s] between the poses the force server answered
    (``answered``, ``contacts``: header stamps [s, wall], increasing), as monotonic windows
    (``offset``: wall minus monotonic [s]), in time order."""
    gaps = np.diff(answered)
    idx = np.flatnonzero(gaps > late)
    idx = idx[np.argsort(-gaps[idx])][:top]
    out = []
    for i in sorted(idx):
        a, b = answered[i], answered[i + 1]
        n = int(np.searchsorted(contacts, b) - np.searchsorted(contacts, a, 'right'))
        out.append(Episode(a - offset, b - offset, n))
    return out


#: perf's line for a CPU's idle task (no thread id): end of the idle stretch [s], cpu, its length
IDLE_LINE = re.compile(r'^\s*([\d.]+)\s+\[(\d+)\]\s+<idle>\s+[\d.]+\s+[\d.]+\s+([\d.]+)')


def parse_line(line: str) -> tuple | None:
    """(t [s], cpu, name, tid, pid, wait, sch delay, run [ms], state) of one ``perf sched
    timehist --state`` line (the idle task: name '<idle>', tid and pid 0); None for another."""
    m = TIMEHIST_LINE.match(line)
    if m:
        t, cpu, name, tid, pid, wait, delay, run, state = m.groups()
        return (float(t), int(cpu), name.strip(), int(tid), int(pid) if pid else int(tid),
                float(wait), float(delay), float(run), state or '')
    m = IDLE_LINE.match(line)
    if m:
        t, cpu, run = m.groups()
        return float(t), int(cpu), '<idle>', 0, 0, 0.0, 0.0, float(run), ''
    return None


def timehist_lines(perf_data: Path):
    """:func:`parse_line` of every switch out in the recording."""
    cmd = ['perf', 'sched', 'timehist', '-i', str(perf_data), '--state']
    with subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                          bufsize=1 << 20) as p:
        for line in p.stdout:
            got = parse_line(line)
            if got is not None:
                yield got


def account(episodes: list[Episode], lines, names: dict[int, str]
            ) -> tuple[float, float, int]:
    """Adds each switch out's run / runnable / asleep stretches to the episodes they overlap;
    fills ``names`` (pid -> the command name of its main thread). Returns the recording's span
    (first and last switch out [s]) and its CPUs. A thread that left its CPU runnable (state R:
    preempted) waited runnable all the time until it ran again: older perf versions (6.1 here) give
    such a wait no scheduler delay (no wake-up), so its whole wait time counts as runnable."""
    starts = np.array([e.start for e in episodes])
    first, last = (starts.min(), max(e.end for e in episodes)) if episodes else (0.0, -1.0)
    lo, hi, cpus = math.inf, -math.inf, 0
    left: dict[int, str] = {}   # tid -> the state it last left its CPU in
    for t, cpu, name, tid, pid, wait, delay, run, state in lines:
        lo, hi, cpus = min(lo, t), max(hi, t), max(cpus, cpu + 1)
        if tid == pid and tid and pid not in names:
            names[pid] = name
        preempted = left.get(tid) == 'R'
        left[tid] = state
        ran_from = t - run * 1e-3
        slept_from = ran_from - wait * 1e-3
        waited_from = slept_from if preempted else ran_from - delay * 1e-3
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
                u.longest_wait = max(u.longest_wait, (ran_from - waited_from) * 1e3)
            u.asleep += overlap(slept_from, waited_from, e.start, e.end)
    return lo, hi, cpus


def servo_gaps(rows: np.ndarray, start: float, top: int) -> list[Episode]:
    """The ``top`` longest gaps between servo ticks longer than :data:`GAP_S`, from ``start``
    [s] after the first tick, as episodes (monotonic, the trace's clock), in time order; prints
    how many there were, and how many longer than 2 ms (a period lost)."""
    t = rows[:, 0]
    dt = np.diff(t)
    late = t[:-1] >= t[0] + start
    idx = np.flatnonzero(late & (dt > GAP_S))
    print(f'servo gaps from {start:g} s: {len(idx)} longer than {GAP_S * 1e3:g} ms '
          f'({dt[idx].sum():.2f} s in all), {int((late & (dt > 0.002)).sum())} longer than 2 ms')
    idx = idx[np.argsort(-dt[idx])][:top]
    return [Episode(t[i], t[i + 1], 0) for i in sorted(idx)]


def summed(episodes: list[Episode]) -> Episode:
    """One episode holding the sums of ``episodes``' uses (its span: their summed length;
    longest wait: the longest)."""
    out = Episode(0.0, sum(e.end - e.start for e in episodes), 0)
    for e in episodes:
        out.idle += e.idle
        for k, u in e.threads.items():
            out.threads.setdefault(k, Use()).add(u)
    return out


def node_pids(log_dir: Path) -> dict[int, str]:
    """{process id: node name, and 'servo process'} from a run's node logs (``*.log``)."""
    out = {}
    for f in sorted(log_dir.glob('*.log')):
        for line in f.read_text(errors='replace').splitlines():
            if m := STARTED.search(line):
                out[int(m.group(2))] = m.group(1)
            elif m := SERVO.search(line):
                out[int(m.group(1))] = 'servo process'
    return out


def by_process(e: Episode, names: dict[int, str], graph: set[int]) -> dict[str, Use]:
    """The use in ``e`` of the processes in ``graph`` (or of all, if empty), their threads
    summed (longest wait: the longest), by name[pid]."""
    out = {}
    for (pid, _), u in e.threads.items():
        if not graph or pid in graph:
            out.setdefault(f'{names.get(pid, "?")}[{pid}]', Use()).add(u)
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
    ap.add_argument('--from', dest='start', type=float, default=30.0,
                    help="from this many seconds after the first tick (default 30: "
                         "bench_servo_load's --settle)")
    ap.add_argument('--threads', type=int, default=8,
                    help='threads of the machine listed per episode, by time waiting for a CPU')
    ap.add_argument('--servo-gaps', action='store_true',
                    help='the --top longest gaps between servo ticks (> 10 ms) instead, summed')
    ap.add_argument('--pids', default='',
                    help='NAME=PID,... the graph\'s processes (default: from the node logs '
                         'beside the trace, log_<bag>/)')
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
    if FORCE_OUT not in topics:
        ap.error(f'{bag}: no {FORCE_OUT} recorded')
    contacts = np.sort(topics.get(CONTACT, (None, np.array([])))[1])
    answered = np.sort(topics[FORCE_OUT][1])
    answered = answered[answered >= rows[0, 0] + offset + a.start]
    if a.servo_gaps:
        eps = servo_gaps(rows, a.start, a.top)
        print(f'{a.trace}: from {a.start:g} s after the first tick, the {len(eps)} longest servo '
              f'gaps above {GAP_S * 1e3:g} ms')
    else:
        eps = find_episodes(answered, contacts, a.late_ms * 1e-3, a.top, offset)
        print(f'{a.trace}: from {a.start:g} s after the first tick, the {len(eps)} longest gaps '
              f'between the poses the force server answered, above {a.late_ms:g} ms')
    try:
        graph = {int(v): k for k, v in (kv.split('=') for kv in a.pids.split(',') if kv)}
    except ValueError:
        ap.error(f'--pids {a.pids!r}: expected NAME=PID,... (PID a number)')
    log_dir = bag.with_name('log_' + bag.name)
    graph = graph or (node_pids(log_dir) if log_dir.is_dir() else {})
    print('graph processes: ' + (', '.join(f'{n} {p}' for p, n in sorted(graph.items()))
                                 or 'unknown (no node logs with process ids; --pids)'))
    names: dict[int, str] = {}
    lo, hi, cpus = account(eps, timehist_lines(a.perf), names)
    names.update(graph)
    print(f'{a.perf}: {lo - rows[0, 0]:.1f} to {hi - rows[0, 0]:.1f} s after the first tick, '
          f'{cpus} CPUs')
    inside = [e for e in eps if lo <= e.start and e.end <= hi]
    if len(inside) < len(eps):
        print(f'{len(eps) - len(inside)} episodes not all in the recording: left out')
    for e in inside if not a.servo_gaps else [summed(inside)]:
        ms = (e.end - e.start) * 1e3
        what = (f'{len(inside)} servo gaps, {ms:.0f} ms in all' if a.servo_gaps else
                f'{ms:.0f} ms of poses unanswered from {e.start - rows[0, 0]:.3f} s after the '
                f'first tick; {e.contacts} /contact for them')
        print(f'\n{what}; CPUs idle {e.idle:.0f} ms of {cpus * ms:.0f}')
        print('  process                 run ms  runnable ms  asleep ms  longest wait ms')
        for name, u in sorted(by_process(e, names, set(graph)).items()):
            print(f'  {name:22s} {u.run:7.0f} {u.runnable:12.0f} {u.asleep:10.0f} '
                  f'{u.longest_wait:16.1f}')
        ran = sorted(by_process(e, names, set()).items(), key=lambda kv: -kv[1].run)[:6]
        print('  ran most: ' + ', '.join(f'{n} {u.run:.0f} ms' for n, u in ran))
        print('  threads waiting longest for a CPU:')
        worst = sorted(e.threads.items(), key=lambda kv: -kv[1].runnable)[:a.threads]
        for (pid, tid), u in worst:
            print(f'    {names.get(pid, "?")}[{pid}] thread {tid}: runnable {u.runnable:.0f} ms '
                  f'(longest {u.longest_wait:.1f}), ran {u.run:.0f} ms')
    return 0


if __name__ == '__main__':
    sys.exit(main())
