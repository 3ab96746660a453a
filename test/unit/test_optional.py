"""haptic_anfis.optional: an optional dependency declared at a module's top, executed on first use."""
from __future__ import annotations

import os
import subprocess
import sys

import pytest

from haptic_anfis.optional import optional


def test_a_missing_package_is_none_and_a_dotted_name_is_refused():
    assert optional('no_such_package_h65c') is None
    with pytest.raises(ValueError, match=r"optional\('scipy.sparse'\): expected a top-level"):
        optional('scipy.sparse')


def test_the_package_runs_at_its_first_use_not_at_the_declaration(tmp_path):
    (tmp_path / 'slowpkg').mkdir()
    (tmp_path / 'slowpkg' / '__init__.py').write_text('import sys\nsys.ran = True\nVALUE = 7\n')
    code = ('import sys\n'
            'from haptic_anfis.optional import optional\n'
            'm = optional("slowpkg")\n'
            'assert not hasattr(sys, "ran"), "executed at the declaration"\n'
            'assert m.VALUE == 7 and sys.ran\n'
            'assert optional("slowpkg") is m and sys.modules["slowpkg"] is m\n')
    env = dict(os.environ, PYTHONPATH=f'{tmp_path}:{os.environ.get("PYTHONPATH", "")}')
    r = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, timeout=120,
                       env=env)
    assert r.returncode == 0, r.stderr


def test_listing_the_cases_loads_neither_felupe_nor_dask():
    """The FE sweep's modules declare felupe and distributed; importing them (what `cases list`
    does) executes neither."""
    code = ('import sys, haptic_anfis.commands.cases, haptic_anfis.tissue.sweep\n'
            'print(sorted(m for m in ("felupe", "distributed", "pypardiso") if m in sys.modules '
            'and not type(sys.modules[m]).__name__.startswith("_Lazy")))\n')
    r = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0 and r.stdout.strip() == '[]', r.stdout + r.stderr
