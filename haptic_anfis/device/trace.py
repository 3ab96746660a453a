"""Per-servo-tick trace (no ROS): what the device was told at every tick, for the force error.

One row per tick: time [s] (the loop's monotonic clock), probe position (3,) [m] and applied force
(3,) [N] in the frame the caller chooses, and the local-model status code of that tick
(:data:`haptic_anfis.device.local_model.STATUS_NAMES`; -1 in zero-order-hold mode; :data:`DISABLED`
while the safety layer is off: before start and at shutdown, when the device is told 0 N on
purpose, so the force error leaves those ticks out). The driver's trace also stores
``realtime_minus_monotonic_s``: add it to a tick's time for the wall-clock time a rosbag2 bag
stamps messages with (to line a tick up with what the graph published then). Rows go into
preallocated chunks (no allocation per tick in the servo thread); :meth:`TickTrace.arrays`
concatenates them.

A case switched in a running session changes the force scale (device force = scale x tissue
force) between two ticks; the driver's trace stores ``force_scales``, ``[[t, scale], ...]``
(``t`` [s] on the ticks' clock from which ``scale`` holds; None for the first: from the start),
and ``device_max_force`` [N], so each tick converts with its own scale (:func:`scale_per_tick`,
:func:`max_force_per_tick`). Older traces carry one ``max_force`` (tissue frame) only.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..rows import RowLog

COLUMNS = ('t', 'px', 'py', 'pz', 'fx', 'fy', 'fz', 'status')
#: status of a tick with the safety layer disabled (0 N on purpose: not a dropout)
DISABLED = -2


class TickTrace(RowLog):
    """The newest rows of :data:`COLUMNS`, appended by one thread (the servo loop).

    A :class:`~haptic_anfis.rows.RowLog` of preallocated chunks: beyond ``max_rows`` the OLDEST
    chunk is dropped, so an hour-long session keeps a bounded trace of its last minutes (the
    loop report then covers those; :attr:`dropped` counts what fell out).

    Args:
        chunk: rows per preallocated chunk (at 1 kHz, 8192 = 8 s).
        max_rows: rows kept at most, rounded up to whole chunks (default 600 000: the last ~10
            minutes at 1 kHz, 8 float64 columns = ~39 MB); 0 = unbounded.
    """

    def __init__(self, chunk: int = 8192, max_rows: int = 600_000) -> None:
        super().__init__(len(COLUMNS), chunk, max_rows)

    def add(self, t: float, p, f, status: int) -> None:
        self.append((t, p[0], p[1], p[2], f[0], f[1], f[2], status))

    def arrays(self) -> np.ndarray:
        """The rows held (n, 8), oldest first."""
        return self.array()


def save_trace(path: str | Path, rows: np.ndarray, **meta) -> Path:
    """Write ``rows`` (n, 8) and ``meta`` (JSON-able values, stored as strings) to ``path`` (.npz),
    through a temporary file renamed into place (a crash leaves the old file or the new one)."""
    path = Path(path)
    tmp = path.with_name(path.name + '.tmp.npz')
    np.savez(tmp, rows=rows, columns=np.array(COLUMNS),
             meta=np.array(json.dumps(meta)))
    tmp.replace(path)
    return path


def scale_per_tick(t: np.ndarray, changes) -> np.ndarray:
    """The force scale in force at each tick time ``t`` (n,) [s]: ``changes`` is
    ``[(t_from, scale), ...]`` in time order, ``t_from`` None or -inf for the first (from the
    start); a tick at ``t_from`` or later has that entry's scale.

    Raises:
        ValueError: ``changes`` empty, or a scale that is not a finite number > 0.
    """
    if not len(changes):
        raise ValueError('scale_per_tick: expected at least one (t_from, scale), got none')
    starts = np.array([-np.inf if c[0] is None else float(c[0]) for c in changes])
    scales = np.array([float(c[1]) for c in changes])
    if not np.all(np.isfinite(scales) & (scales > 0)):
        raise ValueError(f'scale_per_tick: expected force scales > 0, got {scales.tolist()}')
    i = np.searchsorted(starts, np.asarray(t, dtype=np.float64), side='right') - 1
    return scales[np.maximum(i, 0)]


def max_force_per_tick(rows: np.ndarray, meta: dict) -> np.ndarray | float:
    """The device's force limit in the tissue frame [N] at each of ``rows`` (n,) when the trace
    records its force scales, else the one ``max_force`` of an older trace (inf if none)."""
    if 'force_scales' in meta and 'device_max_force' in meta:
        return float(meta['device_max_force']) / scale_per_tick(rows[:, 0], meta['force_scales'])
    return float(meta.get('max_force', np.inf))


def load_trace(path: str | Path) -> tuple[np.ndarray, dict]:
    """(rows (n, 8), meta dict) from :func:`save_trace`'s file.

    Raises:
        ValueError: the file is not such a trace.
    """
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
