"""A simulated trainee's record end to end: live exams (`haptic-anfis exam run --trainee-id ...
--next`, the one-process ROS graph with the simulated Falcon), stored in a fresh trainee record,
then `trainees progress --figure`.

    .venv/bin/python bench/bench_trainee_curve.py [--scripts careless,careless,systematic,...]

Each exam draws its case with --next (level 1 until level 1 is mastered, then level 2...).
Prints the progress table and writes docs/measurements/trainee_curve.md and
docs/measurements/trainee_curve.png (the learning curve). Minutes: one exam is ~30-60 s.
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
from harness import PAGES_DIR, write_page  # noqa: E402

DEFAULT = 'careless,careless,systematic,systematic,systematic,systematic,careless,systematic'


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--scripts', default=DEFAULT,
                    help='the simulated trainee of each session, comma-separated')
    args = ap.parse_args()
    exe = [sys.executable, '-m', 'haptic_anfis.cli']
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        db = str(Path(tmp) / 'trainees.sqlite')
        for k, script in enumerate(args.scripts.split(',')):
            t = time.time()
            p = subprocess.run([*exe, 'exam', 'run', '--trainee', script, '--trainee-id',
                                'sim01', '--next', '--db', db, '--json'],
                               capture_output=True, text=True, timeout=900)
            if p.returncode != 0:
                print(p.stdout[-2000:], p.stderr[-2000:], file=sys.stderr)
                return 1
            r = json.loads(p.stdout.strip().splitlines()[-1])
            rows.append((k + 1, script, r['case'], r['coverage_pct']['deep'], r['hits'],
                         r['misses'], r['false_marks'], r['verdict'], time.time() - t))
            print(f'session {k + 1}: {script} on {r["case"]}: deep {r["coverage_pct"]["deep"]}'
                  f' %, {r["verdict"]} ({time.time() - t:.0f} s)', flush=True)
        png = PAGES_DIR / 'trainee_curve.png'
        png.parent.mkdir(parents=True, exist_ok=True)
        p = subprocess.run([*exe, 'trainees', '--db', db, 'progress', 'sim01', '--figure',
                            str(png)], capture_output=True, text=True, check=True)
        print(p.stdout)
    table = ('| session | simulated trainee | case (drawn by --next) | deep coverage % | hits | '
             'misses | false marks | verdict | wall s |\n| --- | --- | --- | --- | --- | --- | '
             '--- | --- | --- |\n' + '\n'.join('| ' + ' | '.join(
                 f'{v:.0f}' if isinstance(v, float) else str(v) for v in r) + ' |'
                 for r in rows))
    body = (table + '\n\n`trainees progress sim01`:\n\n```\n' + p.stdout.rstrip() + '\n```\n\n'
            '![learning curve](trainee_curve.png)\n')
    print(f'load: {os.getloadavg()[0]:.1f}')
    write_page('trainee_curve', 'Trainee record: a simulated trainee across sessions', body,
               command=f'.venv/bin/python bench/bench_trainee_curve.py --scripts {args.scripts}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
