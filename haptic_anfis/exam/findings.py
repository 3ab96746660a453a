"""Marks against lesions: hits, false marks, misses, and why a lesion was missed (no ROS)."""
from __future__ import annotations

import numpy as np


def project_marks(detector, marks: np.ndarray, tolerance: float) -> tuple[np.ndarray, list]:
    """Surface points (n, 3) [m] of the mark positions ``marks`` (n, 3) [m] (probe tip when
    button 1 was pressed), and per mark None or why it is invalid: outside the skin by more than
    ``tolerance`` [m], or not finite."""
    out = np.zeros((len(marks), 3))
    why: list = []
    for i, m in enumerate(np.asarray(marks, float).reshape(-1, 3)):
        if not np.isfinite(m).all():
            why.append('mark position is not finite')
            out[i] = np.nan
            continue
        r = detector.query(m)
        out[i] = r.contact_point if r.in_contact else r.point
        if r.signed_distance > tolerance:
            why.append(f'{r.signed_distance * 1e3:.1f} mm outside the surface (tolerance '
                       f'{tolerance * 1e3:.1f} mm)')
        else:
            why.append(None)
    return out, why


#: how a lesion the device does not render to a stylus is reported (not "not palpable": people
#: find 3-5 mm lumps in silicone models by shape and mobility, which the simulator does not render)
BELOW_DEVICE = 'below what this device renders'


def match(lesions, lesion_points: np.ndarray, mark_points: np.ndarray, invalid: list,
          margin: float, palpated_deep: list[bool], background=None) -> dict:
    """Findings: each valid mark within lesion radius + ``margin`` of a lesion's surface point is
    a hit (on the nearest such lesion; more marks on a found lesion are 'repeat' marks, not false);
    other marks are false; each lesion not hit is a miss, 'missed although palpated deep' when
    ``palpated_deep[k]`` else 'never palpated deep'. A lesion the FE grading says the device
    does not render to a stylus (``palpable`` False) is neither hit nor miss: it is reported
    'below what this device renders' with the grading's reason, and a mark on it is neither a
    hit nor a false mark. Each lesion says at which pressure level it is first palpable
    (``level``, ``level_depth_mm``; None when ungraded). With the case's ``background`` (its
    nodules and ribs), a false mark over a normal region says which ('no lesion here: a rib
    (rib2)') and names it in ``normal``; ``false_marks_normal`` counts them."""
    found = [None] * len(lesions)
    marks = []
    for i, (p, bad) in enumerate(zip(mark_points, invalid)):
        entry = {'index': i, 'surface_mm': [round(float(v) * 1e3, 2) for v in p]
                 if np.isfinite(p).all() else None}
        if bad:
            entry.update(result='false', reason=bad)
            marks.append(entry)
            continue
        best, bd = None, np.inf
        for k, les in enumerate(lesions):
            d = float(np.linalg.norm(p - lesion_points[k]))
            if d <= les.radius + margin and d < bd:
                best, bd = k, d
        region = (background.region_at(float(p[1]), float(p[2]), margin)
                  if best is None and background is not None else None)
        if region is not None:
            entry.update(result='false', reason=f'no lesion here: {region[1]} ({region[0]})',
                         normal=region[0])
        elif best is None:
            entry.update(result='false', reason='no lesion within radius + margin')
        elif not getattr(lesions[best], 'palpable', True):
            entry.update(result='not_palpable', lesion=lesions[best].name,
                         distance_mm=round(bd * 1e3, 2))
        elif found[best] is None:
            found[best] = i
            entry.update(result='hit', lesion=lesions[best].name, distance_mm=round(bd * 1e3, 2))
        else:
            entry.update(result='repeat', lesion=lesions[best].name, distance_mm=round(bd * 1e3, 2))
        marks.append(entry)
    les_out = []
    for k, les in enumerate(lesions):
        e = {'name': les.name, 'centre_mm': [round(c * 1e3, 2) for c in les.centre],
             'radius_mm': round(les.radius * 1e3, 2),
             'surface_mm': [round(float(c) * 1e3, 2) for c in lesion_points[k]],
             'found': found[k] is not None, 'palpated_deep': bool(palpated_deep[k]),
             'palpable': bool(getattr(les, 'palpable', True)),
             'level': getattr(les, 'level', None),
             'level_depth_mm': (None if getattr(les, 'level_depth', None) is None
                                else round(les.level_depth * 1e3, 2)),
             'contrast_pct': (None if getattr(les, 'contrast_pct', None) is None
                              else round(les.contrast_pct, 1)),
             'contrast_depth_mm': (None if getattr(les, 'contrast_depth', None) is None
                                   else round(les.contrast_depth * 1e3, 2)),
             'difficulty': getattr(les, 'difficulty', None)}
        if not e['palpable']:
            e['missed'] = BELOW_DEVICE
            e['reason'] = getattr(les, 'reason', None)
        elif found[k] is None:
            e['missed'] = ('missed although palpated deep' if palpated_deep[k]
                           else 'never palpated deep')
        les_out.append(e)
    hits = sum(f is not None for f in found)
    n_palpable = sum(bool(getattr(les, 'palpable', True)) for les in lesions)
    return {'hits': hits, 'misses': n_palpable - hits, 'palpable_lesions': n_palpable,
            'false_marks': sum(m['result'] == 'false' for m in marks),
            'false_marks_normal': sum('normal' in m for m in marks),
            'marks': marks, 'lesions': les_out}
