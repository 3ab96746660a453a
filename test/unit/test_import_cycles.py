"""No import cycle between the package's modules, function-level imports included (issue 28.3).
tools/import_cycles.py reads the sources with ast; nothing is imported."""
from __future__ import annotations

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
_spec = importlib.util.spec_from_file_location('import_cycles', ROOT / 'tools' / 'import_cycles.py')
ic = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(ic)

def test_the_package_has_no_import_cycle():
    g = ic.import_graph(ROOT / 'haptic_anfis')
    found = ic.cycles(g)
    assert found == [], [' -> '.join(ic.cycle_path(g, c)) for c in found]


def test_the_finder_sees_function_level_and_relative_imports(tmp_path):
    pkg = tmp_path / 'pkg'
    (pkg / 'sub').mkdir(parents=True)
    (pkg / '__init__.py').write_text('')
    (pkg / 'sub' / '__init__.py').write_text('')
    (pkg / 'a.py').write_text('from .sub import b\n')
    (pkg / 'sub' / 'b.py').write_text('def f():\n    from .. import c\n')
    (pkg / 'c.py').write_text('import pkg.a\n')
    (pkg / 'd.py').write_text('from . import c\n')
    g = ic.import_graph(pkg)
    assert g['pkg.a'] == {'pkg.sub.b'} and g['pkg.sub.b'] == {'pkg.c'} and g['pkg.c'] == {'pkg.a'}
    assert ic.cycles(g) == [['pkg.a', 'pkg.c', 'pkg.sub.b']]
    assert ic.cycle_path(g, ['pkg.a', 'pkg.c', 'pkg.sub.b']) == ['pkg.a', 'pkg.sub.b', 'pkg.c',
                                                                 'pkg.a']
