"""Where numba keeps its compiled kernels (no ROS; run at package import, before numba loads).

numba caches a ``cache=True`` kernel next to its source (``__pycache__``). On an install whose
package directory is not writable (a colcon install into a system prefix, a container image) it
cannot, and every node start paid the compile again (23 s for the contact detector on a busy
2-core machine). :func:`configure` then points ``NUMBA_CACHE_DIR`` at the user's cache directory,
``$XDG_CACHE_HOME/haptic_anfis/numba`` (default ``~/.cache/haptic_anfis/numba``), or, if that
cannot be written either, ``$TMPDIR/haptic_anfis-numba-<uid>``. A ``NUMBA_CACHE_DIR`` set by the
user always wins. ``haptic-anfis warmup`` (run by ``make venv``; :mod:`haptic_anfis.warm`)
compiles every kernel the nodes use into that cache.

It imports nothing of the package: :mod:`haptic_anfis` runs :func:`configure` at its import,
before anything loads numba.
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent


def _writable_dir(d: Path) -> bool:
    try:
        d.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=d):
            pass
        return True
    except OSError:
        return False


def user_cache_dir() -> Path:
    """``$XDG_CACHE_HOME/haptic_anfis/numba`` (default ``~/.cache/haptic_anfis/numba``)."""
    base = os.environ.get('XDG_CACHE_HOME') or os.path.join(os.path.expanduser('~'), '.cache')
    return Path(base) / 'haptic_anfis' / 'numba'


def choose_cache_dir(package_dir: Path = PACKAGE_DIR) -> Path | None:
    """None when numba can cache beside the sources (``package_dir`` writable), else the first
    writable of the user cache directory and a per-user temporary directory."""
    if os.access(package_dir, os.W_OK) and os.access(package_dir / 'anfis', os.W_OK):
        return None
    for d in (user_cache_dir(),
              Path(tempfile.gettempdir()) / f'haptic_anfis-numba-{os.getuid()}'):
        if _writable_dir(d):
            return d
    return None


def configure(package_dir: Path = PACKAGE_DIR) -> str | None:
    """Set ``NUMBA_CACHE_DIR`` if the user has not and ``package_dir`` is not writable; returns
    the directory numba will use (None: beside the sources). Effective only before numba is
    imported (it reads the variable once)."""
    if os.environ.get('NUMBA_CACHE_DIR'):
        return os.environ['NUMBA_CACHE_DIR']
    d = choose_cache_dir(package_dir)
    if d is not None:
        os.environ['NUMBA_CACHE_DIR'] = str(d)
        return str(d)
    return None

