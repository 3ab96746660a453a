"""The breast's normal background as the exam reports it: its nodules and ribs on the skin beside
the lesions, how much each stood out, and the trainee's false marks on them (no ROS).

After the exam the debrief shows every bump the trainee felt, not only the lesions: a normal
glandular lobule (or a fat lobule) and a rib are drawn where they lie, with their bump over the
same breast without them (smooth) at deep pressure from the case's FE grading
(:func:`haptic_anfis.cases.background.background_grades`), and those whose bump reaches the
palpability threshold (the *confounders*: normal tissue that stands out as much as a lesion
the device renders) are told apart. The specificity figures split the false marks into those on
a normal structure and those elsewhere.
"""
from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ['RIB_POINTS', 'normal_lines', 'normal_regions', 'skin_point', 'specificity',
           'specificity_text']

#: surface points per rib in the report (its line across the region to examine, for drawing)
RIB_POINTS = 9
#: [m] height over the chest wall of the query point under a skin point: inside the breast
#: wherever it has tissue, so the detector walks out along +x to the skin above it
_UNDER = 1e-3


def _mm(p) -> list[float]:
    return [round(float(v) * 1e3, 2) for v in p]


def skin_point(detector, y: float, z: float) -> np.ndarray | None:
    """The skin point over (y, z) [m] (the probe axis is -x), None where no skin lies over it."""
    r = detector.query(np.array([_UNDER, y, z]))
    return np.asarray(r.contact_point, float) if r.in_contact else None


def normal_regions(detector, background, grading: dict[str, Any] | None, marks: list[dict],
                   region_radius: float) -> list[dict[str, Any]]:
    """One entry per nodule and rib of ``background``
    (:class:`~haptic_anfis.tissue.background.Background`; [] for None) for the report.

    Args:
        detector: the skin's contact detector (projects along -x).
        grading: the case's background grading (its ``grading()['background']``), None when
            the case is not graded: then no bump and no confounder is known.
        marks: the report's marks (:func:`.findings.match`): a mark with ``normal`` names the
            region it fell on.
        region_radius: [m] the region to examine (a rib is drawn across it).

    Each entry: ``name``, ``kind`` ('nodule' / 'rib'), ``what`` ('a normal glandular lobule',
    'a fat lobule', 'a rib'), ``radius_mm``, ``surface_mm`` (the skin point over it; a rib's
    over y = 0), ``line_mm`` (a rib: its line on the skin, up to :data:`RIB_POINTS` points
    across the region; [] for a nodule), ``depth_mm`` (a nodule's centre under the skin),
    ``bump_pct`` (how much it stood out at deep pressure [%], None ungraded), ``confounder``
    (its bump reaches the grading's threshold), ``marks`` (indices of the marks on it)."""
    if background is None:
        return []
    g = grading or {}
    bumps = {r['name']: r.get('bump_pct') for r in (*g.get('nodules', ()), *g.get('ribs', ()))}
    confound = set(g.get('confounders') or ())
    on: dict[str, list[int]] = {}
    for m in marks:
        if m.get('normal'):
            on.setdefault(m['normal'], []).append(int(m['index']))
    out = []
    for n in background.nodules:
        s = skin_point(detector, n.centre[1], n.centre[2])
        out.append({'name': n.name, 'kind': 'nodule', 'what': n.what,
                    'radius_mm': round(n.radius * 1e3, 2),
                    'surface_mm': None if s is None else _mm(s), 'line_mm': [],
                    'depth_mm': None if s is None else round((s[0] - n.centre[0]) * 1e3, 2)})
    for rib in background.ribs:
        half = float(np.sqrt(max(region_radius ** 2 - rib.z ** 2, 0.0)))
        line = [p for p in (skin_point(detector, y, rib.z)
                            for y in np.linspace(-half, half, RIB_POINTS)) if p is not None]
        s = skin_point(detector, 0.0, rib.z)
        out.append({'name': rib.name, 'kind': 'rib', 'what': rib.what,
                    'radius_mm': round(rib.radius * 1e3, 2),
                    'surface_mm': None if s is None else _mm(s),
                    'line_mm': [_mm(p) for p in line] if half > 0 else [], 'depth_mm': None})
    for e in out:
        b = bumps.get(e['name'])
        e.update(bump_pct=None if b is None else round(float(b), 1) + 0.0,   # no '-0.0'
                 confounder=e['name'] in confound, marks=on.get(e['name'], []))
    return out


