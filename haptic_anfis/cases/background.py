"""Grading a case against its normal background: does a lesion stand out from the nodules?

In a nodular breast every bump is not a lesion. The trainee feels force over a map of the breast;
what tells a lesion apart is that its bump is larger than the normal nodules' bumps at the same
pressing level. From the case's FE points (no extra solves):

- **Force map** at the grading depth (:data:`~.grading.DEEP_DEPTH`): |F| at every loading point.
- **Trend**: the smooth part of that map, a least-squares polynomial of degree
  :data:`TREND_DEGREE` in (y, z) over the loading points (lower for a map of few points:
  :func:`trend_degree`), refitted once without the points whose
  residual exceeds :data:`TREND_CLIP` robust standard deviations (the dome's thickness changes
  slowly across the breast; the bumps are what is left).
- **Bump** of a point: its force over the trend, in % (and in N). The bump of a region (a
  lesion, a nodule, a rib) is the largest among the loading points over it: within its radius
  of its (y, z), or the nearest point when none lies that close (a rib: within its half width of
  its line).
- **Standing out**: a lesion's margin is its bump less the largest normal nodule's bump, in
  percentage points; it stands out when the margin reaches the threshold (the force JND of
  :mod:`.grading`, or the stylus threshold the caller passes), and its difficulty is that
  margin in multiples of the threshold (:func:`~.grading.difficulty`). A lesion that does not
  stand out is difficulty 5: as felt through the device it is one more bump among the normal ones.
- **Level** of a nodular case: its hardest lesion's difficulty; without lesions, 1 when no normal
  bump reaches the threshold (a smooth feel), else 2 (bumps the trainee must leave unmarked).

Pure numpy, no ROS.
"""
from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from ..tissue.scenebase import surface_height
from .grading import DEEP_DEPTH, PALPABLE_PCT, difficulty

__all__ = ['TREND_DEGREE', 'TREND_CLIP', 'force_map', 'trend_degree', 'trend_fit',
           'background_grades',
           'background_gate_failures', 'summary_fields']

#: grouped-CV RMSE (vector norm) as a fraction of each graded feature's bump (as for lesions)
FEATURE_GATE = 1.0 / 3.0

TREND_DEGREE = 4
TREND_CLIP = 2.5


def force_map(records: Sequence[dict[str, Any]], depth: float = DEEP_DEPTH
              ) -> tuple[np.ndarray, np.ndarray]:
    """((P, 2) loading points (y, z) [m], (P,) |F| [N] at ``depth`` [m]) of the point records."""
    yz, f = [], []
    for r in records:
        d = np.asarray(r['depths_m'], dtype=float)
        k = np.flatnonzero(np.abs(d - depth) < 1e-9)
        if not len(k):
            raise ValueError(f'no FE force at depth {depth * 1e3:g} mm at point '
                             f'{r["surface_point_m"]}')
        yz.append(r['surface_point_m'][1:])
        f.append(float(np.linalg.norm(np.asarray(r['forces_N'], dtype=float)[k[0]])))
    return np.asarray(yz, dtype=float), np.asarray(f)


def _basis(yz: np.ndarray, scale: float, degree: int) -> np.ndarray:
    u, v = yz[:, 0] / scale, yz[:, 1] / scale
    return np.column_stack([u ** i * v ** j for i in range(degree + 1)
                            for j in range(degree + 1 - i)])


def trend_degree(points: int, degree: int = TREND_DEGREE) -> int:
    """The trend's polynomial degree for a map of ``points`` loading points: at most ``degree``,
    with at least four points per coefficient (a trend with as many terms as points would
    follow the bumps it is meant to separate)."""
    while degree > 0 and (degree + 1) * (degree + 2) // 2 * 4 > points:
        degree -= 1
    return degree


def trend_fit(yz: np.ndarray, f: np.ndarray, degree: int = TREND_DEGREE,
              clip: float = TREND_CLIP) -> np.ndarray:
    """(P,) smooth trend [N] of the force map at its points (see the module docstring;
    the degree is :func:`trend_degree` of the number of points)."""
    degree = trend_degree(len(f), degree)
    scale = float(np.abs(yz).max()) or 1.0
    A = _basis(yz, scale, degree)
    keep = np.ones(len(f), dtype=bool)
    for _ in range(2):
        coef = np.linalg.lstsq(A[keep], f[keep], rcond=None)[0]
        res = f - A @ coef
        sigma = 1.4826 * np.median(np.abs(res[keep] - np.median(res[keep])))
        if not sigma > 0:
            break
        keep = np.abs(res) <= clip * sigma
    return A @ coef


