"""Every benchmark script starts: ``bench/bench_*.py --help`` exits 0 and writes no page.

A script whose imports broke (a module of ``bench/`` renamed, a function moved) fails here
instead of at its next run. The scripts run a few at a time (each is its own Python process)."""
from __future__ import annotations

import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPTS = sorted((ROOT / 'bench').glob('bench_*.py'))
PAGES = ROOT / 'docs' / 'measurements'
#: seconds one script's ``--help`` may take (imports only, on a loaded 2-core machine)
TIMEOUT = 120.0


def _help(script: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        p for p in (str(ROOT), os.environ.get('PYTHONPATH', '')) if p))
    try:
        return subprocess.run([sys.executable, str(script), '--help'], cwd=ROOT, env=env,
                              capture_output=True, text=True, timeout=TIMEOUT)
    except subprocess.TimeoutExpired as exc:
        return subprocess.CompletedProcess(exc.cmd, -1, '', f'timed out after {TIMEOUT:g} s')


def _pages() -> dict[str, int]:
    return {p.name: p.stat().st_mtime_ns for p in PAGES.glob('*.md')}


@pytest.fixture(scope='module')
def helped() -> tuple[dict[str, subprocess.CompletedProcess], dict, dict]:
    """Each script's ``--help`` run, and the measurement pages before and after."""
    before = _pages()
    with ThreadPoolExecutor(max_workers=max(2, os.cpu_count() or 2)) as pool:
        done = dict(zip((s.name for s in SCRIPTS), pool.map(_help, SCRIPTS)))
    return done, before, _pages()


def test_there_are_benchmarks():
    assert len(SCRIPTS) >= 10, SCRIPTS


@pytest.mark.parametrize('name', [s.name for s in SCRIPTS])
def test_help_exits_0(helped, name):
    r = helped[0][name]
    tail = '\n'.join((r.stderr or r.stdout).strip().splitlines()[-5:])
    assert r.returncode == 0, f'bench/{name} --help: exit {r.returncode}:\n{tail}'
    assert 'usage' in r.stdout.lower(), f'bench/{name} --help printed no usage:\n{r.stdout}'


def test_help_writes_no_page(helped):
    _, before, after = helped
    assert after == before, sorted(k for k in after if after[k] != before.get(k))
