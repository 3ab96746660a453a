"""Grading a case from its FE: each lesion's force contrast at every depth, the shallowest
pressure level at which a stylus can feel it, its difficulty; the case level.

- **Contrast** of a lesion at a depth: the force magnitude |F| the FE gives over the lesion's
  centre, minus the same point of the lesion-free twin (the same scene without lesions) at the
  same depth, in N and in % of the twin's force; at every solved depth (2, 5, 8, 12, 16 mm).
- **Palpable** at a depth when the contrast reaches the threshold ``threshold_pct``
  (:data:`PALPABLE_PCT` by default; ``palpable_pct`` in ``config/exam.yaml``; a trainee's own
  from ``haptic-anfis threshold``). The trainee feels the lump through a rigid stylus, choosing
  the depth as they press: no skin deformation cue, and no press to the very same depth at the
  lump and beside it. Compliance discrimination under those conditions is 22 % (Tan, Durlach,
  Beauregard & Srinivasan 1995, "Manual discrimination of compliance using active pinch grasp:
  the roles of force and work cues", Perception & Psychophysics 57:495-510: rigid plates
  squeezed, work and terminal-force cues dissociated from compliance by roving the
  displacement); with the finger pad's own deformation cue it is 15 % and "more than trebled"
  without it (Bergmann Tiest & Kappers 2009, "Cues for haptic perception of compliance", IEEE
  Trans. Haptics 2:189-199). The force JND at a fixed squeeze, ~7 % over 2.5-10 N (Pang, Tan &
  Durlach 1991), is a lower bound no stylus exam reaches. A relative threshold survives the
  device's force scale (:mod:`.force_mapping`), which keeps every ratio.
- **Pressure level** at which a lesion is found: the exam's level (light >= 2, medium >= 5, deep
  >= 8 mm of tissue depth, :class:`~haptic_anfis.exam.config.ExamConfig`) of the shallowest depth
  at which it is palpable.
- **Difficulty** 1-5 of a palpable lesion from where it is first palpable: 1 at light pressure
  with at least :data:`EASY_MULTIPLE` times the threshold (a lump that stands out at the first
  touch), 2 by medium pressure, 3 at the deep level, 4 only deeper (12 mm), 5 only at the
  library's deepest trained depth (16 mm, :data:`DEEPEST_DEPTH`; a scene whose FE stops at 12 mm,
  as over ribs, grades a lesion first felt there 4, like every other case). Human figures agree in order: a superficial 1 cm lump is found by 87-90 %
  of examiners, a deep 2 cm hard one by 75 % (Fletcher et al., JAMA 1985; Pugh's group).
- A lesion that is not palpable at any trained depth is **below what this device renders** (the
  reason says by how much): not "not palpable" — people find 3-5 mm lumps in silicone models
  (Fletcher et al. 1985: 14 % of 3 mm lumps) by shape and mobility, which the simulator does not
  render. The exam scores it neither hit nor miss.
- **Level** of a case: the difficulty of its hardest palpable lesion; 1 for a case with no lesion
  (the answer is "no lump": it trains specificity). A case whose lesions are ALL below what the
  device renders has no level (None; ``below_device`` names them): scoring a 10 mm carcinoma at
  30 mm as an easy "no lump" case would teach a trainee to pass over a real lump, and no pressure
  finds it here either, so it is neither a lump case nor a lesion-free one. An instructor can
  still open it by name (to show what a stylus cannot give); blind draws and mastery pass it by.

Pure numpy, no ROS.
"""
from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np

__all__ = ['DEEP_DEPTH', 'DEEPEST_DEPTH', 'PALPABLE_PCT', 'EASY_MULTIPLE', 'LEVEL_DEPTHS', 'BASIS',
           'pressure_level', 'grade_contrasts', 'difficulty', 'lesion_grades', 'case_level',
           'below_device', 'grading_record', 'regrade']

