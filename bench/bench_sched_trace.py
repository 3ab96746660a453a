"""Why the servo loop loses periods without real-time priority: a scheduler trace of one run.

Runs configurations of ``bench_servo_load`` (default: ``sim`` and ``launch`` without real-time
priority, beside 8 busy processes, with the recorder and the browser view), records every
context switch and wake-up of the machine for ``--seconds`` in the middle of each run (``perf
sched record -a``) and reads from the trace, for the servo process's tick workers: how long each
waited between its wake-up and running (the scheduler delay), which program held the core while a
worker waited more than 1 ms and how long that program had been running when it let the worker
in, and for every servo gap (no worker ran for more than 1.9 ms, so a period was lost) the
program that held each core during the gap. Programs are named from their command lines (the busy
processes, chromium, the view nodes, the graph, the kernel's threads, ...).

Needs ``perf`` (Debian: linux-perf) and the right to trace the whole machine (root, or
``kernel.perf_event_paranoid`` <= -1); without them it says so and ends without a page (exit 0,
so ``make bench`` goes on).

Usage: ``python bench/bench_sched_trace.py [--configs sim:0,launch:0] [--busy 8] [--no-view]
[--seconds 8] [--page sched_trace]``
"""
from __future__ import annotations

import argparse
import bisect
import collections
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _busy import busy  # noqa: E402
from _page import write_page  # noqa: E402
from bench_servo_load import row, run_one  # noqa: E402

#: a worker that waited longer than this for its core [ms]
LATE_MS = 1.0
#: no worker ran for longer than this: at least one 1 ms period lost [ms]
GAP_MS = 1.9
NODES = ('falcon_driver', 'contact_detector', 'force_server', 'recorder', 'visualizer',
         'web_view', 'examiner', 'trainer')
#: a ``perf sched timehist`` line (one switch out): end of the run [s], cpu, name, tid, pid, wait
#: time, scheduler delay, run time [ms], and with ``--state`` the state it left in (R: preempted)
TIMEHIST_LINE = re.compile(r'^\s*([\d.]+)\s+\[(\d+)\]\s+(.+?)\[(\d+)(?:/(\d+))?\]'
                           r'\s+([\d.]+)\s+([\d.]+)\s+([\d.]+)(?:\s+(\S+))?\s*$')


def _cmdline(pid: int) -> str | None:
    try:
        return Path(f'/proc/{pid}/cmdline').read_bytes().replace(b'\0', b' ').decode(
            errors='replace').strip()
    except OSError:
        return None


def _ppid(pid: int) -> int:
    try:
        return int(Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()[1])
    except (OSError, IndexError, ValueError):
        return 0


def program(cmd: str | None, servo_pid: int, pid: int) -> str:
    """The program a process belongs to, from its command line."""
    if pid == servo_pid:
        return 'servo process'
    if cmd is None or cmd == '':
        return 'kernel'
    if 'while True: pass' in cmd:
        return 'busy process'
    if 'chrom' in cmd:
        return 'chromium'
    head = ' '.join(cmd.split()[:3])   # the interpreter and the node's program, not its arguments
    for n in NODES:
        if n in head:
            return n
    if 'haptic_anfis.cli sim' in cmd:
        return 'sim graph'
    if 'haptic_anfis.cli launch' in cmd:
        return 'launch supervisor'
    if 'perf' in cmd.split()[0]:
        return 'perf'
    return 'other'


def _pinned_threads(pid: int) -> int:
    """Threads of ``pid`` allowed on one CPU only (the servo process's tick workers are pinned,
    one to each core; no other thread of the graph is)."""
    n = 0
    for t in Path(f'/proc/{pid}/task').glob('*/status'):
        try:
            for line in t.read_text().splitlines():
                if line.startswith('Cpus_allowed_list:'):
                    n += line.split(':')[1].strip().isdigit()
        except OSError:
            pass
    return n


