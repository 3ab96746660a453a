"""Memory a forked servo process shares with its parent, and its death with the parent (Linux;
no ROS)."""
from __future__ import annotations

import ctypes
import mmap

import numpy as np

__all__ = ['SharedArrays', 'die_with_parent']

#: prctl option: the signal the calling process gets when its parent dies
_PR_SET_PDEATHSIG = 1


class SharedArrays:
    """numpy arrays in anonymous shared memory (``mmap``, MAP_SHARED): a forked servo process
    and this one see the same bytes. Kept alive as long as this object."""

    def __init__(self) -> None:
        self._maps: list[mmap.mmap] = []

    def zeros(self, shape, dtype=np.float64) -> np.ndarray:
        """A zero-filled shared array of ``shape`` and ``dtype``."""
        n = int(np.prod(shape)) * np.dtype(dtype).itemsize
        m = mmap.mmap(-1, max(n, 8))  # anonymous, shared with children; zero-filled
        self._maps.append(m)
        return np.frombuffer(m, dtype=dtype, count=int(np.prod(shape))).reshape(shape)


def die_with_parent(sig: int) -> None:
    """Linux prctl(PR_SET_PDEATHSIG): the calling process gets ``sig`` when its parent dies
    (elsewhere: nothing)."""
    try:
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, sig, 0, 0, 0)
    except (OSError, AttributeError):
        pass
