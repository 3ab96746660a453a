"""Mastery levels: which case level a trainee has mastered, and which level comes next.

The thresholds live in ``config/exam.yaml`` under ``mastery`` (documented there). A session
*meets* level L when its case is of level L and its deep coverage, palpable lesions found and
false marks meet L's thresholds; level L is *mastered* once ``consecutive_sessions`` of the
trainee's level-L sessions with a palpable lesion in a row meet it (lumps must be found: a case
without one never extends a streak, and failing one breaks it; a pass standard with retry: a
later weak session does not take a mastered level away; a void session counts neither way) and,
where the level sets ``max_false_marks_per_case``, the false marks over that *window* (those
sessions and the lesion-free ones among them) are at most that many per case: specificity
measured over several cases, as a clinician's is, rather than one session at a time.
The trainee's mastered level is the highest L with every level 1..L mastered; the next level is
one above (the top level stays the top). Pure, no ROS.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, fields
from pathlib import Path

import yaml

from ..exam.config import DEFAULT_CONFIG
from .store import same_recording

__all__ = ['MasteryConfig', 'MasteryLevel', 'lesion_free', 'load_mastery_config', 'mastery',
           'meets', 'specificity']


@dataclass(frozen=True)
class MasteryLevel:
    """Thresholds of one case level: deep coverage (fraction of the region, 0-1), whether every
    palpable lesion must be found, the most false marks allowed in one session, sessions in a
    row needed, and the most false marks per case over the mastery window (None: no such
    limit)."""
    min_deep_coverage: float = 0.9
    all_palpable_found: bool = True
    max_false_marks: int = 1
    consecutive_sessions: int = 3
    max_false_marks_per_case: float | None = None

    def __post_init__(self):
        c = self.min_deep_coverage
        if isinstance(c, bool) or not isinstance(c, (int, float)) or not (
                math.isfinite(c) and 0 <= c <= 1):
            raise ValueError(f'min_deep_coverage: expected a fraction 0-1, got {c!r}')
        if not isinstance(self.all_palpable_found, bool):
            raise ValueError(f'all_palpable_found: expected true/false, got '
                             f'{self.all_palpable_found!r}')
        for name, low in (('max_false_marks', 0), ('consecutive_sessions', 1)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < low:
                raise ValueError(f'{name}: expected an integer >= {low}, got {v!r}')
        r = self.max_false_marks_per_case
        if r is not None and (isinstance(r, bool) or not isinstance(r, (int, float))
                              or not (math.isfinite(r) and r >= 0)):
            raise ValueError(f'max_false_marks_per_case: expected a number >= 0 or null, '
                             f'got {r!r}')


@dataclass(frozen=True)
class MasteryConfig:
    """Thresholds per case level (1, 2, ... contiguous)."""
    levels: dict[int, MasteryLevel]

    @property
    def top(self) -> int:
        return max(self.levels)


#: the higher levels' specificity over the mastery window (config/exam.yaml says why)
SPECIFIC = MasteryLevel(max_false_marks_per_case=0.34)
#: used when config/exam.yaml has no ``mastery`` section (the same values as the shipped file)
DEFAULT = MasteryConfig({1: MasteryLevel(), 2: MasteryLevel(), 3: SPECIFIC, 4: SPECIFIC,
                         5: SPECIFIC})


def load_mastery_config(path: str | os.PathLike | None = None) -> MasteryConfig:
    """The ``mastery`` section of ``path`` (default ``config/exam.yaml``); :data:`DEFAULT` when
    the file or the section is absent.

    Raises:
        ValueError: naming the file and the bad key.
    """
    path = Path(path) if path else DEFAULT_CONFIG
    if not path.is_file():
        if path == DEFAULT_CONFIG:
            return DEFAULT
        raise ValueError(f'exam config {str(path)!r}: no such file')
    try:
        doc = yaml.safe_load(path.read_text()) or {}
        sec = doc.get('mastery') if isinstance(doc, dict) else None
        if sec is None:
            return DEFAULT
        if not isinstance(sec, dict):
            raise ValueError('mastery: expected a mapping')
        common = dict(sec)
        levels = common.pop('levels', None)
        known = {f.name for f in fields(MasteryLevel)}
        bad = set(common) - known
        if bad:
            raise ValueError(f'mastery: unknown key(s) {sorted(bad)}')
        if not isinstance(levels, dict) or not levels:
            raise ValueError('mastery.levels: expected a mapping level -> thresholds')
        out = {}
        for k, v in levels.items():
            if isinstance(k, bool) or not isinstance(k, int) or k < 1:
                raise ValueError(f'mastery.levels: level {k!r}: expected an integer >= 1')
            v = v or {}
            if not isinstance(v, dict) or set(v) - known:
                raise ValueError(f'mastery.levels.{k}: expected keys among {sorted(known)}')
            try:
                out[k] = MasteryLevel(**{**common, **v})
            except ValueError as exc:
                raise ValueError(f'mastery.levels.{k}.{exc}') from None
        if sorted(out) != list(range(1, len(out) + 1)):
            raise ValueError(f'mastery.levels: expected levels 1..N, got {sorted(out)}')
        return MasteryConfig(out)
    except (OSError, yaml.YAMLError, ValueError, TypeError) as exc:
        raise ValueError(f'exam config {str(path)!r}: {exc}') from None


def meets(session: dict, level: MasteryLevel) -> bool:
    """Whether one session (a :func:`~haptic_anfis.record.history` dict) meets ``level``."""
    return (session['coverage_pct']['deep'] >= 100 * level.min_deep_coverage - 1e-9
            and (not level.all_palpable_found or session['palpable_missed'] == 0)
            and session['false_marks'] <= level.max_false_marks)


def _window(v: dict, run: list[tuple[bool, int]], level: MasteryLevel) -> None:
    """Level ``v``'s window from its streak ``run`` ((a lump?, false marks) per case): the
    cases from its ``needed``-th last session with a lump on (all of the run while shorter);
    ``v`` is mastered once its streak is long enough and the window's false marks per case are
    within ``level``'s limit (once mastered it stays so)."""
    lumps = [i for i, (lump, _) in enumerate(run) if lump]
    start = lumps[-v['needed']] if len(lumps) >= v['needed'] else 0
    cases = run[start:]
    fm = sum(n for _, n in cases)
    v['window_cases'], v['window_false_marks'] = len(cases), fm
    v['false_marks_per_case'] = round(fm / len(cases), 4) if cases else None
    limit = level.max_false_marks_per_case
    if v['streak'] >= v['needed'] and (limit is None or fm <= limit * len(cases) + 1e-9):
        v['mastered'] = True


