"""``exam run --trainee-id ID --next``: a blind case of the level after the trainee's mastered one.

The pool of level L is the library's ready cases of level L with a palpable lesion (the graded
ones — full-density FE, models within the gates — when the level has any; the levels are the
library's own, :func:`~haptic_anfis.record.levels.case_level`), and, in about
:data:`LESION_FREE_SHARE` of the draws, the cases with no lesion, whatever their level (they train
specificity at every level). A case whose lesions are all below what the device renders is in
neither pool (:func:`~haptic_anfis.record.levels.below_device`). Palpability and level are read
at one threshold, the trainee's own when given. Within the pool, a case the trainee has not seen
comes before one it has (the least seen first), and the draw among those is seeded by the
trainee's id and its number of sessions: reproducible from the record, different for two trainees
and from one session to the next. Pure Python, no ROS.
"""
from __future__ import annotations

import hashlib
import os
import random

from ..cases import CaseError, library
from .db import resolve_db_path
from .levels import below_device, case_level, has_palpable_lesion
from .mastery import MasteryConfig, load_mastery_config, mastery
from .store import UnknownTrainee, history

__all__ = ['LESION_FREE_SHARE', 'draw_seed', 'next_case']

#: the share of blind draws that are a case with no palpable lesion: enough that marking
#: something in every session does not pay (clinical breast examination's pooled specificity is
#: 94 %, Barton, Harris & Fletcher, JAMA 1999), few enough that most sessions have a lump to find
LESION_FREE_SHARE = 0.25


def draw_seed(trainee_id: str, sessions: int) -> int:
    """The seed of a trainee's draw after ``sessions`` stored sessions: a hash of both, so two
    trainees with as many sessions draw differently (the session count alone gave a whole
    class the same "random" cases in the same order)."""
    digest = hashlib.sha256(f'{trainee_id}\0{int(sessions)}'.encode()).digest()
    return int.from_bytes(digest[:8], 'big')


def next_case(db: str | os.PathLike | None, trainee_id: str, lib=None,
              config: MasteryConfig | None = None, exam_config: str | None = None,
              threshold_pct: float | None = None):
    """``(case, level, mastery dict)`` for the trainee's next blind session; a trainee with no
    record yet starts at level 1; a next level above the hardest level with a palpable case
    draws from that; a level without one draws from the next harder level that has one
    (``level`` says which level was drawn, the mastery dict's ``next_level`` what the record
    asks for). ``threshold_pct``: the graded cases' levels at this palpability threshold [%]
    (the trainee's own, ``haptic-anfis threshold``) instead of the stored grading's.

    Raises:
        ValueError: no ready case with a palpable lesion at any level (names the levels there
            are); RecordError: a bad record file.
    """
    config = config or load_mastery_config(exam_config)
    try:
        past = (history(db, trainee_id, instructor=True) if resolve_db_path(db).is_file()
                else [])
    except UnknownTrainee:
        past = []
    m = mastery(past, config)
    level = m['next_level']
    lib = lib or library()
    by_level: dict[int, list] = {}
    free: list = []
    for c in lib.ready():
        try:
            if has_palpable_lesion(c, threshold_pct):
                own = c.level_at(threshold_pct) if threshold_pct is not None else None
                by_level.setdefault(own if own is not None else case_level(c), []).append(c)
            elif not below_device(c, threshold_pct):
                free.append(c)
            # else: lesions the device does not render: no level, not a "no lump" case either
        except (CaseError, ValueError):
            continue   # a broken scene is not drawn (cases list names it)
    if by_level and level > max(by_level):   # past the hardest case there is: stay there
        level = max(by_level)
    elif level not in by_level and any(k > level for k in by_level):
        level = min(k for k in by_level if k > level)   # no case of that level: the next harder
    pool = by_level.get(level)
    if not pool:
        raise ValueError(f'--next: no ready case with a palpable lesion of level {level} for '
                         f'trainee {trainee_id!r} (levels with one: {sorted(by_level) or "none"})')
    # a graded case (full-density FE, models within the gates) before an older coarse one
    pool = [c for c in pool if getattr(c, 'level', None) is not None] or pool
    rng = random.Random(draw_seed(trainee_id, len(past)))
    if free and rng.random() < LESION_FREE_SHARE:
        pool = [c for c in free if getattr(c, 'level', None) is not None] or free
    seen = [s['case'] for s in past]
    least = min(seen.count(c.name) for c in pool)
    pool = sorted((c for c in pool if seen.count(c.name) == least), key=lambda c: c.name)
    return pool[rng.randrange(len(pool))], level, m