def specificity(fin: dict[str, Any], normal: list[dict[str, Any]],
                grading: dict[str, Any] | None = None) -> dict[str, Any]:
    """The case's specificity figures from the findings ``fin`` (:func:`.findings.match`) and
    its ``normal`` regions (:func:`normal_regions`): ``false_marks``, ``on_normal`` (on a
    nodule or a rib), ``elsewhere``, ``clean`` (no false mark: the exam was negative where the
    breast is normal), ``normal_regions``, ``confounders``, ``confounders_marked`` and the
    background grading's ``threshold_pct`` [%] (what a confounder's bump reaches; None
    ungraded)."""
    n, on = int(fin['false_marks']), int(fin['false_marks_normal'])
    conf = [e for e in normal if e['confounder']]
    return {'false_marks': n, 'on_normal': on, 'elsewhere': n - on, 'clean': n == 0,
            'normal_regions': len(normal), 'confounders': len(conf),
            'confounders_marked': sum(bool(e['marks']) for e in conf),
            'threshold_pct': (grading or {}).get('threshold_pct')}


def specificity_text(report: dict[str, Any]) -> str:
    """' (2 on normal tissue, 1 elsewhere)' after a report's false-mark count: '' without a
    false mark or a normal background (a smooth case, a report made before the split)."""
    sp = report.get('specificity')
    if not sp or not sp['false_marks'] or not sp['normal_regions']:
        return ''
    return f" ({sp['on_normal']} on normal tissue, {sp['elsewhere']} elsewhere)"


def _bump(e: dict[str, Any]) -> str:
    return '' if e.get('bump_pct') is None else f", bump {e['bump_pct']:+.1f} %"


def normal_lines(report: dict[str, Any]) -> list[str]:
    """What a report says of the breast's normal background, for an instructor: how many
    lobules and ribs and how much they stood out at deep pressure, those that stand out as
    much as a lesion the device renders (confounders), and the normal structures the trainee
    marked. [] for a smooth case."""
    normal = report.get('normal') or []
    if not normal:
        return []
    nod = [e for e in normal if e['kind'] == 'nodule']
    ribs = [e for e in normal if e['kind'] == 'rib' and e['line_mm']]   # under the region
    kinds = sorted({e['what'].removeprefix('a ').removeprefix('normal ') for e in nod})
    parts = [f"{len(nod)} {' / '.join(k + 's' for k in kinds) or 'lobules'}"] if nod else []
    bumps = [e['bump_pct'] for e in nod if e.get('bump_pct') is not None]
    if bumps:
        parts[0] += f' (bumps {min(bumps):+.1f}..{max(bumps):+.1f} % at deep pressure)'
    if ribs:
        parts.append(f"{len(ribs)} rib{'s' if len(ribs) > 1 else ''} under the region")
    lines = ['normal background: ' + (', '.join(parts) or 'none under the region')]
    thr = (report.get('specificity') or {}).get('threshold_pct')
    conf = [e for e in normal if e['confounder']]
    if thr is not None:
        lines.append(f'stand out as much as a lesion (bump >= {thr:g} %): '
                     + (', '.join(f"{e['name']} ({e['what']}{_bump(e)})" for e in conf)
                        or 'none'))
    for e in normal:
        if e['marks']:
            lines.append(f"false mark{'s' if len(e['marks']) > 1 else ''} "
                         f"{', '.join(str(i) for i in e['marks'])} on {e['name']}: "
                         f"{e['what']}{_bump(e)}, not a lesion")
    return lines