def lesion_free(session: dict) -> bool:
    """Whether the session's case had no palpable lesion (its report's lesions all not
    palpable, or none): a specificity session."""
    return session['lesions'] - len(session.get('not_palpable') or ()) <= 0


def mastery(sessions: list[dict], config: MasteryConfig = DEFAULT) -> dict:
    """Mastery of a trainee from its sessions (oldest first, :func:`history` dicts).

    Lumps must be found: level L's streak counts only sessions on level-L cases with a palpable
    lesion. A session on a case with none (:func:`lesion_free`: it trains specificity, drawn at
    every level) never extends a streak, and one that misses the thresholds of the level the
    trainee was working on at the time (the first not yet mastered) ends that level's streak.
    A void session (its haptic loop fell behind, ``void``) counts neither way.

    Level L's *window* is its current streak's last ``needed`` sessions with a lump and the
    lesion-free sessions among them; where L sets ``max_false_marks_per_case``, L is mastered
    only once the false marks over the window's cases are at most that many per case (a longer
    streak slides the window on).

    Returns ``{'mastered_level': int (0 = none), 'next_level': int, 'levels': {L: {'sessions'
    (with a palpable lesion), 'met', 'streak' (current run), 'best_streak', 'needed',
    'mastered', 'lesion_free' (specificity sessions while working on L), 'lesion_free_met',
    'void', 'cases' (counted sessions of either kind), 'false_marks' and 'false_marks_normal'
    (over them; the latter of the sessions that know it), 'window_cases',
    'window_false_marks' (the current window), 'false_marks_per_case' (over the window, None
    without one)}}, 'specificity': :func:`specificity` of every session not void, whatever
    its level}``; sessions
    with no case level are not counted (a case whose lesions are all below what the device
    renders has none), nor a bag's second session (a recording scored again,
    in a record from before :class:`~haptic_anfis.record.AlreadyStored`); two recordings made
    at one path (``bag_start_ns`` differs) count as two.
    """
    counted: list[dict] = []
    for s in sessions:   # a recording counts once (store_session's rule)
        if not any(same_recording(s.get('bag'), s.get('bag_start_ns'), c.get('bag'),
                                  c.get('bag_start_ns')) for c in counted):
            counted.append(s)
    per = {L: {'sessions': 0, 'met': 0, 'streak': 0, 'best_streak': 0,
               'needed': th.consecutive_sessions, 'mastered': False, 'lesion_free': 0,
               'lesion_free_met': 0, 'void': 0, 'cases': 0, 'false_marks': 0,
               'false_marks_normal': 0, 'window_cases': 0, 'window_false_marks': 0,
               'false_marks_per_case': None} for L, th in sorted(config.levels.items())}
    streaks: dict[int, list[tuple[bool, int]]] = {L: [] for L in per}   # (a lump?, false marks)

    def working() -> int:   # the first level not mastered yet (the top once all are)
        return next((L for L in per if not per[L]['mastered']), config.top)
    for s in counted:
        free = lesion_free(s)
        if free and s['lesions'] and s.get('case_level') is None:
            continue   # lesions all below what the device renders: no level, counts neither way
        L = working() if free else s.get('case_level')
        if L not in per:
            continue
        v = per[L]
        if s.get('void'):
            v['void'] += 1
            continue
        ok = meets(s, config.levels[L])
        v['cases'] += 1
        v['false_marks'] += s['false_marks']
        v['false_marks_normal'] += s.get('false_marks_normal') or 0
        run = streaks[L]
        if not ok:
            run.clear()
        else:
            run.append((not free, s['false_marks']))
        if free:
            v['lesion_free'] += 1
            v['lesion_free_met'] += ok
            if not ok:
                v['streak'] = 0
        else:
            v['sessions'] += 1
            v['met'] += ok
            v['streak'] = v['streak'] + 1 if ok else 0
            v['best_streak'] = max(v['best_streak'], v['streak'])
        _window(v, run, config.levels[L])
    mastered = 0
    for L in per:
        if not per[L]['mastered']:
            break
        mastered = L
    return {'mastered_level': mastered, 'next_level': min(mastered + 1, config.top),
            'levels': per, 'specificity': specificity([s for s in counted if not s.get('void')])}


def specificity(sessions: list[dict]) -> dict:
    """The trainee's specificity over ``sessions`` (:func:`history` dicts): ``sessions``,
    ``clean`` (without a false mark) and its share ``clean_pct`` [%] (None without a session),
    ``false_marks_per_session``, and of the sessions that know the split (``split_sessions``:
    stored since schema v6) the false marks per session on a normal lobule or rib
    (``normal_per_session``) and elsewhere (``elsewhere_per_session``; None without one)."""
    n = len(sessions)
    split = [s for s in sessions if s.get('false_marks_normal') is not None]
    fm = sum(s['false_marks'] for s in sessions)
    on = sum(s['false_marks_normal'] for s in split)
    off = sum(s['false_marks'] for s in split) - on
    per = (lambda k, m: round(k / m, 3) if m else None)  # noqa: E731
    clean = sum(s['false_marks'] == 0 for s in sessions)
    return {'sessions': n, 'clean': clean,
            'clean_pct': round(100 * clean / n, 1) if n else None,
            'false_marks_per_session': per(fm, n), 'split_sessions': len(split),
            'normal_per_session': per(on, len(split)),
            'elsewhere_per_session': per(off, len(split))}
