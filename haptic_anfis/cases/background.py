"""Grading a case against its normal background: does a lesion stand out from the nodules?

In a nodular breast every bump is not a lesion. What tells a lesion apart is that, at the same
pressing level, it feels firmer than the normal nodules and ribs do. From the case's FE points
(no extra solves) and the force map of the same breast without any region
(:class:`~.reference.SmoothReference`: a lesion-free smooth case of the same geometry, scaled to
the base modulus), per indentation depth (the exam's levels are tissue depths):

- **Contrast** of a point: its |F| over the smooth breast's at the same point, in % (and in N).
  The contrast of a region (a lesion, a nodule) is the largest among the loading points over it:
  within its radius of its (y, z), or the nearest point when none lies that close. Over ribs the
  smooth breast is the one over the same ribs (they raise the force everywhere, between them
  too), and a **rib's** own contrast is its ridge in that smooth breast: the force over its line
  against the intercostal tissue halfway to its neighbours, at the same y, the largest along the
  line's loading points. Nothing is fitted to the nodular map, so no bump is
  absorbed into its own background. A normal region is read only at points beyond every
  lesion's reach (farther from its centre than its radius plus the probe's), else the lesion's
  own bump would count as a normal one; a region with no point within its radius reads its
  nearest point within one grid spacing; one with none is not graded (``bump_pct`` None, no
  ``contrasts``: beyond the loaded disc, or under a lesion's bump).
- **Depths**: every depth at least :data:`MIN_SOLVED_SHARE` of the points reached; a partial
  point (its load path stopped short near the rim or over a rib) is left out where it stopped.
- **Normal distribution** per depth: the contrasts of the nodules and ribs (min, median, max and
  how many reach the threshold). Those reaching the threshold at some depth are *confounders*.
- **Separation** of a lesion per depth: its force over that of the firmest normal region, in %
  (``100 * ((1 + c_lesion) / (1 + c_normal) - 1)``, with c_normal at least 0: against a smooth
  feel it is the lesion's contrast). The threshold is a discrimination threshold between two
  stiffnesses felt through a stylus (:data:`~.grading.PALPABLE_PCT`, Tan et al. 1995), so a
  lesion is told apart at the depths where its separation reaches it. The per-depth separations
  are graded as a smooth case's contrasts are (:func:`~.grading.grade_contrasts`: the
  shallowest depth it is told apart at and the level scale 1-5). A lesion never told apart is
  difficulty 5: through the device it is one more bump among the normal ones (``felt`` says
  whether its contrast over the smooth breast reaches the threshold at some depth, ``reason``
  what it lacks).
- **Level** of a nodular case: its hardest lesion's difficulty; without lesions, 1 when no
  normal region reaches the threshold (a smooth feel), else 2 (bumps the trainee must leave
  unmarked).

``bump_pct`` / ``bump_n`` of a region are its contrast at the deep level
(:data:`~.grading.DEEP_DEPTH`), the figure the exam and the debrief show. Pure numpy, no ROS.
"""
from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from ..tissue.scenebase import surface_height
from .grading import DEEP_DEPTH, PALPABLE_PCT, grade_contrasts

__all__ = ['FEATURE_GATE', 'MIN_SOLVED_SHARE', 'force_map', 'basis', 'map_contrasts',
           'separation_pct', 'background_grades', 'regrade_background', 'background_gate_failures',
           'summary_fields']

#: grouped-CV RMSE (vector norm) as a fraction of each graded feature's bump (as for lesions)
FEATURE_GATE = 1.0 / 3.0


#: a depth is graded when at least this share of a case's points reached it (a partial point,
#: whose load path stopped short of it near the rim or over a rib, is left out at that depth)
MIN_SOLVED_SHARE = 0.9


