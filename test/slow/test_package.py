"""The package is a valid ament_python package: colcon builds it into the layout ros2 run expects."""
from __future__ import annotations

import ast
import os
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
BIN = Path(sys.executable).parent


def _nodes() -> list[str]:
    """Executable names of the NODES dict in setup.py (parsed, not imported: setup.py runs setup())."""
    tree = ast.parse((ROOT / 'setup.py').read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.AnnAssign) and getattr(node.target, 'id', None) == 'NODES':
            return list(ast.literal_eval(node.value).keys())
    raise AssertionError('setup.py has no NODES dict')


def test_package_xml_is_format_3_and_declares_runtime_dependencies():
    root = ET.parse(ROOT / 'package.xml').getroot()
    assert root.tag == 'package' and root.get('format') == '3'
    assert root.findtext('name') == 'haptic_anfis'
    deps = {e.text for e in root.iter('exec_depend')}
    for dep in ('rclpy', 'geometry_msgs', 'std_srvs', 'python3-numpy', 'python3-scipy',
                'python3-yaml'):
        assert dep in deps
    assert root.find('export/build_type').text == 'ament_python'


def test_top_level_layout():
    for p in ('package.xml', 'setup.py', 'setup.cfg', 'haptic_anfis/__init__.py',
              'resource/haptic_anfis', 'test', 'config', 'README.md', 'Makefile', '.ci/run'):
        assert (ROOT / p).exists(), p
    cfg = (ROOT / 'setup.cfg').read_text()
    assert 'script_dir=$base/lib/haptic_anfis' in cfg
    assert 'install_scripts=$base/lib/haptic_anfis' in cfg


@pytest.mark.skipif(not (BIN / 'colcon').exists(), reason='colcon is installed by "make venv"')
def test_colcon_build_installs_executables_and_ament_index(tmp_path):
    src = tmp_path / 'ws' / 'src' / 'haptic_anfis'
    shutil.copytree(ROOT, src, ignore=shutil.ignore_patterns(
        '.venv*', '.git', 'build', 'install', 'log', 'out', '__pycache__', '*.egg-info',
        '.pytest_cache', '.hypothesis', '.whl', '.fe_work'))
    env = {k: v for k, v in os.environ.items() if k != '_ROS_WHEELS_BOOTSTRAP_COMPLETE'}
    env['PATH'] = f'{BIN}{os.pathsep}{env.get("PATH", "")}'
    ws = tmp_path / 'ws'
    proc = subprocess.run([str(BIN / 'colcon'), 'build', '--base-paths', 'src'], cwd=ws, env=env,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    install = ws / 'install' / 'haptic_anfis'
    lib = install / 'lib' / 'haptic_anfis'
    for exe in ['haptic-anfis', *_nodes()]:
        assert (lib / exe).is_file() and os.access(lib / exe, os.X_OK), exe
    assert (install / 'share' / 'ament_index' / 'resource_index' / 'packages' / 'haptic_anfis').is_file()
    assert (install / 'share' / 'haptic_anfis' / 'package.xml').is_file()
    assert list((install / 'share' / 'haptic_anfis' / 'config').glob('*.yaml'))
    # The installed command runs from the install space (as `ros2 run` would start it).
    site = next(install.glob('lib/python3*/site-packages'))
    env['PYTHONPATH'] = str(site)
    out = subprocess.run([str(lib / 'haptic-anfis'), '--version'], env=env, cwd=tmp_path,
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and '0.1.0' in out.stdout, out.stderr
    # Data files travel with the package (default dataset and model).
    assert list(site.glob('haptic_anfis*/**/default_model.json')) or \
        (site / 'haptic_anfis' / 'data' / 'default_model.json').is_file()
