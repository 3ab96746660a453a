"""Where the lesions are: a small source function, so a case library can plug in (no ROS)."""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..cases import CaseError, library
from ..cases.grading import DEEP_DEPTH
from ..tissue.scene import DEFAULT_SCENE, load_scene


@dataclass(frozen=True)
class Lesion:
    """A lesion to find: ``name``, ``centre`` (3,) [m] tissue frame, ``radius`` [m]; ``palpable``
    False when the case's FE grading says the device does not render it to a stylus (scored
    neither hit nor miss, reported as below what this device renders, with ``reason``);
    ``level``: the pressure level ('light', 'medium', 'deep') and ``level_depth`` [m] the tissue
    depth at which it is first palpable (None: ungraded); ``contrast_pct`` how much it stands
    out [%] (its force against the breast without it) at ``contrast_depth`` [m], the deep
    pressure's depth when graded there; ``difficulty`` 1-5 (None: not palpable or ungraded)."""
    name: str
    centre: tuple[float, float, float]
    radius: float
    palpable: bool = True
    level: str | None = None
    level_depth: float | None = None
    reason: str | None = None
    contrast_pct: float | None = None
    contrast_depth: float | None = None
    difficulty: int | None = None


@dataclass(frozen=True)
class ExamSubject:
    """What the examiner needs to know of the case: its lesions, the palpable radius [m] and the
    probe radius [m] from the scene, and the scene file (provenance); ``background``: the
    scene's normal background (:class:`haptic_anfis.tissue.background.Background`: a false mark
    on a nodule or a rib says which), None for a smooth breast; ``background_grading``: the
    case's FE grading of that background (each nodule's and rib's bump, the confounders:
    :func:`haptic_anfis.cases.background.background_grades`), None when not graded."""
    lesions: tuple[Lesion, ...]
    palpable_radius: float
    probe_radius: float
    source: str
    background: Any = None
    background_grading: dict | None = None


def subject_from_scene(path: str | os.PathLike | None = None) -> ExamSubject:
    """The lesions (tumours) and palpable radius of a scene file (default: the default scene).

    Raises:
        SceneError (a ValueError): the file is missing or malformed.
    """
    p = Path(path) if path else DEFAULT_SCENE
    sc = load_scene(p)
    grading = _case_grading(p)
    graded = _fe_grades(grading)
    les = tuple(Lesion(t.name, tuple(float(c) for c in t.centre), float(t.radius),
                       **graded.get(t.name, {}))
                for t in sc.tumours)
    return ExamSubject(les, float(sc.palpable_radius), float(sc.probe_radius), str(p),
                       sc.background, grading.get('background'))


def _case_grading(scene_path: Path) -> dict:
    """The FE grading of the library case whose scene file this is (haptic_anfis.cases.grading);
    {} for an ungraded scene."""
    lib = library()
    try:
        case = lib.get(scene_path.stem)
    except CaseError:
        return {}
    if case.scene_path.resolve() != scene_path.resolve():
        return {}
    return case.grading() or {}


def _fe_grades(grading: dict) -> dict[str, dict]:
    """{lesion name: {palpable, level, level_depth, reason}} from a case's FE ``grading``
    (:func:`_case_grading`); {} (all palpable, no level) for an ungraded scene."""
    return {g['lesion']: {'palpable': bool(g['palpable']), 'level': g.get('found_level'),
                          'level_depth': g.get('found_depth_m'), 'reason': g.get('reason'),
                          'difficulty': g.get('difficulty'), **_deep_contrast(g)}
            for g in (grading.get('lesions') or [])}


def _deep_contrast(grade: dict) -> dict:
    """``contrast_pct`` / ``contrast_depth`` [m] of a lesion's grading: at the deep pressure's
    depth (what a trainee pressing as taught would feel), else its strongest; {} without
    per-depth contrasts."""
    rows = grade.get('contrasts') or []
    if not rows:
        return {}
    row = next((r for r in rows if abs(r['depth_m'] - DEEP_DEPTH) < 1e-6),
               max(rows, key=lambda r: r['contrast_pct']))
    return {'contrast_pct': float(row['contrast_pct']), 'contrast_depth': float(row['depth_m'])}


def lesion_surface_points(detector, lesions) -> np.ndarray:
    """(k, 3) [m]: each lesion's centre projected on the skin along the probe axis (the surface
    point a probe pressing straight in over the lesion touches)."""
    out = []
    for les in lesions:
        r = detector.query(np.asarray(les.centre, float))
        out.append(r.contact_point if r.in_contact else r.point)
    return np.array(out, float).reshape(-1, 3)
