"""The trainee record's costs: storing one session (one transaction, WAL), reading a trainee's
history, and concurrent writer processes (every session kept, how long the busy ones waited).

    .venv/bin/python bench/bench_record.py [--sessions 200] [--writers 4] [--per-writer 50]

Prints a table and writes docs/measurements/record.md. Synthetic reports (the fields an exam
report has, with a ~6 kB JSON like a real one); a temporary file, removed afterwards.
"""
from __future__ import annotations

import argparse
import os
import sqlite3
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from harness import write_page  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def report(rng) -> dict:
    deep = float(rng.uniform(0, 100))
    return {'coverage_pct': {'light': deep, 'medium': deep, 'deep': deep},
            'duration_s': float(rng.uniform(30, 300)), 'contact_s': 20.0, 'hits': 1, 'misses': 0,
            'false_marks': int(rng.integers(0, 3)), 'score': float(rng.uniform(0, 100)),
            'verdict': 'retry', 'pattern': 'vertical_strip', 'case': 'default',
            'lesions': [{'name': 'idc', 'found': True}],
            'marks': [{'index': k, 'y_mm': 1.0, 'z_mm': 2.0} for k in range(5)],
            'notes': ['x' * 80] * 60}


WRITER = textwrap.dedent('''
    import json, sys, time
    import numpy as np
    sys.path.insert(0, {bench!r})
    from bench_record import report
    from haptic_anfis.record import store_session
    db, who, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
    rng = np.random.default_rng(int(who[1:]))
    print('ready', flush=True)
    sys.stdin.readline()
    worst = 0.0
    t0 = time.perf_counter()
    for _ in range(n):
        t = time.perf_counter()
        store_session(db, who, report(rng), case_level=1)
        worst = max(worst, time.perf_counter() - t)
    print(json.dumps({{'wall': time.perf_counter() - t0, 'worst': worst}}), flush=True)
''')


def concurrent(db: Path, writers: int, per: int) -> dict:
    import json
    script = db.parent / 'writer.py'
    script.write_text(WRITER.format(bench=str(Path(__file__).resolve().parent)))
    env = {**os.environ, 'PYTHONPATH': os.pathsep.join([str(ROOT), os.environ.get(
        'PYTHONPATH', '')])}
    procs = [subprocess.Popen([sys.executable, str(script), str(db), f'w{k}', str(per)],
                              env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
             for k in range(writers)]
    for p in procs:
        assert p.stdout.readline().strip() == 'ready'
    t0 = time.perf_counter()
    for p in procs:
        p.stdin.write('go\n')
        p.stdin.flush()
    outs = [json.loads(p.communicate(timeout=600)[0].strip().splitlines()[-1]) for p in procs]
    wall = time.perf_counter() - t0
    with sqlite3.connect(db) as c:
        kept = c.execute('SELECT count(*) FROM sessions').fetchone()[0]
    return {'wall': wall, 'kept': kept, 'worst': max(o['worst'] for o in outs)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--sessions', type=int, default=200)
    ap.add_argument('--writers', type=int, default=4)
    ap.add_argument('--per-writer', type=int, default=50)
    args = ap.parse_args()
    from haptic_anfis.record import history, store_session
    rng = np.random.default_rng(0)
    with tempfile.TemporaryDirectory() as tmp:
        db = Path(tmp) / 'trainees.sqlite'
        times = []
        for _ in range(args.sessions):
            t = time.perf_counter()
            store_session(db, 'bench', report(rng), case_level=1)
            times.append(time.perf_counter() - t)
        t = time.perf_counter()
        h = history(db, 'bench')
        t_hist = time.perf_counter() - t
        assert len(h) == args.sessions
        size = db.stat().st_size
        db2 = Path(tmp) / 'concurrent.sqlite'
        con = concurrent(db2, args.writers, args.per_writer)
    ms = np.array(times) * 1e3
    total = args.writers * args.per_writer
    rows = [
        ('store one session (open, one transaction, close)',
         f'median {np.median(ms):.1f} ms, p95 {np.percentile(ms, 95):.1f} ms, max {ms.max():.1f} ms'
         f' over {args.sessions}'),
        (f'history of {args.sessions} sessions', f'{t_hist * 1e3:.1f} ms'),
        (f'file size after {args.sessions} sessions', f'{size / 1024:.0f} KiB '
         f'({size / args.sessions / 1024:.1f} KiB per session)'),
        (f'{args.writers} writer processes x {args.per_writer} sessions at once',
         f'{con["kept"]} of {total} kept in {con["wall"]:.1f} s; slowest single store '
         f'{con["worst"] * 1e3:.0f} ms'),
    ]
    table = '| what | measured |\n| --- | --- |\n' + '\n'.join(f'| {a} | {b} |' for a, b in rows)
    print(table)
    print(f'load: {os.getloadavg()[0]:.1f}')
    write_page('record', 'Trainee record (SQLite)', table + '\n\nEvery session of every writer '
               'must be kept (WAL, busy timeout, retries); the times are under the load above.',
               command=f'.venv/bin/python bench/bench_record.py --sessions {args.sessions} '
                       f'--writers {args.writers} --per-writer {args.per_writer}')
    return 0 if con['kept'] == total else 1


if __name__ == '__main__':
    sys.exit(main())
