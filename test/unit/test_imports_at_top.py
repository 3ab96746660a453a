"""Imports stand at the top of the package's modules; an optional dependency is imported there too,
in a ``try: ... except ImportError:`` (trimesh's pattern), never inside a function. Read with ast;
nothing is imported."""
from __future__ import annotations

import ast
from collections import Counter
from pathlib import Path

PKG = Path(__file__).resolve().parents[2] / 'haptic_anfis'

#: rooms (sub-packages; '.' = the top-level modules) with no import inside a function
CLEAN = ('.', 'bag', 'cases', 'commands', 'contact', 'exam', 'pipeline', 'record', 'report',
         'tissue')
#: the most function-level imports a room not yet in CLEAN may hold (may only go down)
CAP = {'anfis': 2, 'device': 12, 'nodes': 99, 'realtime': 3, 'session': 40, 'view': 32}


def function_level_imports(source: str) -> list[int]:
    """Line numbers of the ``import`` / ``from ... import`` statements inside a function."""
    out = set()
    for fn in ast.walk(ast.parse(source)):
        if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            out.update(n.lineno for n in ast.walk(fn)
                       if isinstance(n, (ast.Import, ast.ImportFrom)))
    return sorted(out)


def _room(f: Path) -> str:
    parts = f.relative_to(PKG).parts
    return parts[0] if len(parts) > 1 else '.'


def test_the_finder_sees_imports_in_functions_methods_and_nested_blocks_only():
    src = ('import os\n'
           'try:\n    import felupe\nexcept ImportError:\n    felupe = None\n'
           'def f():\n    import json\n'
           'class C:\n    def m(self):\n        if os:\n            from . import x\n')
    assert function_level_imports(src) == [7, 11]


def test_clean_rooms_import_nothing_inside_a_function_and_the_others_do_not_grow():
    found: dict[str, list[str]] = {}
    counts: Counter[str] = Counter()
    for f in sorted(PKG.rglob('*.py')):
        lines = function_level_imports(f.read_text())
        counts[_room(f)] += len(lines)
        if lines and _room(f) in CLEAN:
            found[str(f.relative_to(PKG))] = lines
    assert found == {}, f'imports inside functions (move them to the top): {found}'
    grown = {r: (counts[r], cap) for r, cap in CAP.items() if counts[r] > cap}
    assert grown == {}, f'function-level imports above the cap (room: (found, cap)): {grown}'
    assert set(counts) <= set(CLEAN) | set(CAP), f'a new room: add it to CLEAN: {set(counts)}'
