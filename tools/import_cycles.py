#!/usr/bin/env python3
"""Find import cycles between the package's modules, function-level imports included.

Reads every module of ``haptic_anfis`` with :mod:`ast` (nothing is imported), collects EVERY
``import`` / ``from ... import`` statement wherever it stands (module level, inside functions,
under ``if TYPE_CHECKING``), resolves relative imports, and takes ``from pkg import name`` as an
import of ``pkg.name`` when that is a module. Cycles are the strongly connected components of
that graph with more than one module (or a module importing itself).

Usage: ``python tools/import_cycles.py [PACKAGE_DIR]`` prints each cycle as one line
(``a -> b -> a``) and exits 1 if there is any; ``test/test_import_cycles.py`` asserts none.
"""
from __future__ import annotations

import ast
import sys
from pathlib import Path

__all__ = ['module_files', 'import_graph', 'cycles', 'cycle_path', 'main']


def module_files(package_dir: Path) -> dict[str, Path]:
    """{dotted module name: file} of every ``.py`` below ``package_dir`` (a package)."""
    package_dir = Path(package_dir).resolve()
    root = package_dir.parent
    out = {}
    for f in sorted(package_dir.rglob('*.py')):
        parts = list(f.relative_to(root).with_suffix('').parts)
        if parts[-1] == '__init__':
            parts = parts[:-1]
        out['.'.join(parts)] = f
    return out


def _resolve(module: str, is_package: bool, level: int, target: str | None) -> str:
    if level == 0:
        return target or ''
    base = module.split('.') if is_package else module.split('.')[:-1]
    base = base[:len(base) - (level - 1)] if level > 1 else base
    return '.'.join(base + ([target] if target else []))


def import_graph(package_dir: Path) -> dict[str, set[str]]:
    """{module: the package modules it imports anywhere in its body}."""
    files = module_files(package_dir)
    graph: dict[str, set[str]] = {m: set() for m in files}
    for mod, f in files.items():
        is_pkg = f.name == '__init__.py'
        tree = ast.parse(f.read_text(), str(f))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                for a in node.names:
                    name = a.name
                    while name and name not in files:
                        name = name.rpartition('.')[0]
                    if name:
                        graph[mod].add(name)
            elif isinstance(node, ast.ImportFrom):
                base = _resolve(mod, is_pkg, node.level, node.module)
                for a in node.names:
                    sub = f'{base}.{a.name}'
                    if sub in files:
                        graph[mod].add(sub)
                    elif base in files:
                        graph[mod].add(base)
    for mod in graph:
        graph[mod].discard(mod)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    counter = [0]

    def strong(v: str) -> None:  # iterative Tarjan: no recursion limit on deep graphs
        work = [(v, iter(sorted(graph.get(v, ()))))]
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        while work:
            node, it = work[-1]
            for w in it:
                if w not in index:
                    index[w] = low[w] = counter[0]
                    counter[0] += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(graph.get(w, ())))))
                    break
                if w in on:
                    low[node] = min(low[node], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    comp = []
                    while True:
                        w = stack.pop()
                        on.discard(w)
                        comp.append(w)
                        if w == node:
                            break
                    if len(comp) > 1:
                        out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            strong(v)
    return sorted(out)


def cycle_path(graph: dict[str, set[str]], comp: list[str]) -> list[str]:
    """One concrete cycle through the component ``comp``: [a, b, ..., a] (breadth-first)."""
    members = set(comp)
    start = comp[0]
    prev: dict[str, str] = {}
    frontier = [start]
    while frontier:
        nxt = []
        for v in frontier:
            for w in sorted(graph[v] & members):
                if w == start:
                    path = [v]
                    while path[-1] != start:
                        path.append(prev[path[-1]])
                    return list(reversed(path)) + [start]
                if w not in prev:
                    prev[w] = v
                    nxt.append(w)
        frontier = nxt
    return comp


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    pkg = Path(argv[0]) if argv else Path(__file__).resolve().parents[1] / 'haptic_anfis'
    g = import_graph(pkg)
    found = cycles(g)
    for comp in found:
        print(' -> '.join(cycle_path(g, comp)) + f'   ({len(comp)} modules in the loop)')
    if not found:
        print(f'no import cycles among {len(g)} modules (function-level imports included)')
    return 1 if found else 0


if __name__ == '__main__':
    sys.exit(main())
