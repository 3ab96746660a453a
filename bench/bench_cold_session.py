"""The first session on a cold numba cache: is any kernel compiled after the graph is ready?

Runs ``haptic-anfis sim`` and ``haptic-anfis launch`` for ``--duration`` s each, with
``NUMBA_CACHE_DIR`` pointing at a fresh directory (a fresh install before ``haptic-anfis warmup``,
or a cache an upgrade made stale) and numba's cache log on (``NUMBA_DEBUG_CACHE``), then once
more on the cache the first run filled. It prints the kernels compiled (saved to the cache) after
each process said it was ready, and the run's dropout figures: a kernel compiled at the first
touch stops the contact stream while it compiles, and the servo loop renders 0 N once its model
expires (issue 32). Usage: ``python bench/bench_cold_session.py [--duration 10] [--no-page]``.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / 'bench'))

from bench_servo_load import fmt, last_json, loop_rate  # noqa: E402

CLI = [sys.executable, '-m', 'haptic_anfis.cli']
COLS = ('layout', 'cache', 'compiled', 'compiled_after_ready', 'zero_ticks', 'dropout_ms',
        'expired', 'err_rms_pct', 'rate_hz')


def compiled_after_ready(text: str) -> int:
    """Kernels numba saved to its cache after the log's last 'ready after' line."""
    lines = text.splitlines()
    ready = max((i for i, line in enumerate(lines) if 'ready after' in line), default=-1)
    return sum('data saved to' in line for line in lines[ready + 1:])


def one(layout: str, cache: Path, work: Path, duration: float) -> dict:
    """One run of ``layout`` ('sim' or 'launch') on the numba cache ``cache``."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), NUMBA_DEBUG_CACHE='1',
               PYTHONPATH=str(ROOT))
    logs = work / f'logs_{layout}_{len(list(work.iterdir()))}'
    cmd = [*CLI, layout, '--duration', str(duration), '--json']
    if layout == 'launch':
        cmd += ['--localhost', '--log-dir', str(logs)]
    # one stream, in order: numba's cache log (stdout) against the ready line (the ROS log)
    r = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env,
                       timeout=duration + 900)
    j = last_json(r.stdout) or {}
    # each node's own log (launch) or the one process's output (sim)
    texts = ([p.read_text(errors='replace') for p in sorted(logs.glob('*.log'))]
             if layout == 'launch' else [r.stdout])
    return {'layout': layout, 'compiled': sum(t.count('data saved to') for t in texts),
            'compiled_after_ready': sum(map(compiled_after_ready, texts)),
            'zero_ticks': j.get('zero_force_ticks'), 'dropout_ms': j.get('longest_dropout_ms'),
            'expired': j.get('ticks_expired'), 'err_rms_pct': j.get('force_error_rms_pct'),
            'rate_hz': loop_rate(j),
            'error': None if j else f'exit {r.returncode}: {r.stdout[-300:]}'}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--duration', type=float, default=10.0)
    ap.add_argument('--no-page', action='store_true', help='print only')
    a = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory(prefix='bench-cold-') as td:
        for layout in ('sim', 'launch'):
            cache = Path(td) / f'numba_{layout}'
            cache.mkdir()
            for state in ('cold', 'warm'):
                r = one(layout, cache, Path(td), a.duration)
                r['cache'] = state
                rows.append(r)
                print(' '.join(f'{k}={fmt(r.get(k))}' for k in COLS), r['error'] or '',
                      flush=True)
    lines = ['| ' + ' | '.join(COLS) + ' |', '|' + '---|' * len(COLS)]
    lines += ['| ' + ' | '.join(fmt(r.get(k)) for k in COLS) + ' |' for r in rows]
    notes = (f'\n\n{a.duration:g} s per run, the driver\'s defaults, no other load. `cache`: '
             '`cold` on an empty `NUMBA_CACHE_DIR`, `warm` on the one the cold run filled. '
             '`compiled`: kernels numba compiled and saved in the whole run; '
             '`compiled_after_ready`: kernels numba compiled and saved after the process (each '
             'node\'s own log in `launch`) said it was ready — each one a stop of that process '
             'in the middle of the session; `zero_ticks`: ticks in contact at 0 N while the '
             'ideal force is > 1 N (`dropout_ms`: the longest run); `expired`: ticks whose local '
             'model had expired; `err_rms_pct`: applied-force RMS error, % of the RMS ideal '
             'force. Target (issue 32): no dropout; so nothing compiled after ready.\n')
    table = '\n'.join(lines)
    print(table)
    if not a.no_page:
        from _page import write_page
        cmd = ('.venv/bin/python bench/bench_cold_session.py ' + ' '.join(sys.argv[1:])).strip()
        print('page:', write_page('cold_session', 'The first session on a cold numba cache',
                                  table + notes, command=cmd))
    return 0 if all(r['error'] is None for r in rows) else 1


if __name__ == '__main__':
    sys.exit(main())