DEEP_DEPTH = 0.008  # [m]: haptic_anfis.exam.config.ExamConfig.deep (default)
#: [m] the library's deepest trained depth: a lesion felt only there is difficulty 5
DEEPEST_DEPTH = 0.016
#: [%] of the lesion-free force: stiffness discrimination through a rigid stylus (Tan et al. 1995)
PALPABLE_PCT = 22.0
#: a lesion palpable at light pressure with this many times the threshold is difficulty 1
EASY_MULTIPLE = 2.0
#: the exam's pressure levels [m] of tissue depth (haptic_anfis.exam.config defaults)
LEVEL_DEPTHS: tuple[tuple[str, float], ...] = (('light', 0.002), ('medium', 0.005),
                                                ('deep', DEEP_DEPTH))
BASIS = ('haptic_anfis.cases.grading (stiffness discrimination through a rigid stylus: Tan et al. '
         '1995, 22 %; the shallowest palpable pressure level)')


def pressure_level(depth: float, levels: Sequence[tuple[str, float]] = LEVEL_DEPTHS
                   ) -> str | None:
    """The deepest pressure level whose depth threshold [m] ``depth`` [m] reaches; None above
    the lightest."""
    name = None
    for n, d in levels:
        if depth >= d - 1e-9:
            name = n
    return name


def grade_contrasts(contrasts: Mapping[float, float], threshold_pct: float = PALPABLE_PCT,
                    levels: Sequence[tuple[str, float]] = LEVEL_DEPTHS) -> dict[str, Any]:
    """Grade one lesion from its contrast [%] per depth [m]: ``palpable``, ``difficulty`` (None
    when not palpable), ``found_depth_m`` / ``found_level`` (the shallowest palpable depth and its
    pressure level), ``reason`` (why it is below what the device renders; None when palpable)."""
    if not (np.isfinite(threshold_pct) and threshold_pct > 0):
        raise ValueError(f'palpability threshold: expected a finite number > 0 %, got '
                         f'{threshold_pct!r}')
    depths = sorted(d for d, c in contrasts.items() if np.isfinite(c))
    found = next((d for d in depths if contrasts[d] >= threshold_pct), None)
    out: dict[str, Any] = {'palpable': found is not None, 'difficulty': None,
                           'found_depth_m': found, 'found_level': None, 'reason': None,
                           'threshold_pct': float(threshold_pct)}
    if found is None:
        if depths:
            best = max(depths, key=lambda d: contrasts[d])
            out['reason'] = (f'below what this device renders: at most {contrasts[best]:+.1f} % '
                             f'(at {best * 1e3:g} mm) against the breast without it, under the '
                             f'{threshold_pct:g} % a stylus can tell apart')
        else:
            out['reason'] = 'below what this device renders: no FE contrast'
        return out
    th = dict(levels)
    c = contrasts[found]
    if found <= th['light'] + 1e-9 and c >= EASY_MULTIPLE * threshold_pct:
        d = 1
    elif found <= th['medium'] + 1e-9:
        d = 2
    elif found <= th['deep'] + 1e-9:
        d = 3
    elif found < max(depths[-1], DEEPEST_DEPTH) - 1e-9:
        d = 4
    else:
        d = 5
    out.update(difficulty=d, found_level=pressure_level(found, levels))
    return out


def difficulty(contrast_pct: float, threshold_pct: float = PALPABLE_PCT, depth: float = 0.002
               ) -> int | None:
    """The difficulty 1-5 of a lesion with one contrast [%] known, at ``depth`` [m]; None below
    the threshold (:func:`grade_contrasts` with that one depth)."""
    return grade_contrasts({depth: contrast_pct}, threshold_pct)['difficulty']


def _force_at(rec: dict[str, Any], depth: float) -> float:
    """|F| [N] of a stored point record at ``depth`` [m] (a solved depth)."""
    d = np.asarray(rec['depths_m'], dtype=float)
    k = np.flatnonzero(np.abs(d - depth) < 1e-9)
    if not len(k):
        raise ValueError(f'no FE force at depth {depth * 1e3:g} mm (solved: '
                         f'{", ".join(f"{v * 1e3:g}" for v in d)} mm)')
    return float(np.linalg.norm(np.asarray(rec['forces_N'], dtype=float)[k[0]]))


