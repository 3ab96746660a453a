"""Rows of numbers appended one at a time, kept as float64 arrays (no ROS, no allocation per row).

A session an hour long appends millions of rows: the servo ticks (1 kHz) and the contact
samples an exam scores (1 kHz). As a list of tuples each row of six floats costs ~240 bytes of
Python objects (~0.9 GB an hour per node); here it costs its 8 bytes a value, in preallocated
chunks, so an append writes into memory that already exists.
"""
from __future__ import annotations

from collections.abc import Iterator, Sequence

import numpy as np

__all__ = ['RowLog']


class RowLog:
    """Rows of ``columns`` float64 values, oldest first, in chunks of ``chunk`` rows.

    Reads like the list of tuples it replaces: ``len()``, iteration (tuples), ``log[i]`` (a
    tuple), ``log[a:b]`` and ``np.asarray(log)`` (arrays, copies).

    Args:
        columns: values per row.
        chunk: rows per preallocated chunk.
        max_rows: rows kept at most, rounded up to whole chunks: beyond it the OLDEST chunk is
            dropped (:attr:`dropped` counts its rows) and its memory reused; 0 = unbounded.
    """

    def __init__(self, columns: int, chunk: int = 8192, max_rows: int = 0) -> None:
        if columns < 1 or chunk < 1 or max_rows < 0:
            raise ValueError(f'RowLog: expected columns >= 1, chunk >= 1 and max_rows >= 0, got '
                             f'{columns}, {chunk}, {max_rows}')
        self.columns, self.chunk, self.max_rows = int(columns), int(chunk), int(max_rows)
        self.clear()

    def clear(self) -> None:
        """No rows (and none dropped)."""
        self._chunks: list[np.ndarray] = [np.empty((self.chunk, self.columns))]
        self._i = 0        # rows used in the newest chunk
        self.rows = 0      # rows held
        self.dropped = 0   # oldest rows dropped to stay within max_rows

    def _room(self) -> np.ndarray:
        """The newest chunk, with room for a row (a new or recycled chunk when it is full)."""
        if self._i == self.chunk:
            if self.max_rows and self.rows >= self.max_rows and len(self._chunks) > 1:
                new = self._chunks.pop(0)   # the oldest chunk's memory for the newest rows
                self.rows -= self.chunk
                self.dropped += self.chunk
            else:
                new = np.empty((self.chunk, self.columns))
            self._chunks.append(new)
            self._i = 0
        return self._chunks[-1]

    def append(self, row: Sequence[float]) -> None:
        """One row of ``columns`` values."""
        self._room()[self._i] = row
        self._i += 1
        self.rows += 1

    def extend(self, rows) -> None:
        """Rows (k, columns) at once."""
        rows = np.asarray(rows, dtype=np.float64).reshape(-1, self.columns)
        i = 0
        while i < len(rows):
            c = self._room()
            k = min(self.chunk - self._i, len(rows) - i)
            c[self._i:self._i + k] = rows[i:i + k]
            self._i += k
            self.rows += k
            i += k

    def array(self, start: int = 0, stop: int | None = None) -> np.ndarray:
        """Rows ``start`` .. ``stop`` (indices into the rows held, as a slice takes them) as a
        new (n, columns) array."""
        start, stop, _ = slice(start, stop).indices(self.rows)
        if stop <= start:
            return np.empty((0, self.columns))
        # every chunk but the newest is full and the oldest row is the first chunk's first
        a, b, n = start, stop, self.chunk
        parts = [c[max(a - j * n, 0):min(b - j * n, n)] for j, c in enumerate(self._chunks)
                 if j * n < b and (j + 1) * n > a]
        return np.concatenate(parts, axis=0)

    def _chunk_rows(self, j: int) -> int:
        """Rows used in chunk ``j`` (all but the newest are full)."""
        return self._i if j == len(self._chunks) - 1 else self.chunk

    def __len__(self) -> int:
        return self.rows

    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        a = self.array()
        return a if dtype is None else a.astype(dtype, copy=False)

    def __iter__(self) -> Iterator[tuple]:
        for j, c in enumerate(self._chunks):
            yield from map(tuple, c[:self._chunk_rows(j)].tolist())

    def __getitem__(self, key):
        if isinstance(key, slice):
            if key.step not in (None, 1):
                raise ValueError('RowLog: slices with a step are not supported')
            return self.array(key.start or 0, key.stop)
        i = range(self.rows)[key]   # IndexError as a list gives it
        return tuple(self.array(i, i + 1)[0].tolist())

    def __repr__(self) -> str:
        return f'RowLog({self.rows} rows x {self.columns})'
