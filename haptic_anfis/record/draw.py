"""``exam run --trainee-id ID --next``: a blind case of the level after the trainee's mastered one.

Among the library's ready cases of that level — the graded ones (full-density FE, models
within the gates) when the level has any — the one the trainee has done least often (ties:
drawn with the number of sessions stored as the seed, so the draw is reproducible from the record
and differs from one session to the next). Pure Python, no ROS.
"""
from __future__ import annotations

import os
import random

from .db import resolve_db_path
from .levels import case_level
from .mastery import MasteryConfig, load_mastery_config, mastery
from .store import UnknownTrainee, history

__all__ = ['next_case']


def next_case(db: str | os.PathLike | None, trainee_id: str, lib=None,
              config: MasteryConfig | None = None, exam_config: str | None = None):
    """``(case, level, mastery dict)`` for the trainee's next blind session; a trainee with no
    record yet starts at level 1; a next level above the hardest ready case draws from that; a
    level without a ready case draws from the next harder level that has one (``level`` says
    which level was drawn, the mastery dict's ``next_level`` what the record asks for).

    Raises:
        ValueError: no ready case of that level (names the level and the levels there are);
        RecordError: a bad record file.
    """
    from ..cases import CaseError, library
    config = config or load_mastery_config(exam_config)
    try:
        past = history(db, trainee_id) if resolve_db_path(db).is_file() else []
    except UnknownTrainee:
        past = []
    m = mastery(past, config)
    level = m['next_level']
    lib = lib or library()
    by_level: dict[int, list] = {}
    for c in lib.ready():
        try:
            by_level.setdefault(case_level(c), []).append(c)
        except (CaseError, ValueError):
            continue   # a broken scene is not drawn (cases list names it)
    if by_level and level > max(by_level):   # past the hardest case there is: stay there
        level = max(by_level)
    elif level not in by_level and any(k > level for k in by_level):
        level = min(k for k in by_level if k > level)   # no case of that level: the next harder
    pool = by_level.get(level)
    # a graded case (full-density FE, models within the gates) before an older coarse one
    graded = [c for c in pool or () if getattr(c, 'level', None) is not None]
    pool = graded or pool
    if not pool:
        raise ValueError(f'--next: no ready case of level {level} for trainee {trainee_id!r} '
                         f'(levels with cases: {sorted(by_level) or "none"})')
    done = [s['case'] for s in past]
    least = min(done.count(c.name) for c in pool)
    pool = [c for c in pool if done.count(c.name) == least]
    return pool[random.Random(len(past)).randrange(len(pool))], level, m
