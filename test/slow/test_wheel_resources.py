"""The shipped config/ and data/ are found from an installed wheel as from the source tree
(issue 28.3): build the wheel, install it into a fresh virtualenv, and read every shipped default
from there, outside the source tree. No network: the dependencies come from this interpreter's
site-packages (a .pth line), the build uses this environment's setuptools and wheel."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.slow

PROBE = r'''
import json, sys
from pathlib import Path
import haptic_anfis
from haptic_anfis import resources
from haptic_anfis.exam.config import DEFAULT_CONFIG, load_exam_config
from haptic_anfis.exam.trainee import trainee_path
from haptic_anfis.tissue.scene import DEFAULT_SCENE, load_scene
from haptic_anfis.commands.bench import CONFIG
load_exam_config(); load_scene(DEFAULT_SCENE)
print(json.dumps({'package': haptic_anfis.__file__, 'prefix': sys.prefix,
                  'files': [str(p) for p in (DEFAULT_CONFIG, DEFAULT_SCENE, CONFIG,
                            trainee_path('systematic'), resources.config_file('palpation.yaml'),
                            resources.data_file('default_model.json'))]}))
'''


def test_an_installed_wheel_finds_its_config_and_data(tmp_path):
    pytest.importorskip('wheel')  # bdist_wheel for this environment's setuptools
    src = tmp_path / 'src'
    for d in ('haptic_anfis', 'config', 'resource'):
        shutil.copytree(ROOT / d, src / d, ignore=shutil.ignore_patterns('__pycache__', '*.nbi',
                                                                          '*.nbc'))
    for f in ('setup.py', 'setup.cfg', 'package.xml'):
        shutil.copy(ROOT / f, src / f)
    pip = [sys.executable, '-m', 'pip', '--disable-pip-version-check', '-q']
    subprocess.run([*pip, 'wheel', '--no-deps', '--no-build-isolation', '-w',
                    str(tmp_path / 'dist'), str(src)], check=True, capture_output=True,
                   timeout=300)
    (whl,) = (tmp_path / 'dist').glob('haptic_anfis-*.whl')
    venv = tmp_path / 'venv'
    subprocess.run([sys.executable, '-m', 'venv', '--without-pip', str(venv)], check=True,
                   timeout=120)
    py = venv / 'bin' / 'python'
    site = subprocess.run([str(py), '-c', 'import site; print(site.getsitepackages()[0])'],
                          check=True, capture_output=True, text=True).stdout.strip()
    # Installed as pip lays a wheel out (purelib -> site-packages, .data/data -> the prefix), by
    # hand: pip run from this environment would first UNINSTALL the package from this
    # environment (it sees it installed here, even with --prefix).
    _install_wheel(whl, Path(site), venv)
    deps = [p for p in sys.path if p.endswith('site-packages')]
    (Path(site) / 'deps.pth').write_text('\n'.join(deps) + '\n')  # numpy, yaml, ...
    env = {'PATH': '/usr/bin:/bin', 'HOME': str(tmp_path)}  # no PYTHONPATH, no ament prefix
    out = subprocess.run([str(py), '-c', PROBE], cwd=tmp_path, env=env, capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    r = json.loads(out.stdout.strip().splitlines()[-1])
    assert Path(r['package']).is_relative_to(venv), r
    for f in r['files']:
        assert Path(f).is_file() and Path(f).is_relative_to(venv), f  # not the source tree's
    # every file the package ships in data/ is in the wheel (the FE dent of the default case,
    # the DDS profile, the case library), not only the ones probed above
    shipped = subprocess.run(['git', 'ls-files', 'haptic_anfis/data'], cwd=ROOT, text=True,
                             capture_output=True).stdout.split()
    installed = Path(r['package']).parent
    missing = [f for f in shipped if not (installed.parent / f).is_file()]
    assert shipped and not missing, missing


def _install_wheel(whl: Path, site: Path, prefix: Path) -> None:
    """Lay ``whl`` out like pip: its package into ``site``, ``*.data/data/...`` under ``prefix``
    (``share/haptic_anfis/config`` ...), ``*.data/purelib`` into ``site``."""
    import zipfile
    with zipfile.ZipFile(whl) as z:
        for name in z.namelist():
            top, _, rest = name.partition('/')
            if top.endswith('.data'):
                kind, _, rel = rest.partition('/')
                dest = (prefix if kind == 'data' else site) / rel
            else:
                dest = site / name
            dest.parent.mkdir(parents=True, exist_ok=True)
            dest.write_bytes(z.read(name))
