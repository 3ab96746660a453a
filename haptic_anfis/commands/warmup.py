"""``haptic-anfis warmup``: compile the nodes' numba kernels into the cache (run at install).

The force model, the contact detector and the servo tick are compiled on first use: on a cold
cache the first session waits for them (tens of seconds on a busy 2-core machine). ``make venv``
runs this once so the first session starts warm. The cache is beside the sources, or
``NUMBA_CACHE_DIR`` (set by the package to the user cache directory when the package directory is
not writable, see :mod:`haptic_anfis.numba_cache`); the kernels: :mod:`haptic_anfis.warm`.
"""
from __future__ import annotations

import argparse
import os

from ..warm import warm

NAME = 'warmup'


def add_arguments(p: argparse.ArgumentParser) -> None:
    pass


def run(args: argparse.Namespace) -> int:
    where = os.environ.get('NUMBA_CACHE_DIR') or 'beside the sources (__pycache__)'
    times = warm()
    print(f'numba kernels cached {where}: '
          + ', '.join(f'{k} {v:.1f} s' for k, v in times.items()), flush=True)
    return 0
