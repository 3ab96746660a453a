"""Tests take their own ROS domain and discovery range, whatever the shell exported (27.5)."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path


def test_an_exported_domain_is_not_inherited_by_the_tests(tmp_path):
    probe = tmp_path / 'test_probe.py'
    probe.write_text('import os\n\ndef test_env():\n'
                     '    print("DOMAIN", os.environ["ROS_DOMAIN_ID"],\n'
                     '          os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"])\n')
    conftest = Path(__file__).resolve().parents[1] / 'conftest.py'
    (tmp_path / 'conftest.py').write_text(conftest.read_text())
    env = {**os.environ, 'ROS_DOMAIN_ID': '7', 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'SUBNET'}
    out = subprocess.run([sys.executable, '-m', 'pytest', '-q', '-s', '-p', 'no:cacheprovider',
                          str(probe)], env=env, cwd=tmp_path, capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr
    line = next(ln for ln in out.stdout.splitlines() if ln.startswith('DOMAIN'))
    _, domain, rng = line.split()
    assert domain != '7' and 40 <= int(domain) < 90 and rng == 'LOCALHOST'