def _grade_entry(entry: dict[str, Any], threshold_pct: float) -> dict[str, Any]:
    """A lesion's grading entry (with its per-depth ``contrasts``) graded at ``threshold_pct``;
    the top-level contrast figures are those at the depth it is found (else its largest)."""
    rows = entry['contrasts']
    g = grade_contrasts({r['depth_m']: r['contrast_pct'] for r in rows}, threshold_pct)
    at = g['found_depth_m']
    row = (next(r for r in rows if abs(r['depth_m'] - at) < 1e-9) if at is not None
           else max(rows, key=lambda r: r['contrast_pct']))
    return {**entry, **g, 'depth_m': row['depth_m'], 'force_n': row['force_n'],
            'twin_force_n': row['twin_force_n'], 'contrast_n': row['contrast_n'],
            'contrast_pct': row['contrast_pct']}


def lesion_grades(scene, records: Sequence[dict[str, Any]], twins: dict[str, dict[str, Any]],
                  threshold_pct: float = PALPABLE_PCT) -> list[dict[str, Any]]:
    """Per lesion of ``scene``: ``contrasts`` (depth_m, force_n, twin_force_n, contrast_n,
    contrast_pct at every depth both solved) and the grade (:func:`grade_contrasts`).

    Args:
        records: the case's point records (with ``surface_point_m``); one lies over each centre.
        twins: {lesion name: the twin's record over that lesion's centre}.
    """
    yz = np.array([r['surface_point_m'][1:] for r in records], dtype=float)
    out = []
    for t in scene.tumours:
        k = int(np.argmin(np.hypot(yz[:, 0] - t.centre[1], yz[:, 1] - t.centre[2])))
        if np.hypot(yz[k, 0] - t.centre[1], yz[k, 1] - t.centre[2]) > 1e-6:
            raise ValueError(f'lesion {t.name!r}: no loading point over its centre')
        twin = twins[t.name]
        depths = [float(d) for d in records[k]['depths_m']
                  if np.any(np.abs(np.asarray(twin['depths_m'], float) - d) < 1e-9)]
        rows = []
        for d in depths:
            f_case, f_twin = _force_at(records[k], d), _force_at(twin, d)
            rows.append({'depth_m': d, 'force_n': f_case, 'twin_force_n': f_twin,
                         'contrast_n': f_case - f_twin,
                         'contrast_pct': 100.0 * (f_case - f_twin) / f_twin})
        out.append(_grade_entry({'lesion': t.name, 'kind': t.kind or 'unstated',
                                 'contrasts': rows}, threshold_pct))
    return out


def case_level(grades: Sequence[dict[str, Any]]) -> int | None:
    """The case's level 1-5: its hardest palpable lesion's difficulty; 1 without lesions; None
    when it has lesions and every one is below what the device renders."""
    ds = [g['difficulty'] for g in grades if g['palpable']]
    if ds:
        return int(max(ds))
    return None if grades else 1


def below_device(grading: Mapping[str, Any] | None) -> bool:
    """Whether a case's ``grading`` (a :func:`grading_record`) has lesions and the device
    renders none of them (no level: see the module docstring); False for an ungraded case."""
    if not grading:
        return False
    # one rule for smooth and nodular cases, the palpability the draws read
    # (record.levels.has_palpable_lesion): a nodular lesion that is rendered but not told apart
    # from its background keeps a level (5)
    lesions = grading.get('lesions') or ()
    return bool(lesions) and not any(g.get('palpable') for g in lesions)


def grading_record(grades: Sequence[dict[str, Any]], threshold_pct: float = PALPABLE_PCT
                   ) -> dict[str, Any]:
    """The sidecar's ``grading`` object of a case with these lesion grades."""
    return {'threshold_pct': float(threshold_pct), 'level': case_level(grades),
            'lesions': list(grades),
            'below_device': [g['lesion'] for g in grades if not g['palpable']],
            'levels_m': dict(LEVEL_DEPTHS), 'basis': BASIS}


def regrade(grading: dict[str, Any], threshold_pct: float) -> dict[str, Any]:
    """A stored ``grading`` graded again at ``threshold_pct`` [%] from its lesions' per-depth
    contrasts (a grading written before those were kept has the one depth it was graded at)."""
    grades = []
    for e in grading.get('lesions') or []:
        if not e.get('contrasts'):
            e = {**e, 'contrasts': [{k: e[k] for k in ('depth_m', 'force_n', 'twin_force_n',
                                                         'contrast_n', 'contrast_pct')}]}
        grades.append(_grade_entry(e, threshold_pct))
    return grading_record(grades, threshold_pct)
