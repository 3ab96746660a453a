"""numba's cache directory when the package directory is read-only (issue 20, cold start)."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from haptic_anfis import numba_cache
from haptic_anfis.warm import warm

ROOT = Path(__file__).resolve().parents[2]


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


def test_warm_rejects_an_unknown_part():
    with pytest.raises(ValueError, match=r"unknown part\(s\) \['servo'\]; expected some of"):
        warm(('servo',))


def _cache_files(d: Path) -> dict[str, int]:
    return {str(p.relative_to(d)): p.stat().st_mtime_ns for p in d.rglob('*') if p.is_file()}


@pytest.mark.slow
def test_the_warm_up_compiles_the_servo_tick_the_driver_then_loads(tmp_path):
    """`haptic-anfis warmup` compiles the servo tick into an empty cache; the loop the simulated
    Falcon's driver then builds (its own process, a tick trace, a held script) finds every kernel
    there and compiles nothing (no cache file added or rewritten)."""
    cache = tmp_path / 'numba'
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), PYTHONPATH=str(ROOT))
    warm = ('from haptic_anfis.warm import warm; '
            "print(sorted(warm(('servo_tick',))))")
    out = subprocess.run([sys.executable, '-c', warm], env=env, capture_output=True, text=True,
                         timeout=600)
    assert out.returncode == 0 and "['servo_tick']" in out.stdout, out.stderr
    files = _cache_files(cache)
    for kernel in ('run', 'tick', '_fault'):
        assert any(f'native_tick.{kernel}-' in f and f.endswith('.nbc') for f in files), kernel
    driver = (
        'from haptic_anfis.device.palpation import PalpationScript\n'
        'from haptic_anfis.device.servo_native import NativeServoLoop\n'
        'from haptic_anfis.device.start_gate import HeldScript\n'
        'from haptic_anfis.device.trace import TickTrace\n'
        'from haptic_anfis.resources import config_file\n'
        "s = HeldScript(PalpationScript.from_yaml(config_file('palpation.yaml')), held=True)\n"
        'NativeServoLoop(s, process=True, trace=TickTrace(max_rows=100), workers=2).compile()\n')
    out = subprocess.run([sys.executable, '-c', driver], env=env, capture_output=True, text=True,
                         timeout=600)
    assert out.returncode == 0, out.stderr
    assert _cache_files(cache) == files
