"""Where the lesions are: a small source function, so a case library can plug in (no ROS)."""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np


@dataclass(frozen=True)
class Lesion:
    """A lesion to find: ``name``, ``centre`` (3,) [m] tissue frame, ``radius`` [m]; ``palpable``
    False when the case's FE says a probe cannot feel it (scored neither hit nor miss, reported
    as 'not palpable here')."""
    name: str
    centre: tuple[float, float, float]
    radius: float
    palpable: bool = True


@dataclass(frozen=True)
class ExamSubject:
    """What the examiner needs to know of the case: its lesions, the palpable radius [m] and the
    probe radius [m] from the scene, and the scene file (provenance); ``background``: the
    scene's normal background (:class:`haptic_anfis.tissue.background.Background`: a false mark
    on a nodule or a rib says which), None for a smooth breast."""
    lesions: tuple[Lesion, ...]
    palpable_radius: float
    probe_radius: float
    source: str
    background: Any = None


def subject_from_scene(path: str | os.PathLike | None = None) -> ExamSubject:
    """The lesions (tumours) and palpable radius of a scene file (default: the default scene).

    Raises:
        SceneError (a ValueError): the file is missing or malformed.
    """
    from ..tissue.scene import DEFAULT_SCENE, load_scene
    p = Path(path) if path else DEFAULT_SCENE
    sc = load_scene(p)
    palpable = _fe_palpable(p)
    les = tuple(Lesion(t.name, tuple(float(c) for c in t.centre), float(t.radius),
                       palpable.get(t.name, True))
                for t in sc.tumours)
    return ExamSubject(les, float(sc.palpable_radius), float(sc.probe_radius), str(p),
                       sc.background)


def _fe_palpable(scene_path: Path) -> dict[str, bool]:
    """{lesion name: palpable} from the FE grading of the library case whose scene file this
    is (haptic_anfis.cases.grading); {} (all palpable) for an ungraded scene."""
    from ..cases import CaseError, library

    lib = library()
    try:
        case = lib.get(scene_path.stem)
    except CaseError:
        return {}
    if case.scene_path.resolve() != scene_path.resolve():
        return {}
    return {g['lesion']: bool(g['palpable'])
            for g in ((case.grading() or {}).get('lesions') or [])}


def lesion_surface_points(detector, lesions) -> np.ndarray:
    """(k, 3) [m]: each lesion's centre projected on the skin along the probe axis (the surface
    point a probe pressing straight in over the lesion touches)."""
    out = []
    for les in lesions:
        r = detector.query(np.asarray(les.centre, float))
        out.append(r.contact_point if r.in_contact else r.point)
    return np.array(out, float).reshape(-1, 3)