def _region_bump(yz: np.ndarray, bump: np.ndarray, centre: Sequence[float], radius: float
                 ) -> int:
    """Index of the point with the largest bump within ``radius`` of ``centre`` (y, z), or the
    nearest point when none is that close."""
    d = np.hypot(yz[:, 0] - centre[0], yz[:, 1] - centre[1])
    near = np.flatnonzero(d <= radius + 1e-12)
    return int(near[np.argmax(bump[near])]) if len(near) else int(np.argmin(d))


def background_grades(scene, records: Sequence[dict[str, Any]], depth: float = DEEP_DEPTH,
                      threshold_pct: float = PALPABLE_PCT) -> dict[str, Any]:
    """The case's grading against its background (see the module docstring).

    Returns a dict: ``background`` ('smooth' / 'nodular'), ``nodules`` (per nodule: name, kind,
    bump_pct, bump_n), ``ribs`` (per rib: name, z_m, bump_pct, bump_n), ``nodule_bump_pct``
    ([min, max] or None), ``lesions`` (per lesion: bump_pct, bump_n, margin_pct, stands_out,
    difficulty), ``confounders`` (normal regions whose bump reaches the threshold), ``level``,
    and the ``depth_m`` / ``threshold_pct`` used.
    """
    yz, f = force_map(records, depth)
    trend = trend_fit(yz, f)
    bump_n = f - trend
    bump = 100.0 * bump_n / trend
    bg = scene.background
    out: dict[str, Any] = {'depth_m': depth, 'threshold_pct': threshold_pct,
                           'background': bg.kind if bg is not None else 'smooth',
                           'trend': {'degree': trend_degree(len(f)), 'clip_sigma': TREND_CLIP},
                           'nodules': [], 'ribs': []}
    for n in (bg.nodules if bg is not None else ()):
        k = _region_bump(yz, bump, n.centre[1:], n.radius)
        out['nodules'].append({'name': n.name, 'kind': n.kind, 'radius_m': n.radius,
                               'depth_m': _depth(scene, n.centre), 'bump_pct': float(bump[k]),
                               'bump_n': float(bump_n[k])})
    for rib in (bg.ribs if bg is not None else ()):
        on = np.flatnonzero(np.abs(yz[:, 1] - rib.z) <= rib.radius)
        if len(on):
            k = int(on[np.argmax(bump[on])])
            out['ribs'].append({'name': rib.name, 'z_m': rib.z, 'bump_pct': float(bump[k]),
                                'bump_n': float(bump_n[k])})
    normal = [r['bump_pct'] for r in out['nodules']]
    out['nodule_bump_pct'] = [float(min(normal)), float(max(normal))] if normal else None
    worst_normal = max([*normal, *(r['bump_pct'] for r in out['ribs'])], default=0.0)
    out['confounders'] = [r['name'] for r in (*out['nodules'], *out['ribs'])
                          if r['bump_pct'] >= threshold_pct]
    lesions = []
    for t in scene.tumours:
        k = _region_bump(yz, bump, t.centre[1:], t.radius)
        margin = float(bump[k]) - max(worst_normal, 0.0)
        d = difficulty(margin, threshold_pct)
        lesions.append({'lesion': t.name, 'bump_pct': float(bump[k]), 'bump_n': float(bump_n[k]),
                        'margin_pct': margin, 'stands_out': d is not None,
                        'difficulty': d if d is not None else 5})
    out['lesions'] = lesions
    if lesions:
        out['level'] = int(max(g['difficulty'] for g in lesions))
    else:
        out['level'] = 2 if out['confounders'] else 1
    return out


def background_gate_failures(cv_rmse: np.ndarray, grading: dict[str, Any]) -> list[str]:
    """One message per graded feature whose bump the model cannot render: the grouped-CV RMSE
    (norm over Fx, Fy, Fz) [N] must stay within :data:`FEATURE_GATE` of the bump [N] of every
    lesion and of every normal region the exam treats as a confounder (its bump reaches the
    threshold)."""
    norm = float(np.linalg.norm(cv_rmse))
    feats = [(f'lesion {g["lesion"]}', g['bump_n']) for g in grading['lesions']]
    feats += [(f'normal {r["name"]}', r['bump_n']) for r in (*grading['nodules'], *grading['ribs'])
              if r['name'] in grading['confounders']]
    return [f'{what}: grouped-CV RMSE {norm:.4f} N (|Fx, Fy, Fz|) is more than 1/3 of its bump '
            f'{abs(b):.4f} N over the background trend' for what, b in feats
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