def find_servo_process(timeout: float) -> int | None:
    """The servo process: forked by the driver after the compile (so with its parent's command
    line), its tick workers each pinned to one core (``sim``'s re-run of itself has its parent's
    command line too, but no pinned thread)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        for p in Path('/proc').iterdir():
            if not p.name.isdigit():
                continue
            pid = int(p.name)
            cmd = _cmdline(pid)
            if cmd and ('haptic_anfis' in cmd or 'falcon_driver' in cmd) \
                    and _cmdline(_ppid(pid)) == cmd and _pinned_threads(pid) >= 1:
                return pid
        time.sleep(0.2)
    return None


def names_now(servo_pid: int, examples: dict | None = None) -> dict[int, str]:
    """{pid or thread id: program} of every process and thread now (the trace names a thread
    by its own id where it does not know its process's); ``examples`` gets one command line
    per program."""
    out = {}
    for p in Path('/proc').iterdir():
        if p.name.isdigit():
            pid = int(p.name)
            cmd = _cmdline(pid)
            out[pid] = program(cmd, servo_pid, pid)
            try:
                tids = [int(t.name) for t in (p / 'task').iterdir()]
            except OSError:
                tids = []
            for tid in tids:
                out.setdefault(tid, out[pid])
            if examples is not None and cmd:
                examples.setdefault(out[pid], cmd[:160])
    return out


def parse(text: str) -> list[tuple[float, int, int, int, float, float]]:
    """``perf sched timehist`` lines: (end of the run [s], cpu, tid, pid, scheduler delay [ms],
    run time [ms]), in time order."""
    out = []
    for line in text.splitlines():
        m = TIMEHIST_LINE.match(line)
        if m:
            t, cpu, _, a, b, _wait, sch, run = m.groups()[:8]
            tid, pid = (int(a), int(b)) if b else (int(a), int(a))
            out.append((float(t), int(cpu), tid, pid, float(sch), float(run)))
    return out


def analyse(runs, servo_pid: int, names: dict[int, str]) -> dict:
    """The servo workers' scheduler delays, who held the core when they were late, and the
    servo gaps with the program on each core."""
    name = lambda pid: names.get(pid, 'exited')  # noqa: E731
    # a tick worker: any thread of the servo process (it runs nothing else), by its process
    # id or, where the trace gives only the thread's, by that
    servo = lambda r: r[3] == servo_pid or names.get(r[2]) == 'servo process'  # noqa: E731
    per_cpu: dict[int, list] = collections.defaultdict(list)
    for r in runs:
        per_cpu[r[1]].append(r)
    delays, late_holders, held_for = [], collections.Counter(), collections.defaultdict(list)
    for cpu, rs in per_cpu.items():
        for prev, r in zip(rs, rs[1:]):
            if not servo(r):
                continue
            delays.append(r[4])
            if r[4] > LATE_MS and not servo(prev):
                late_holders[name(prev[3])] += 1
                held_for[name(prev[3])].append(prev[5])
    ticks = [r[0] for r in runs if servo(r)]
    gaps = [(a, b) for a, b in zip(ticks, ticks[1:]) if (b - a) * 1e3 > GAP_MS]
    gap_holders = collections.Counter()
    ends = {c: [r[0] for r in rs] for c, rs in per_cpu.items()}
    for g0, g1 in gaps:
        pair = []
        for cpu in sorted(per_cpu):
            occ = collections.Counter()   # time each program held this core during the gap
            for r in per_cpu[cpu][bisect.bisect_left(ends[cpu], g0):]:
                s = r[0] - r[5] * 1e-3
                if s >= g1:
                    break
                occ[name(r[3])] += min(r[0], g1) - max(s, g0)
            pair.append(occ.most_common(1)[0][0] if occ else 'idle')
        gap_holders[' + '.join(pair)] += 1
    d = np.asarray(delays) if delays else np.zeros(1)
    span = (runs[-1][0] - runs[0][0]) if runs else 0.0
    return {'wakeups': len(delays), 'p50': float(np.percentile(d, 50)),
            'p99': float(np.percentile(d, 99)), 'max': float(d.max()),
            'late_pct': 100.0 * float((d > LATE_MS).mean()), 'late_holders': late_holders,
            'held_for': held_for, 'gaps': len(gaps), 'gap_holders': gap_holders,
            'seconds': span}


def cannot_trace() -> str:
    """Why this machine cannot be traced here ('' when it can): no perf, or no right to record
    every CPU's scheduler events."""
    if shutil.which('perf') is None:
        return 'perf is not installed (Debian: apt-get install linux-perf)'
    with tempfile.TemporaryDirectory(prefix='bench-sched-check-') as td:
        r = subprocess.run(['perf', 'sched', 'record', '-a', '-o', f'{td}/check.data', '--',
                            'true'], capture_output=True, text=True)
    if r.returncode != 0:
        return ('perf cannot trace the whole machine (root, or kernel.perf_event_paranoid <= '
                f'-1, is needed): {r.stderr.strip()[-200:]}')
    return ''


def trace_one(kind: str, prio: int, a, d: Path) -> tuple[dict, dict]:
    """One run of ``kind`` at servo priority ``prio``; the trace analysed and the run's JSON."""
    result: dict = {}
    th = threading.Thread(target=lambda: result.update(
        run_one(kind, prio, a.duration, 'auto', d, 0, a.view)), daemon=True)
    th.start()
    servo = find_servo_process(180.0)
    if servo is None:
        th.join()
        raise SystemExit(f'{kind}: no servo process appeared: {result.get("error", "")}')
    time.sleep(a.settle)   # the graph ready, the browser on its page
    data = d / f'{kind}_{prio}.perf'
    examples: dict = {}
    names = names_now(servo, examples)
    rec = subprocess.run(['perf', 'sched', 'record', '-a', '-o', str(data), '--', 'sleep',
                          str(a.seconds)], capture_output=True, text=True)
    names.update({k: v for k, v in names_now(servo, examples).items() if k not in names})
    th.join()
    if rec.returncode != 0:
        raise SystemExit(f'perf sched record failed (root or kernel.perf_event_paranoid <= -1 '
                         f'is needed): {rec.stderr.strip()[-300:]}')
    hist = subprocess.run(['perf', 'sched', 'timehist', '-i', str(data)], capture_output=True,
                          text=True)
    s = analyse(parse(hist.stdout), servo, names)
    s['examples'] = examples
    return s, result


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--configs', default='sim:0,launch:0', help='KIND:SERVO_PRIORITY, ...')
    ap.add_argument('--busy', type=int, default=8)
    ap.add_argument('--no-view', dest='view', action='store_false',
                    help='without the browser view (default: with it)')
    ap.add_argument('--duration', type=float, default=30.0, help='each run [s]')
    ap.add_argument('--settle', type=float, default=8.0,
                    help='from the servo process\'s start to the trace [s]')
    ap.add_argument('--seconds', type=float, default=8.0, help='traced [s]')
    ap.add_argument('--page', default='sched_trace')
    ap.add_argument('--no-page', action='store_true')
    a = ap.parse_args()
    why = cannot_trace()
    if why:
        print(f'skipped: {why}')
        return 0
    sections = []
    with tempfile.TemporaryDirectory(prefix='bench-sched-') as td:
        for c in a.configs.split(','):
            kind, prio = c.split(':')[0], int(c.split(':')[1])
            with busy(a.busy):
                s, j = trace_one(kind, prio, a, Path(td))
            label = f'{kind} prio {prio}, {a.busy} busy' + (', view' if a.view else '')
            j = row(label, a.busy, 0.0, j)
            lines = [f'## {label}', '',
                     f'Run: rate {j["rate_hz"] or 0:.1f} Hz, periods lost {j["periods_lost"]}, '
                     f'longest gap {j["max_gap_ms"] or 0:.1f} ms (the whole run); traced '
                     f'{s["seconds"]:.1f} s of it.', '',
                     '| worker wake-ups | delay p50 ms | p99 ms | max ms | over 1 ms % | gaps |',
                     '|---|---|---|---|---|---|',
                     f'| {s["wakeups"]} | {s["p50"]:.3f} | {s["p99"]:.2f} | {s["max"]:.2f} | '
                     f'{s["late_pct"]:.2f} | {s["gaps"]} |', '',
                     'A worker late by more than 1 ms: the program that held its core, and how '
                     'long that program had run when it let the worker in.', '',
                     '| holder | times | its run p50 ms | max ms |', '|---|---|---|---|']
            for who, n in s['late_holders'].most_common():
                h = np.asarray(s['held_for'][who])
                lines.append(f'| {who} | {n} | {np.median(h):.2f} | {h.max():.2f} |')
            lines += ['', 'Servo gaps (no worker ran for > 1.9 ms): the program on each core.',
                      '', '| cores | gaps |', '|---|---|']
            lines += [f'| {who} | {n} |' for who, n in s['gap_holders'].most_common()]
            shown = set(s['late_holders']) | {w for k in s['gap_holders'] for w in k.split(' + ')}
            lines += ['', 'The programs, as named from a command line of theirs:', '',
                      '| program | a command line |', '|---|---|']
            lines += [f'| {k} | `{v}` |' for k, v in sorted(s['examples'].items()) if k in shown]
            sections.append('\n'.join(lines))
            print(sections[-1], flush=True)
    body = ('\n\n'.join(sections) + '\n\nThe servo process has two tick workers, one pinned to '
            'each core; a period is lost only when both are late. Scheduler delay: from a '
            "worker's wake-up to its run (`perf sched timehist`). `its run`: how long the "
            'holder had run without a switch when the worker got the core.\n')
    if not a.no_page:
        print('page:', write_page(a.page, 'Scheduler trace of the servo loop', body))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
