"""Optional dependencies (the package's extras) that cost seconds to import, loaded on first use.

``felupe = optional('felupe')`` at a module's top declares the dependency where the imports stand
but executes it only when one of its attributes is first used (:class:`importlib.util.LazyLoader`,
the recipe of the importlib documentation): ``haptic-anfis cases list`` imports the FE sweep's
modules without paying felupe's or dask's import (~1 s each on a loaded 2-core machine). None
when the package is not installed; the caller then names the extra to install. A light optional
dependency is imported eagerly instead, in a module-top ``try: ... except ImportError:``.
"""
from __future__ import annotations

import importlib.util
import sys
from types import ModuleType

__all__ = ['optional']


def optional(name: str) -> ModuleType | None:
    """The top-level package ``name``, executed on first attribute access; None if not installed
    (an installed package that fails to import raises at that first use)."""
    if '.' in name:
        raise ValueError(f'optional({name!r}): expected a top-level package name (no dot)')
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.find_spec(name)
    if spec is None or spec.loader is None:
        return None
    spec.loader = importlib.util.LazyLoader(spec.loader)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module
