"""Case difficulty levels (1 = easiest) for mastery and ``exam run --next``.

:func:`case_level` prefers a ``level`` the case library states (the graded library,
graded from the FE: lesion contrast, palpability). Until a case has one, the level is derived from
its lesions' count and size alone — a placeholder, documented in docs/trainee_record.md:

- level 1: at most one lesion, and it is at least ``SMALL_DIAMETER`` across (no lesion counts
  here too: covering the breast and marking nothing is the task);
- level 2: one small lesion, or two lesions;
- level 3: three or more lesions, or two with a small one.

Lesion size matters most (Fletcher et al., JAMA 1985: examiners found 87 % of 1 cm lumps on
silicone models but 14 % of 3 mm ones). Pure Python, no ROS.
"""
from __future__ import annotations

from pathlib import Path

from ..cases import library
from ..tissue.scene import load_scene

__all__ = ['MAX_LEVEL', 'SMALL_DIAMETER', 'below_device', 'case_level', 'has_palpable_lesion',
           'level_of_case_name']

#: [m] a lesion narrower than this is "small" for the derived level
SMALL_DIAMETER = 0.012
#: the highest derived level
MAX_LEVEL = 3


def case_level(case) -> int:
    """The difficulty level (>= 1) of ``case``: a :class:`~haptic_anfis.cases.Case`, a
    :class:`~haptic_anfis.tissue.scene.Scene`, or any object with ``level`` / ``scene.level`` /
    ``tumours``. A stated ``level`` (on the case or its scene) wins; else count and size.

    Raises:
        ValueError: a stated level that is not an integer >= 1.
    """
    for owner in (case, getattr(case, 'scene', None)):
        level = getattr(owner, 'level', None) if owner is not None else None
        if level is None and isinstance(owner, dict):
            level = owner.get('level')
        if level is not None:
            if isinstance(level, bool) or not isinstance(level, int) or level < 1:
                raise ValueError(f'case {getattr(case, "name", case)!r}: level: expected an '
                                 f'integer >= 1, got {level!r}')
            return level
    scene = getattr(case, 'scene', case)
    radii = [float(t.radius) for t in getattr(scene, 'tumours', ())]
    n = len(radii)
    small = any(2 * r < SMALL_DIAMETER for r in radii)
    return min(MAX_LEVEL, 1 + max(n - 1, 0) + int(small))


def has_palpable_lesion(case, threshold_pct: float | None = None) -> bool:
    """Whether ``case`` (a library :class:`~haptic_anfis.cases.Case`, or a scene) has a lesion
    the trainee can feel: one its FE grading calls palpable at ``threshold_pct`` [%] (the
    trainee's own; None: the stored grading's, ``Case.grading()``), the threshold the case's
    level is read at too (``Case.level_at``); for a case not graded, any lesion. A case with no
    lesion trains specificity (cover the breast, mark nothing) and ``exam run --next`` draws it
    at every level; one whose lesions are all below what the device renders
    (:func:`below_device`) is neither and is not drawn."""
    grading = getattr(case, 'grading', None)
    g = None
    if callable(grading):
        g = grading() if threshold_pct is None else grading(threshold_pct)
    if g is not None:
        return any(les.get('palpable') for les in g.get('lesions', ()))
    scene = getattr(case, 'scene', case)
    return bool(getattr(scene, 'tumours', ()))


def below_device(case, threshold_pct: float | None = None) -> bool:
    """Whether ``case`` is graded, has lesions, and the device renders none of them at
    ``threshold_pct`` [%] (None: as stored): it has no level (``cases list`` shows its reason)
    and blind draws and mastery pass it by (:func:`haptic_anfis.cases.grading.below_device`)."""
    check = getattr(case, 'below_device_at', None)
    return bool(check(threshold_pct)) if callable(check) else False


def level_of_case_name(name: str | None) -> int | None:
    """:func:`case_level` of a case of the shipped library or of a scene file, by the name an
    exam report gives (``report['case']``); None when it is neither (or unreadable)."""
    if not name:
        return None

    try:
        p = Path(name)
        if p.suffix in ('.yaml', '.yml') and p.is_file():
            return case_level(load_scene(p))
        case = library().get(name)
        # every lesion below what the device renders: no level (its sessions count neither way)
        return None if below_device(case) else case_level(case)
    except ValueError:
        return None