def force_map(records: Sequence[dict[str, Any]], depth: float = DEEP_DEPTH,
              skip_missing: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """((P, 2) loading points (y, z) [m], (P,) |F| [N] at ``depth`` [m]) of the point records
    (``skip_missing``: leave out the points that did not reach ``depth``, else refuse them)."""
    yz, f = [], []
    for r in records:
        d = np.asarray(r['depths_m'], dtype=float)
        k = np.flatnonzero(np.abs(d - depth) < 1e-9)
        if not len(k) and skip_missing:
            continue
        if not len(k):
            raise ValueError(f'no FE force at depth {depth * 1e3:g} mm at point '
                             f'{r["surface_point_m"]}')
        yz.append(r['surface_point_m'][1:])
        f.append(float(np.linalg.norm(np.asarray(r['forces_N'], dtype=float)[k[0]])))
    return np.asarray(yz, dtype=float), np.asarray(f)


def basis(yz: np.ndarray, scale: float, degree: int) -> np.ndarray:
    """(P, terms) monomials u^i v^j, i + j <= ``degree``, of (y, z) / ``scale`` [m]."""
    u, v = yz[:, 0] / scale, yz[:, 1] / scale
    return np.column_stack([u ** i * v ** j for i in range(degree + 1)
                            for j in range(degree + 1 - i)])


def map_contrasts(records: Sequence[dict[str, Any]], reference, depth: float
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """((P, 2) points [m], (P,) contrast [%], (P,) contrast [N]) of the case's force map at
    ``depth`` [m] over the smooth breast ``reference`` (an object with ``forces(yz, depth)``)."""
    yz, f = force_map(records, depth, skip_missing=True)
    ref = np.asarray(reference.forces(yz, depth), dtype=float)
    return yz, 100.0 * (f - ref) / ref, f - ref


def separation_pct(lesion_pct: float, normal_pct: float) -> float:
    """[%] how much firmer a lesion of contrast ``lesion_pct`` feels than the firmest normal
    region, of contrast ``normal_pct`` (both over the smooth breast; a normal map below the
    smooth breast counts as smooth)."""
    return 100.0 * ((1.0 + lesion_pct / 100.0) / (1.0 + max(normal_pct, 0.0) / 100.0) - 1.0)


def _region_point(yz: np.ndarray, c: np.ndarray, centre: Sequence[float], radius: float) -> int:
    """Index of the point with the largest contrast within ``radius`` of ``centre`` (y, z), or
    the nearest point when none is that close."""
    d = np.hypot(yz[:, 0] - centre[0], yz[:, 1] - centre[1])
    near = np.flatnonzero(d <= radius + 1e-12)
    return int(near[np.argmax(c[near])]) if len(near) else int(np.argmin(d))


def _depths(scene, records: Sequence[dict[str, Any]]) -> list[float]:
    """The scene's depths [m] that at least :data:`MIN_SOLVED_SHARE` of the records solved."""
    def share(d: float) -> float:
        return float(np.mean([np.any(np.abs(np.asarray(r['depths_m'], float) - d) < 1e-9)
                              for r in records]))
    return [float(d) for d in scene.depths if records and share(d) >= MIN_SOLVED_SHARE]


def _at(rows: list[dict[str, Any]], depth: float) -> dict[str, Any]:
    return next(r for r in rows if abs(r['depth_m'] - depth) < 1e-9)


def background_grades(scene, records: Sequence[dict[str, Any]], reference,
                      threshold_pct: float = PALPABLE_PCT, depth: float = DEEP_DEPTH
                      ) -> dict[str, Any]:
    """The case's grading against its background (see the module docstring).

    Args:
        reference: the smooth breast (:class:`~.reference.SmoothReference`, or any object with
            ``name`` and ``forces(yz, depth)`` giving |F| [N] at (P, 2) points [m]).
        depth: [m] the level whose contrasts are the regions' ``bump_pct`` / ``bump_n``.

    Raises:
        ValueError: the threshold is not a positive number, or no depth of ``depth`` was solved.

    Returns a dict: ``background`` ('smooth' / 'nodular'), ``reference`` (the smooth case),
    ``depths_m``, ``nodules`` (per nodule: name, kind, radius_m, depth_m, contrasts per depth,
    bump_pct, bump_n), ``ribs`` (per rib: name, z_m, contrasts, bump_pct, bump_n),
    ``normal_by_depth`` (per depth: min / median / max contrast %, count at the threshold),
    ``nodule_bump_pct`` ([min, max] at ``depth`` or None), ``lesions`` (per lesion: contrasts
    and separations per depth, bump_pct, bump_n, margin_pct, felt, stands_out, found_depth_m,
    found_level, difficulty), ``confounders`` (normal regions whose contrast reaches the
    threshold at some depth), ``level``, ``depth_m``, ``threshold_pct``.
    """
    depths = _depths(scene, records)
    if not any(abs(d - depth) < 1e-9 for d in depths):
        raise ValueError(f'background grading: no FE force at the level depth {depth * 1e3:g} mm '
                         f"(solved at {MIN_SOLVED_SHARE:.0%} of the points or more: "
                         f"{', '.join(f'{d * 1e3:g}' for d in depths)} mm)")
    maps = {d: map_contrasts(records, reference, d) for d in depths}
    bg = scene.background

    # a normal region is read away from every lesion's reach (the probe over the lesion's
    # footprint), else the lesion's own bump would be counted as a normal one; per depth, as a
    # partial point is missing from the deeper maps
    clear = {}
    for d, (yz, _, _) in maps.items():
        clear[d] = np.ones(len(yz), dtype=bool)
        for t in scene.tumours:
            clear[d] &= np.hypot(yz[:, 0] - t.centre[1], yz[:, 1] - t.centre[2]) \
                > t.radius + scene.probe_radius

    def rows(centre, radius, normal: bool) -> list[dict[str, Any]]:
        out = []
        for d, (yz, c, cn) in maps.items():
            allowed = clear[d] if normal else np.ones(len(yz), dtype=bool)
            dist = np.hypot(yz[:, 0] - centre[0], yz[:, 1] - centre[1])
            on = np.flatnonzero((dist <= radius + 1e-12) & allowed)
            # a region between the grid's points: its nearest point, within one spacing
            near = np.flatnonzero(allowed & (dist <= radius + scene.spacing + 1e-12))
            if not len(on) and len(near):
                on = near[[int(np.argmin(dist[near]))]]
            if not len(on):
                return []
            k = int(on[np.argmax(c[on])])
            out.append({'depth_m': d, 'contrast_pct': float(c[k]), 'contrast_n': float(cn[k])})
        return out

    ribs = bg.ribs if bg is not None else ()

    def rib_rows(i: int) -> list[dict[str, Any]]:
        # a rib's bump is its ridge in the smooth breast over the ribs (the reference): the force
        # over its line against the intercostal tissue halfway to its neighbours, at the same y
        rib = ribs[i]
        mids = [0.5 * (rib.z + ribs[j].z) for j in (i - 1, i + 1) if 0 <= j < len(ribs)]
        if not mids:
            return []
        out = []
        for d, (yz, _, _) in maps.items():
            on = np.flatnonzero((np.abs(yz[:, 1] - rib.z) <= rib.radius) & clear[d])
            if not len(on):
                return []
            y = yz[on, 0]   # the loading points on the line: the reference's FE points too
            # one reference call per depth: the line, then each neighbouring midline
            f = reference.forces(np.vstack([yz[on], *(np.column_stack([y, np.full_like(y, m)])
                                                     for m in mids)]), d).reshape(-1, len(on))
            f_on, f_mid = f[0], f[1:].mean(axis=0)
            k = int(np.argmax(f_on / f_mid))
            out.append({'depth_m': d, 'contrast_pct': float(100.0 * (f_on[k] / f_mid[k] - 1.0)),
                        'contrast_n': float(f_on[k] - f_mid[k])})
        return out

    def deep(entry: dict[str, Any]) -> dict[str, Any]:
        if not entry['contrasts']:   # all its points are within a lesion's reach
            return {**entry, 'bump_pct': None, 'bump_n': None}
        r = _at(entry['contrasts'], depth)
        return {**entry, 'bump_pct': r['contrast_pct'], 'bump_n': r['contrast_n']}

    out: dict[str, Any] = {'depth_m': depth, 'threshold_pct': threshold_pct, 'depths_m': depths,
                           'background': bg.kind if bg is not None else 'smooth',
                           'reference': getattr(reference, 'name', str(reference)),
                           'nodules': [], 'ribs': []}
    for n in (bg.nodules if bg is not None else ()):
        out['nodules'].append(deep({'name': n.name, 'kind': n.kind, 'radius_m': n.radius,
                                    'depth_m': _depth(scene, n.centre),
                                    'contrasts': rows(n.centre[1:], n.radius, True)}))
    for i, rib in enumerate(ribs):
        out['ribs'].append(deep({'name': rib.name, 'z_m': rib.z, 'contrasts': rib_rows(i)}))
    nod = [e['bump_pct'] for e in out['nodules'] if e['bump_pct'] is not None]
    out['nodule_bump_pct'] = [float(min(nod)), float(max(nod))] if nod else None
    out['lesions'] = [{'lesion': t.name, 'contrasts': rows(t.centre[1:], t.radius, False)}
                      for t in scene.tumours]
    return regrade_background(out, threshold_pct)


def regrade_background(grading: dict[str, Any], threshold_pct: float) -> dict[str, Any]:
    """A background grading graded (again) at ``threshold_pct`` [%] from its regions' per-depth
    contrasts: the normal distribution per depth, the confounders, each lesion's separations and
    grade, the level (a trainee's own threshold; :func:`background_grades` grades once)."""
    if not (np.isfinite(threshold_pct) and threshold_pct > 0):
        raise ValueError(f'palpability threshold: expected a finite number > 0 %, got '
                         f'{threshold_pct!r}')
    out = {**grading, 'threshold_pct': float(threshold_pct)}
    normal = [e for e in (*out['nodules'], *out['ribs']) if e['contrasts']]
    out['normal_by_depth'] = []
    for d in out['depths_m']:
        c = np.array([_at(e['contrasts'], d)['contrast_pct'] for e in normal])
        out['normal_by_depth'].append(
            {'depth_m': d, 'count': len(c),
             **({'min_pct': float(c.min()), 'median_pct': float(np.median(c)),
                 'max_pct': float(c.max()), 'at_threshold': int((c >= threshold_pct).sum())}
                if len(c) else {'min_pct': None, 'median_pct': None, 'max_pct': None,
                                'at_threshold': 0})})
    out['confounders'] = [e['name'] for e in normal
                          if any(r['contrast_pct'] >= threshold_pct for r in e['contrasts'])]
    out['lesions'] = [_lesion(g['lesion'], [dict(r) for r in g['contrasts']],
                              out['normal_by_depth'], threshold_pct, out['depth_m'])
                      for g in grading['lesions']]
    out['level'] = (int(max(g['difficulty'] for g in out['lesions'])) if out['lesions']
                    else 2 if out['confounders'] else 1)
    return out


def _lesion(name: str, contrasts: list[dict[str, Any]], normal_by_depth: list[dict[str, Any]],
            threshold_pct: float, depth: float) -> dict[str, Any]:
    """One lesion's grade against the normal regions' contrasts per depth."""
    for r in contrasts:
        n = _at(normal_by_depth, r['depth_m'])
        worst = n['max_pct'] if n['max_pct'] is not None else 0.0
        r.update(normal_max_pct=worst,
                 separation_pct=separation_pct(r['contrast_pct'], worst))
    g = grade_contrasts({r['depth_m']: r['separation_pct'] for r in contrasts}, threshold_pct)
    felt = any(r['contrast_pct'] >= threshold_pct for r in contrasts)
    at = g['found_depth_m']
    margin = (_at(contrasts, at) if at is not None
              else max(contrasts, key=lambda r: r['separation_pct']))['separation_pct']
    d = g['difficulty'] if g['palpable'] else 5
    best = max(contrasts, key=lambda r: r['separation_pct'])
    reason = None if g['palpable'] else (
        f'never told apart: at most {best["separation_pct"]:+.1f} % over the firmest normal '
        f'region (at {best["depth_m"] * 1e3:g} mm; {best["contrast_pct"]:+.1f} % over the smooth '
        f'breast), under the {threshold_pct:g} % a stylus can tell apart')
    r = _at(contrasts, depth)
    return {'lesion': name, 'contrasts': contrasts, 'bump_pct': r['contrast_pct'],
            'bump_n': r['contrast_n'], 'margin_pct': float(margin), 'felt': felt,
            'stands_out': g['palpable'], 'found_depth_m': at, 'found_level': g['found_level'],
            'difficulty': d, 'reason': reason}


def background_gate_failures(cv_rmse: np.ndarray, grading: dict[str, Any]) -> list[str]:
    """One message per graded feature whose bump the model cannot render: the grouped-CV RMSE
    (norm over Fx, Fy, Fz) [N] must stay within :data:`FEATURE_GATE` of the bump [N] (its
    contrast over the smooth breast at the deep level) of every lesion and of every normal
    region the exam treats as a confounder."""
    norm = float(np.linalg.norm(cv_rmse))
    feats = [(f'lesion {g["lesion"]}', g['bump_n']) for g in grading['lesions']]
    feats += [(f'normal {r["name"]}', r['bump_n']) for r in (*grading['nodules'], *grading['ribs'])
              if r['name'] in grading['confounders']]
    return [f'{what}: grouped-CV RMSE {norm:.4f} N (|Fx, Fy, Fz|) is more than 1/3 of its bump '
            f'{abs(b):.4f} N over the smooth breast' for what, b in feats
            if norm > FEATURE_GATE * abs(b)]


def _depth(scene, centre: Sequence[float]) -> float:
    """Depth [m] of a point under the skin along -x."""
    return float(surface_height(np.array(centre[1]), np.array(centre[2]), scene.radii)) - centre[0]


def summary_fields(scene, grading: dict[str, Any] | None) -> dict[str, Any]:
    """What ``cases list`` shows of a case's background: ``background`` ('smooth', or
    'nodular' with the nodule count and, once graded, their bump range in %) and ``ribs``
    (their number)."""
    bg = scene.background
    if bg is None or not bg.nodules:
        text = 'smooth'
    else:
        text = f'nodular {len(bg.nodules)}'
        rng = (grading or {}).get('nodule_bump_pct')
        if rng:
            text += f' ({rng[0]:+.1f}..{rng[1]:+.1f} %)'
    return {'background': text, 'nodules': len(bg.nodules) if bg is not None else 0,
            'nodule_bump_pct': (grading or {}).get('nodule_bump_pct'),
            'ribs': len(bg.ribs) if bg is not None else 0}
