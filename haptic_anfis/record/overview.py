"""The class at a glance for the instructor: every trainee's sessions, last score, mastered
level, and who is stalled or drifting; as rows and as CSV (pure, no ROS).

- **stalled**: no progress in the last :data:`STALL_SESSIONS` sessions: none of them raised the
  trainee's best score or mastered level above what the sessions before had reached (a
  trainee with fewer sessions than that plus one is not judged).
- **drifting**: deep coverage falling: the mean deep coverage of the last :data:`DRIFT_SESSIONS`
  sessions is at least :data:`DRIFT_POINTS` percentage points below the mean of the
  :data:`DRIFT_SESSIONS` before them (a falling trend, not one weak session).
"""
from __future__ import annotations

import csv
import io
import os

from .mastery import DEFAULT, MasteryConfig, mastery
from .store import history, trainees

__all__ = ['OVERVIEW_COLUMNS', 'STALL_SESSIONS', 'DRIFT_SESSIONS', 'DRIFT_POINTS', 'overview',
           'overview_csv', 'stalled', 'drifting']

#: sessions without progress that make a trainee stalled
STALL_SESSIONS = 3
#: sessions per window of the deep-coverage trend
DRIFT_SESSIONS = 3
#: [percentage points] the fall of mean deep coverage between the two windows that is drifting
DRIFT_POINTS = 10.0
#: the columns of the overview's CSV
OVERVIEW_COLUMNS = ('trainee', 'sessions', 'last_utc', 'last_score', 'last_verdict',
                    'mastered_level', 'next_level', 'best_score', 'deep_coverage_last_pct',
                    'stalled', 'drifting')


def stalled(sessions: list[dict], levels: list[int], n: int = STALL_SESSIONS) -> bool:
    """Whether the last ``n`` of ``sessions`` (oldest first) raised neither the best score nor
    the mastered level ``levels`` (after each session) above what the ones before reached."""
    if len(sessions) <= n:
        return False
    before = sessions[:-n]
    best = max(s['score'] for s in before)
    level = levels[len(before) - 1]
    return (max(s['score'] for s in sessions[-n:]) <= best
            and max(levels[-n:]) <= level)


def drifting(sessions: list[dict], n: int = DRIFT_SESSIONS, points: float = DRIFT_POINTS) -> bool:
    """Whether mean deep coverage [%] of the last ``n`` sessions fell by at least ``points``
    below the mean of the ``n`` before them."""
    if len(sessions) < 2 * n:
        return False
    deep = [s['coverage_pct']['deep'] for s in sessions[-2 * n:]]
    return sum(deep[:n]) / n - sum(deep[n:]) / n >= points


def overview(db: str | os.PathLike | None = None, config: MasteryConfig = DEFAULT) -> list[dict]:
    """One dict per trainee (:data:`OVERVIEW_COLUMNS`), sorted by id; ``sessions_list``: the
    trainee's sessions (:func:`~haptic_anfis.record.history` dicts, oldest first) for curves.

    Raises:
        RecordError: a bad record file.
    """
    out = []
    for t in trainees(db):
        ss = history(db, t['id'])
        levels = [mastery(ss[:k + 1], config)['mastered_level'] for k in range(len(ss))]
        m = mastery(ss, config)
        last = ss[-1] if ss else None
        out.append({'trainee': t['id'], 'sessions': len(ss),
                    'last_utc': last['started_utc'] if last else None,
                    'last_score': last['score'] if last else None,
                    'last_verdict': last['verdict'] if last else None,
                    'mastered_level': m['mastered_level'], 'next_level': m['next_level'],
                    'best_score': max((s['score'] for s in ss), default=None),
                    'deep_coverage_last_pct': last['coverage_pct']['deep'] if last else None,
                    'stalled': stalled(ss, levels), 'drifting': drifting(ss),
                    'sessions_list': ss})
    return out


def overview_csv(rows: list[dict]) -> str:
    """The overview ``rows`` as CSV text (:data:`OVERVIEW_COLUMNS`, a header row first)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator='\n')
    w.writerow(OVERVIEW_COLUMNS)
    for r in rows:
        w.writerow(['' if r[k] is None else r[k] for k in OVERVIEW_COLUMNS])
    return buf.getvalue()
