"""The graph's threads beside busy processes: how long a thread of a node waits runnable but
unscheduled, with each node's threads free to run on any CPU and kept on one (issue 32).

``launch --record`` (the servo at its default priority, the graph's nodes under the normal
scheduler as for a user without an rtprio limit: ``--graph-priority 0``), beside ``--busy``
processes spinning in this benchmark's session, once per arm: ``free`` (``--graph-pinning off``)
and ``pinned`` (``--graph-pinning on``: each node on the haptic path kept on one CPU; the default, ``auto``, does so where the servo is real-time). A sampler in a
session of its own reads every thread's ``/proc/<pid>/task/<tid>/schedstat`` and state every
20 ms; a *runnable streak* is a run of samples in which a thread was runnable (state R) and got
no CPU time; its length is the time from the sample before it to the sample after it. Printed
per arm: each node's longest streak (and the thread's name), the streaks of 100 ms or more, and
the driver's loop report (expired models, dropout ticks at 0 N with the ideal above 1 N,
force error, ripple; ``bench_servo_load``'s columns).

Usage: ``python bench/bench_graph_threads.py [--minutes 5] [--busy 8] [--arms free,pinned]``.
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

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _busy import busy  # noqa: E402
from _page import markdown_table, run_with_page  # noqa: E402
from bench_servo_load import account, fmt, row, run_one  # noqa: E402

NODES = ('recorder', 'force_server', 'contact_detector', 'falcon_driver')
ARMS = {'free': ('--graph-pinning', 'off'), 'pinned': ('--graph-pinning', 'on')}
COLS = ('arm', 'node', 'longest_ms', 'thread', 'streaks_100ms')
LOOP_COLS = ('arm', 'rate_hz', 'expired', 'zero_ticks', 'dropout_ms', 'trips_contact',
             'err_rms_pct', 'ripple_pct', 'lat_max_ms', 'max_gap_ms', 'sched')


def _node_pids() -> dict[str, int]:
    """{node: pid} of the graph's node processes running now (by their command line)."""
    found = {}
    for p in os.listdir('/proc'):
        if not p.isdigit():
            continue
        try:
            cmd = Path(f'/proc/{p}/cmdline').read_bytes().split(b'\0')
        except OSError:
            continue
        for n in NODES:
            if any(c.endswith(n.encode()) or c.endswith(f'nodes.{n}'.encode())
                   for c in cmd[1:3]):
                # the lowest pid: the falcon driver's servo process has the driver's command
                # line, and it is started after the node
                found[n] = min(int(p), found.get(n, int(p)))
    return found


def sample(out: Path, seconds: float, period: float = 0.02) -> None:
    """The sampler (run in a process of its own session): every ``period`` s one JSON line
    {t, node: {tid: [run_ns, state, name]}} to ``out`` for ``seconds``."""
    end = time.monotonic() + seconds
    pids: dict[str, int] = {}
    with out.open('w') as f:
        while time.monotonic() < end:
            t = time.monotonic()
            if len(pids) < len(NODES):
                pids.update(_node_pids())
            row_: dict = {'t': t}
            for n, pid in pids.items():
                threads = {}
                try:
                    for tid in os.listdir(f'/proc/{pid}/task'):
                        run = Path(f'/proc/{pid}/task/{tid}/schedstat').read_text().split()[0]
                        st = Path(f'/proc/{pid}/task/{tid}/stat').read_text()
                        threads[tid] = [int(run), st[st.rindex(')') + 2],
                                        st[st.index('(') + 1:st.rindex(')')]]
                except OSError:   # ended, or a thread ended between the two reads
                    pass
                row_[n] = threads
            f.write(json.dumps(row_) + '\n')
            time.sleep(max(0.0, period - (time.monotonic() - t)))


def streaks(path: Path, threshold: float = 0.1) -> dict[str, dict]:
    """{node: {longest_ms, thread, streaks_100ms}} from a sampler's file (module doc)."""
    rows = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    out = {n: {'longest_ms': 0, 'thread': '', 'streaks_100ms': 0} for n in NODES}
    start: dict[tuple[str, str], float] = {}
    for prev, cur in zip(rows, rows[1:]):
        for n in NODES:
            for tid, (run, state, name) in cur.get(n, {}).items():
                before = prev.get(n, {}).get(tid)
                key = (n, tid)
                if before is not None and state == 'R' and run == before[0]:
                    start.setdefault(key, prev['t'])
                    continue
                if key in start:   # the streak ended at this sample
                    ms = (cur['t'] - start.pop(key)) * 1e3
                    o = out[n]
                    o['streaks_100ms'] += ms >= threshold * 1e3
                    if ms > o['longest_ms']:
                        o['longest_ms'], o['thread'] = round(ms), name
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--minutes', type=float, default=5.0, help='per arm (default 5)')
    ap.add_argument('--busy', type=int, default=8)
    ap.add_argument('--arms', default='free,pinned')
    ap.add_argument('--page', default='graph_threads')
    a = ap.parse_args()
    arms = [x for x in a.arms.split(',') if x]
    for x in arms:
        if x not in ARMS:
            ap.error(f'--arms: unknown arm {x!r}; expected some of {", ".join(ARMS)}')
    print(account())
    print(f'{a.busy} busy processes in this benchmark\'s session; {a.minutes:g} min per arm; '
          f'{os.cpu_count()} CPUs')
    stats, loops = [], []
    with busy(a.busy), tempfile.TemporaryDirectory(prefix='graph_threads_') as tmp:
        d = Path(tmp)
        for arm in arms:
            samples = d / f'{arm}.jsonl'
            sampler = subprocess.Popen(
                [sys.executable, __file__, '--sample', str(samples), str(a.minutes * 60 + 30)],
                start_new_session=True)
            load = os.getloadavg()[0]
            j = run_one('launch', 50, a.minutes * 60, 'auto', d, graph_priority=0,
                        launch_args=('--graph-priority', '0', *ARMS[arm]))
            sampler.terminate()
            sampler.wait()
            for n, s in streaks(samples).items():
                stats.append({'arm': arm, 'node': n, **s})
            loops.append({**row(f'launch {arm}', a.busy, load, j), 'arm': arm})
    print('\nrunnable streaks (runnable, no CPU time) per node')
    print(markdown_table(stats, COLS, fmt))
    print('\nthe loop (the driver\'s report; columns as bench_servo_load\'s)')
    print('| ' + ' | '.join(LOOP_COLS) + ' |\n|' + '---|' * len(LOOP_COLS))
    for r in loops:
        print('| ' + ' | '.join(fmt(r.get(c)) for c in LOOP_COLS) + ' |')
        if r.get('error'):
            print(f'{r["arm"]}: {r["error"]}')
    return 0


if __name__ == '__main__':
    if sys.argv[1:2] == ['--sample']:
        sample(Path(sys.argv[2]), float(sys.argv[3]))
        sys.exit(0)
    sys.exit(run_with_page(main, __file__, __doc__,
                           name=next((sys.argv[i + 1] for i, x in enumerate(sys.argv[:-1])
                                      if x == '--page'), 'graph_threads')))
