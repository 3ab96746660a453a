"""The one lookup of the files the package ships: ``config/`` (parameter files, scenes, trainee
scripts, scoring and model settings) and ``data/`` (the default dataset, model, surface and the
case library).

``config/`` is found, in order: beside the sources (a checkout or an editable install), in the
ament index's share directory (colcon, or ``AMENT_PREFIX_PATH``), in ``<sys.prefix>/share/
haptic_anfis/config`` (where pip puts a wheel's ``data_files``). ``data/`` is package data: it
sits inside the installed package in every layout.
"""
from __future__ import annotations

import sys
from pathlib import Path

try:  # the ament index (ROS): where colcon installs the package's share directory
    from ament_index_python.packages import get_package_share_directory
except ImportError:
    get_package_share_directory = None

__all__ = ['PACKAGE', 'PACKAGE_DIR', 'DATA_DIR', 'config_dir', 'config_file', 'data_file']

PACKAGE = 'haptic_anfis'
PACKAGE_DIR = Path(__file__).resolve().parent
#: package data (default dataset / model / surface, data/cases/): inside the package everywhere
DATA_DIR = PACKAGE_DIR / 'data'


def _candidates() -> list[Path]:
    out = [PACKAGE_DIR.parent / 'config']
    if get_package_share_directory is not None:
        try:
            out.append(Path(get_package_share_directory(PACKAGE)) / 'config')
        except Exception:  # noqa: BLE001 (the package is not in the ament index)
            pass
    out.append(Path(sys.prefix) / 'share' / PACKAGE / 'config')
    return out


def _first(name: str, kind: str) -> Path:
    """``name`` in the first candidate directory where it is a ``kind`` ('dir' / 'file'); else
    in the source tree's (so a 'not found' names a real place)."""
    cands = _candidates()
    for c in cands:
        p = c / name
        if (p.is_dir() if kind == 'dir' else p.is_file()):
            return p
    return cands[0] / name


def config_dir(sub: str = '') -> Path:
    """The shipped ``config/`` directory (or its sub-directory ``sub``, e.g. 'scenes')."""
    return _first(sub, 'dir')


def config_file(name: str) -> Path:
    """A file shipped in ``config/`` (``name`` may hold a sub-directory: 'scenes/default.yaml')."""
    return _first(name, 'file')


def data_file(name: str) -> Path:
    """A file of the package data (``data/``)."""
    return DATA_DIR / name
