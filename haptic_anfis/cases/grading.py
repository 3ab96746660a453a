"""Grading a case from its FE: each lesion's force contrast, palpability, difficulty; the case level.

- **Contrast** of a lesion: the force magnitude |F| the FE gives over the lesion's centre at the
  deep level (:data:`DEEP_DEPTH`, the exam's default ``deep`` threshold: any deep press reaches
  it), minus the same point of the lesion-free twin (the same scene without lesions), in N and in
  % of the twin's force.
- **Palpable** when the contrast reaches :data:`PALPABLE_PCT`: the just-noticeable difference of
  force for a human pressing with the finger, about 7 % (Jones 1989, "Matching forces: constant
  errors and differential thresholds", Perception 18:681-687; 5-10 % in Pang, Tan & Durlach 1991,
  "Manual discrimination of force using active finger motion", Perception & Psychophysics
  49:531-540). The Falcon scales forces but keeps their ratios, so a relative threshold is the
  right kind; it is a lower bound (real lumps are also felt by shape and mobility, which the
  simulator does not render).
- **Difficulty** 1-5 of a palpable lesion from its contrast in multiples of that threshold:
  >= 6x: 1, >= 4x: 2, >= 2.5x: 3, >= 1.5x: 4, else 5.
- **Level** of a case: the difficulty of its hardest palpable lesion; 1 when nothing is palpable
  (the right answer is "no lump"; lesions that are there but not palpable are reported as such).

Pure numpy, no ROS.
"""
from __future__ import annotations

from typing import Any, Sequence

import numpy as np

__all__ = ['DEEP_DEPTH', 'PALPABLE_PCT', 'DIFFICULTY_MULTIPLES', 'difficulty', 'lesion_grades',
           'case_level']

DEEP_DEPTH = 0.008  # [m]: haptic_anfis.exam.config.ExamConfig.deep (default)
PALPABLE_PCT = 7.0  # [%] of the lesion-free force: force JND (Jones 1989)
#: lower bounds (multiples of PALPABLE_PCT) of difficulty 1, 2, 3, 4; 5 below the last
DIFFICULTY_MULTIPLES = (6.0, 4.0, 2.5, 1.5)


def difficulty(contrast_pct: float, threshold_pct: float = PALPABLE_PCT) -> int | None:
    """1 (easy) .. 5 (hard) for a palpable contrast [%], None when below the threshold."""
    if not np.isfinite(contrast_pct) or contrast_pct < threshold_pct:
        return None
    for level, m in enumerate(DIFFICULTY_MULTIPLES, 1):
        if contrast_pct >= m * threshold_pct:
            return level
    return 5


def _force_at(rec: dict[str, Any], depth: float) -> float:
    """|F| [N] of a stored point record at ``depth`` [m] (a solved depth)."""
    d = np.asarray(rec['depths_m'], dtype=float)
    k = np.flatnonzero(np.abs(d - depth) < 1e-9)
    if not len(k):
        raise ValueError(f'no FE force at depth {depth * 1e3:g} mm (solved: '
                         f'{", ".join(f"{v * 1e3:g}" for v in d)} mm)')
    return float(np.linalg.norm(np.asarray(rec['forces_N'], dtype=float)[k[0]]))


def lesion_grades(scene, records: Sequence[dict[str, Any]], twins: dict[str, dict[str, Any]],
                  depth: float = DEEP_DEPTH, threshold_pct: float = PALPABLE_PCT
                  ) -> list[dict[str, Any]]:
    """Per lesion of ``scene``: contrast_n, contrast_pct, palpable, difficulty (and the two forces).

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
        f_case, f_twin = _force_at(records[k], depth), _force_at(twins[t.name], depth)
        c_n = f_case - f_twin
        c_pct = 100.0 * c_n / f_twin
        d = difficulty(c_pct, threshold_pct)
        out.append({'lesion': t.name, 'kind': t.kind or 'unstated', 'depth_m': depth,
                    'force_n': f_case, 'twin_force_n': f_twin, 'contrast_n': c_n,
                    'contrast_pct': c_pct, 'palpable': d is not None, 'difficulty': d,
                    'threshold_pct': threshold_pct})
    return out


def case_level(grades: Sequence[dict[str, Any]]) -> int:
    """The case's level 1-5: its hardest palpable lesion's difficulty; 1 if none is palpable."""
    ds = [g['difficulty'] for g in grades if g['palpable']]
    return int(max(ds)) if ds else 1
