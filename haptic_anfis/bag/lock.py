"""A recording in progress, told from an interrupted one: the writer holds an exclusive
``flock`` on each MCAP file it writes until it closes it; the kernel drops the lock when the file
is closed or the writer dies. Before the close there is no ``metadata.yaml`` either way, and
``bag recover`` on a live file would move it aside while the recorder goes on writing into it.
"""
from __future__ import annotations

import fcntl
import os
from pathlib import Path

from .errors import BagError

__all__ = ['being_recorded', 'hold', 'release']

_held: set[int] = set()


def _drop_in_child() -> None:
    # A forked child (the servo process) must not keep a recording's lock alive after the
    # recorder closed its file: its copy of the descriptor would hold the lock.
    for fd in list(_held):
        try:
            os.close(fd)
        except OSError:
            pass
    _held.clear()


os.register_at_fork(after_in_child=_drop_in_child)


def hold(path: str | os.PathLike) -> int:
    """Lock ``path`` (an MCAP file being written) for this process; returns the descriptor for
    :func:`release`.

    Raises:
        BagError: another process is writing it.
    """
    fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(fd)
        raise BagError(f'{path}: another process is recording into it') from None
    _held.add(fd)
    return fd


def release(fd: int | None) -> None:
    """Drop a lock from :func:`hold` (None: nothing held)."""
    if fd is None or fd not in _held:
        return
    _held.discard(fd)
    os.close(fd)


def being_recorded(path: str | os.PathLike) -> bool:
    """Whether a live writer holds ``path`` (False when it cannot be opened)."""
    try:
        fd = os.open(Path(path), os.O_RDONLY | os.O_CLOEXEC)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except OSError:
        return True
    finally:
        os.close(fd)   # also drops the shared lock just taken
    return False
