"""numba's cache directory when the package directory is read-only (issue 20, cold start)."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from haptic_anfis import numba_cache

ROOT = Path(__file__).resolve().parents[1]


def test_writable_package_keeps_the_in_tree_cache(tmp_path):
    (tmp_path / 'anfis').mkdir()
    assert numba_cache.choose_cache_dir(tmp_path) is None


@pytest.mark.skipif(os.geteuid() == 0, reason='root writes anywhere')
def test_read_only_package_uses_the_user_cache_dir(tmp_path, monkeypatch):
    pkg = tmp_path / 'pkg'
    (pkg / 'anfis').mkdir(parents=True)
    pkg.chmod(0o555)
    monkeypatch.setenv('XDG_CACHE_HOME', str(tmp_path / 'cache'))
    monkeypatch.delenv('NUMBA_CACHE_DIR', raising=False)
    try:
        assert numba_cache.choose_cache_dir(pkg) == tmp_path / 'cache' / 'haptic_anfis' / 'numba'
        assert numba_cache.configure(pkg) == str(tmp_path / 'cache' / 'haptic_anfis' / 'numba')
        assert os.environ['NUMBA_CACHE_DIR'] == str(tmp_path / 'cache' / 'haptic_anfis' / 'numba')
        # unwritable user cache too: a per-user temporary directory
        (tmp_path / 'cache').mkdir(exist_ok=True)
        (tmp_path / 'cache').chmod(0o555)
        monkeypatch.delenv('NUMBA_CACHE_DIR')
        d = numba_cache.choose_cache_dir(pkg)
        assert d is not None and d.name == f'haptic_anfis-numba-{os.getuid()}'
    finally:
        pkg.chmod(0o755)
        (tmp_path / 'cache').chmod(0o755)


def test_a_users_numba_cache_dir_wins(tmp_path, monkeypatch):
    monkeypatch.setenv('NUMBA_CACHE_DIR', str(tmp_path / 'mine'))
    assert numba_cache.configure(tmp_path / 'nowhere') == str(tmp_path / 'mine')


def test_package_import_sets_it_before_numba_loads(tmp_path):
    """In a fresh interpreter whose package directory is read-only, numba sees the user cache."""
    code = ('import haptic_anfis.numba_cache as c, os; from pathlib import Path;'
            'print(c.configure(Path(os.environ["PKG"])))')
    pkg = tmp_path / 'ro'
    (pkg / 'anfis').mkdir(parents=True)
    pkg.chmod(0o555)
    env = {k: v for k, v in os.environ.items() if k != 'NUMBA_CACHE_DIR'}
    env.update(PKG=str(pkg), XDG_CACHE_HOME=str(tmp_path / 'xdg'), PYTHONPATH=str(ROOT))
    try:
        out = subprocess.run([sys.executable, '-c', code], env=env, capture_output=True,
                             text=True, timeout=120).stdout.strip()
    finally:
        pkg.chmod(0o755)
    if os.geteuid() != 0:
        assert out.splitlines()[-1] == str(tmp_path / 'xdg' / 'haptic_anfis' / 'numba')
