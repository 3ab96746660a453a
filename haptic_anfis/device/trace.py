"""Per-servo-tick trace (no ROS): what the device was told at every tick, for the force error.

One row per tick: time [s] (the loop's monotonic clock), probe position (3,) [m] and applied force
(3,) [N] in the frame the caller chooses, and the local-model status code of that tick
(:data:`haptic_anfis.device.local_model.STATUS_NAMES`; -1 in zero-order-hold mode; :data:`DISABLED`
while the safety layer is off: before start and at shutdown, when the device is told 0 N on
purpose, so the force error leaves those ticks out). Rows go into
preallocated chunks (no allocation per tick in the servo thread); :meth:`TickTrace.arrays`
concatenates them.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

COLUMNS = ('t', 'px', 'py', 'pz', 'fx', 'fy', 'fz', 'status')
#: status of a tick with the safety layer disabled (0 N on purpose: not a dropout)
DISABLED = -2


class TickTrace:
    """The newest rows of :data:`COLUMNS`, appended by one thread (the servo loop).

    A ring of preallocated chunks: beyond ``max_rows`` the OLDEST chunk is dropped, so an
    hour-long session keeps a bounded trace of its last minutes (the loop report then covers
    those; :attr:`dropped` counts what fell out).

    Args:
        chunk: rows per preallocated chunk (at 1 kHz, 8192 = 8 s).
        max_rows: rows kept at most, rounded up to whole chunks (default 600 000: the last ~10
            minutes at 1 kHz, 8 float64 columns = ~39 MB); 0 = unbounded.
    """

    def __init__(self, chunk: int = 8192, max_rows: int = 600_000) -> None:
        if chunk < 1 or max_rows < 0:
            raise ValueError(f'TickTrace: expected chunk >= 1 and max_rows >= 0, got {chunk}, '
                             f'{max_rows}')
        self.chunk = int(chunk)
        self.max_rows = int(max_rows)
        self._chunks: list[np.ndarray] = [np.empty((self.chunk, len(COLUMNS)))]
        self._i = 0
        self.rows = 0  # rows held now
        self.dropped = 0  # oldest rows dropped to stay within max_rows

    def add(self, t: float, p, f, status: int) -> None:
        if self._i == self.chunk:
            if self.max_rows and self.rows >= self.max_rows and len(self._chunks) > 1:
                old = self._chunks.pop(0)  # reuse the oldest chunk's memory for the newest rows
                self.rows -= self.chunk
                self.dropped += self.chunk
            else:
                old = np.empty((self.chunk, len(COLUMNS)))
            self._chunks.append(old)
            self._i = 0
        self._chunks[-1][self._i] = (t, p[0], p[1], p[2], f[0], f[1], f[2], status)
        self._i += 1
        self.rows += 1

    def extend(self, rows: np.ndarray) -> None:
        """Append ``rows`` (k, 8) at once (the native loop's bridge drains its ring here)."""
        rows = np.asarray(rows, dtype=np.float64).reshape(-1, len(COLUMNS))
        i = 0
        while i < len(rows):
            if self._i == self.chunk:
                self.add(*_split(rows[i]))
                i += 1
                continue
            k = min(self.chunk - self._i, len(rows) - i)
            self._chunks[-1][self._i:self._i + k] = rows[i:i + k]
            self._i += k
            self.rows += k
            i += k

    def clear(self) -> None:
        self.__init__(self.chunk, self.max_rows)

    def arrays(self) -> np.ndarray:
        """The rows held (n, 8), oldest first."""
        parts = self._chunks[:-1] + [self._chunks[-1][:self._i]]
        return np.concatenate(parts, axis=0) if parts else np.empty((0, len(COLUMNS)))


def _split(r: np.ndarray) -> tuple:
    """One row as :meth:`TickTrace.add`'s arguments."""
    return r[0], r[1:4], r[4:7], r[7]


def save_trace(path: str | Path, rows: np.ndarray, **meta) -> Path:
    """Write ``rows`` (n, 8) and ``meta`` (JSON-able values, stored as strings) to ``path`` (.npz),
    through a temporary file renamed into place (a crash leaves the old file or the new one)."""
    import json
    path = Path(path)
    tmp = path.with_name(path.name + '.tmp.npz')
    np.savez(tmp, rows=rows, columns=np.array(COLUMNS),
             meta=np.array(json.dumps(meta)))
    tmp.replace(path)
    return path


def load_trace(path: str | Path) -> tuple[np.ndarray, dict]:
    """(rows (n, 8), meta dict) from :func:`save_trace`'s file.

    Raises:
        ValueError: the file is not such a trace.
    """
    import json
    try:
        with np.load(path, allow_pickle=False) as z:
            rows, cols, meta = z['rows'], tuple(z['columns'].tolist()), json.loads(str(z['meta']))
    except (OSError, KeyError, ValueError) as exc:
        raise ValueError(f'{path}: not a servo tick trace (.npz with rows/columns/meta): '
                         f'{exc}') from exc
    if cols != COLUMNS or rows.ndim != 2 or rows.shape[1] != len(COLUMNS):
        raise ValueError(f'{path}: expected columns {COLUMNS}, got {cols} with shape '
                         f'{rows.shape}')
    return rows, meta
