"""A trainee's measured stiffness-discrimination thresholds in the record (``haptic-anfis
threshold``): store one, read the latest. The graded library is graded against it (``cases list
--threshold``, ``exam run --next``). Pure Python (``sqlite3``), no ROS.
"""
from __future__ import annotations

import json
import math
import os

from .db import connect, resolve_db_path, write
from .store import check_trainee_id, utc_iso

__all__ = ['store_threshold', 'latest_threshold']


def store_threshold(db: str | os.PathLike | None, trainee_id: str, threshold_pct: float,
                    trials: int, device: str, details: dict) -> int:
    """Store a measured threshold [%] for ``trainee_id`` (created if new) in one transaction;
    returns its row id.

    Raises:
        ValueError: a bad trainee id or threshold; RecordError: the file.
    """
    check_trainee_id(trainee_id)
    if not (math.isfinite(threshold_pct) and threshold_pct > 0):
        raise ValueError(f'threshold: expected a finite percentage > 0, got {threshold_pct!r}')
    now = utc_iso()

    def fn(conn):
        conn.execute('INSERT OR IGNORE INTO trainees (id, created_utc) VALUES (?, ?)',
                     (trainee_id, now))
        cur = conn.execute('INSERT INTO thresholds (trainee_id, measured_utc, threshold_pct, '
                           'trials, device, details_json) VALUES (?, ?, ?, ?, ?, ?)',
                           (trainee_id, now, float(threshold_pct), int(trials), device,
                            json.dumps(details, allow_nan=False)))
        return int(cur.lastrowid)
    return write(db, fn)


def latest_threshold(db: str | os.PathLike | None, trainee_id: str) -> float | None:
    """The trainee's most recent measured threshold [%]; None without one (or without a
    record file)."""
    if not resolve_db_path(db).is_file():
        return None
    with connect(db) as conn:
        row = conn.execute('SELECT threshold_pct FROM thresholds WHERE trainee_id = ? '
                           'ORDER BY id DESC LIMIT 1', (trainee_id,)).fetchone()
    return None if row is None else float(row[0])
