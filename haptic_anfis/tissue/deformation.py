"""The tissue's dent for display, from the FE sweep's skin displacements (no ROS).

Given a contact (point on the undeformed skin, unit direction into the tissue, depth),
:meth:`DeformationModel.displace` moves every skin vertex near the probe by the displacement the FE
computed for that load case:

- **Position**: the probe-frame harmonics (``displacement.py``) of the loading points around the
  contact are blended linearly over the Delaunay triangles of the loading points' (y, z) (a contact
  outside the sampled disc takes the nearest point on its hull: positions saturate, as the force
  model's do). Form chosen by measurement against a single universal radial profile and the nearest
  loading point (``holdout_errors``; README *Tissue deformation*).
- **Depth**: displacement / depth is linear between the recorded depths, held constant below the
  first and beyond the last, so the dent is exactly 0 at depth 0 and scales on beyond 16 mm.
- **Footprint**: vertices within the probe radius a of the axis move by exactly depth x direction
  (the flat probe face: no gap, no overlap). The FE's meshed footprint outline sits slightly inside
  a (``edge_offset``); its field over [r_fp, 2 a] is stretched onto [a, 2 a] so the dent is
  continuous at the probe edge.
- **Far field**: beyond ``R_TAPER`` probe radii the displacement fades smoothly to exactly 0 at
  ``R_MAX`` (the sampled extent); vertices on the chest wall (x <= 0) never move.

SI units (m); tissue frame (chest wall x = 0, +x out of the body).
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np
from scipy.spatial import Delaunay

from .dataset import DEFAULT_DATASET, ForceDataset, fold_indices, sidecar_path
from .displacement import (DisplacementDataError, DisplacementSet, displacement_path,
                           harmonic_basis, load_displacements, probe_frame)

R_TAPER = 8.0  # probe radii: start of the fade to zero
R_MAX = 9.0  # probe radii: nothing moves beyond (the extent of the recorded field)
FORMS = ('interpolant', 'nearest', 'radial')


def _smoothstep(t: np.ndarray) -> np.ndarray:
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


@dataclass
class DeformationModel:
    """Skin dent model fitted from a :class:`~haptic_anfis.tissue.displacement.DisplacementSet`.

    Parameters:
        form: 'interpolant' (default; harmonics blended over the loading points), 'nearest'
            (the nearest loading point's field) or 'radial' (one axisymmetric profile per depth,
            averaged over all points) -- the alternatives measured against it.
        taper, reach: the dent fades from ``taper`` to exactly 0 at ``reach`` probe radii
            (defaults R_TAPER, R_MAX: the recorded extent; a display may cut it shorter).
    Learned attributes:
        yz_: (P, 2) loading points' (y, z) [m]; unit_: (P, D, K, H, 3) harmonics / depth on
        the knots rho_ (K,) [m] (footprint, then the recorded radii); depths_: (D,) [m];
        sample_rho_: the recorded radii [m]; probe_radius_: a [m]; footprint_radius_: the FE's
        meshed footprint outline [m]; dataset_sha256_: the force data the field belongs to.
    """

    form: str = 'interpolant'
    taper: float = R_TAPER
    reach: float = R_MAX

    def fit(self, data: DisplacementSet, footprint_radius: float | None = None
            ) -> 'DeformationModel':
        """Learn from ``data`` (points with a failed depth are left out)."""
        if self.form not in FORMS:
            raise ValueError(f'deformation form must be one of {FORMS}, got {self.form!r}')
        if not 1.0 < self.taper < self.reach <= R_MAX:
            raise ValueError(f'need 1 < taper < reach <= {R_MAX} probe radii, got taper '
                             f'{self.taper!r}, reach {self.reach!r}')
        ok = np.all(np.isfinite(data.coeffs), axis=(1, 2, 3, 4))
        if ok.sum() < (1 if self.form != 'interpolant' else 3):
            raise DisplacementDataError(f'only {int(ok.sum())} loading points have a complete '
                                        'displacement field; need at least 3')
        self.depths_ = np.asarray(data.depths, dtype=float)
        if np.any(self.depths_ <= 0) or np.any(np.diff(self.depths_) <= 0):
            raise DisplacementDataError(f'depths must be positive and increasing, '
                                        f'got {self.depths_}')
        self.sample_rho_ = np.asarray(data.rho, dtype=float)
        self.probe_radius_ = float(data.meta.get('probe_radius_m') or data.probe_radius)
        if not np.isfinite(self.probe_radius_) or self.probe_radius_ <= 0:
            raise DisplacementDataError('displacement data names no probe radius')
        a = self.probe_radius_
        self.footprint_radius_ = float(footprint_radius or data.meta.get('footprint_radius_m')
                                       or a)
        self.dataset_sha256_ = data.meta.get('dataset_sha256')
        self.yz_ = np.asarray(data.surface_point, dtype=float)[ok, 1:]
        unit = data.coeffs[ok] / self.depths_[None, :, None, None, None]
        if self.form == 'radial':  # axisymmetric: harmonic 0 only, mean over all points
            mean = unit.mean(axis=0, keepdims=True)
            unit = np.zeros_like(mean)
            unit[:, :, :, 0] = mean[:, :, :, 0]
            self.yz_ = np.zeros((1, 2))
        # Knots: the bonded footprint (exactly the depth along the axis, nothing lateral) out to
        # its meshed outline r_fp, then the recorded radii beyond it: linear between r_fp and
        # the next radius is what the FE's linear element there gives.
        f = self.footprint_radius_
        beyond = self.sample_rho_ > f * (1 + 1e-9)
        self.rho_ = np.concatenate([[0.0, f], self.sample_rho_[beyond]])
        knots = np.zeros(unit.shape[:2] + (len(self.rho_),) + unit.shape[3:])
        knots[:, :, :2, 0, 0] = 1.0
        knots[:, :, 2:] = unit[:, :, beyond]
        self.unit_ = knots
        self._tri = None
        if self.form == 'interpolant':

            self._tri = Delaunay(self.yz_)
        return self

    # -- loading -----------------------------------------------------------------------------

    @classmethod
    def load(cls, path: str | os.PathLike, dataset_sha256: str | None = None,
             **params) -> 'DeformationModel':
        """Model from a displacement file (``<dataset>.displacement.npz``, or the dataset CSV
        beside which it lies); ``dataset_sha256`` checks it belongs to that force data."""
        path = Path(path)
        if path.suffix == '.csv':
            path = displacement_path(path)
        return cls(**params).fit(load_displacements(path, dataset_sha256))

    @classmethod
    def load_default(cls, **params) -> 'DeformationModel':
        """The shipped default scene's model, checked against the shipped force data's hash."""
        sha = json.loads(sidecar_path(DEFAULT_DATASET).read_text()).get('sha256')
        return cls.load(displacement_path(DEFAULT_DATASET), dataset_sha256=sha, **params)

    # -- evaluation --------------------------------------------------------------------------

    def _stretch(self, rho: np.ndarray) -> np.ndarray:
        """Source radius in the FE field for model radius rho: [a, 2a] -> [r_fp, 2a]."""
        a, f = self.probe_radius_, self.footprint_radius_
        t = np.clip((rho - a) / a, 0.0, 1.0)
        return np.where(rho < a, rho * f / a, np.where(rho <= 2 * a, f + t * (2 * a - f), rho))

    def _weights(self, yz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Loading-point ids and blending weights for a contact at (y, z) [m]."""
        if self.form == 'radial':
            return np.array([0]), np.array([1.0])
        if self.form == 'nearest':
            return np.array([int(np.argmin(np.sum((self.yz_ - yz) ** 2, axis=1)))]), np.array([1.0])
        tri = self._tri
        s = int(tri.find_simplex(yz))
        if s < 0:  # outside the sampled disc: saturate onto the nearest hull edge
            yz = self._project_to_hull(yz)
            s = int(tri.find_simplex(yz, tol=1e-9))
            if s < 0:
                return self._weights_nearest(yz)
        T = tri.transform[s]
        b = T[:2] @ (yz - T[2])
        w = np.clip(np.array([b[0], b[1], 1.0 - b.sum()]), 0.0, None)
        return tri.simplices[s], w / w.sum()

    def _weights_nearest(self, yz):
        return np.array([int(np.argmin(np.sum((self.yz_ - yz) ** 2, axis=1)))]), np.array([1.0])

    def _project_to_hull(self, yz: np.ndarray) -> np.ndarray:
        tri = self._tri
        best, best_d = yz, np.inf
        for i, j in tri.convex_hull:
            p, q = self.yz_[i], self.yz_[j]
            t = np.clip(np.dot(yz - p, q - p) / np.dot(q - p, q - p), 0.0, 1.0)
            c = p + t * (q - p)
            d = np.sum((yz - c) ** 2)
            if d < best_d:
                best, best_d = c, d
        return best

    def coefficients(self, contact_point: Sequence[float], depth: float) -> np.ndarray:
        """(K, H, 3) displacement harmonics [m] on ``rho_`` for a contact at ``contact_point``
        (3,) [m] and ``depth`` [m] (clamped to >= 0)."""
        ids, w = self._weights(np.asarray(contact_point, dtype=float)[1:3])
        unit = np.einsum('p,pdkhc->dkhc', w, self.unit_[ids])
        d = max(float(depth), 0.0)
        D = self.depths_
        j = int(np.clip(np.searchsorted(D, d), 1, len(D) - 1)) if len(D) > 1 else 0
        if len(D) == 1 or d <= D[0]:
            u = unit[0]
        elif d >= D[-1]:
            u = unit[-1]
        else:
            t = (d - D[j - 1]) / (D[j] - D[j - 1])
            u = (1 - t) * unit[j - 1] + t * unit[j]
        return u * d

    def displacement(self, points: np.ndarray, contact_point: Sequence[float],
                     direction: Sequence[float], depth: float) -> np.ndarray:
        """(n, 3) displacement [m] (tissue frame) of skin points (n, 3) [m] for one contact."""
        P = np.asarray(points, dtype=float)
        if P.ndim != 2 or P.shape[1] != 3:
            raise ValueError(f'vertices must be an (n, 3) array, got shape {P.shape}')
        c = np.asarray(contact_point, dtype=float)
        if c.shape != (3,) or not np.all(np.isfinite(c)):
            raise ValueError(f'contact_point must be 3 finite numbers, got {contact_point!r}')
        if not np.isfinite(depth):
            raise ValueError(f'depth must be finite, got {depth!r}')
        frame = probe_frame(direction)
        out = np.zeros_like(P)
        d = max(float(depth), 0.0)
        if d == 0.0 or len(P) == 0:
            return out
        a = self.probe_radius_
        rmax = self.reach * a
        # Cheap cull first: only vertices within the sampled radius of the probe axis move.
        v = P - c
        s = v @ frame[0]
        perp = v - s[:, None] * frame[0]
        rho2 = np.einsum('ij,ij->i', perp, perp)
        near = np.flatnonzero((rho2 < rmax * rmax) & (P[:, 0] > 0.0))
        if len(near) == 0:
            return out
        pv = perp[near]
        rho = np.sqrt(rho2[near])
        x1, x2 = pv @ frame[1], pv @ frame[2]
        coeffs = self.coefficients(c, d)  # (K, H, 3)
        K, H, _ = coeffs.shape
        src = self._stretch(rho)
        # linear interpolation in rho of all H x 3 series at once
        k = np.clip(np.searchsorted(self.rho_, src) - 1, 0, K - 2)
        t = np.clip((src - self.rho_[k]) / (self.rho_[k + 1] - self.rho_[k]), 0.0, 1.0)
        prof = coeffs[k] * (1 - t)[:, None, None] + coeffs[k + 1] * t[:, None, None]  # (m,H,3)
        with np.errstate(invalid='ignore', divide='ignore'):
            cos1 = np.where(rho > 0, x1 / rho, 1.0)
            sin1 = np.where(rho > 0, x2 / rho, 0.0)
        cols = [np.ones_like(rho), cos1, sin1]
        cm, sm = cos1, sin1
        for _ in range(2, (H - 1) // 2 + 1):  # cos/sin of m theta by the angle-sum recurrence
            cm, sm = cm * cos1 - sm * sin1, sm * cos1 + cm * sin1
            cols += [cm, sm]
        comp = np.einsum('mh,mhc->mc', np.stack(cols[:H], axis=1), prof)  # (ax, rad, tan)
        radial = cos1[:, None] * frame[1] + sin1[:, None] * frame[2]
        tang = -sin1[:, None] * frame[1] + cos1[:, None] * frame[2]
        u = comp[:, :1] * frame[0] + comp[:, 1:2] * radial + comp[:, 2:3] * tang
        inside = rho <= a
        u[inside] = d * frame[0]  # the flat probe face, exactly
        fade = 1.0 - _smoothstep((rho - self.taper * a) / ((self.reach - self.taper) * a))
        out[near] = u * fade[:, None]
        return out

    def displace(self, vertices: np.ndarray, contact_point: Sequence[float],
                 direction: Sequence[float], depth: float) -> np.ndarray:
        """New vertex positions (n, 3) [m]: ``vertices`` (n, 3) [m, tissue frame] moved by the
        dent of a probe at ``contact_point`` (3,) [m] pressed ``depth`` [m] along the unit
        ``direction`` (into the tissue). Vertices far from the probe come back unchanged."""
        V = np.asarray(vertices, dtype=float)
        return V + self.displacement(V, contact_point, direction, depth)

    def field_samples(self, contact_point: Sequence[float], depth: float,
                      n_angles: int = 32) -> np.ndarray:
        """(K, J, 3) model (axial, radial, tangential) displacement [m] on the recorded polar
        grid (radii ``sample_rho_``, J angles), footprint rule and stretch included: what
        ``holdout_errors`` compares with the FE."""
        coeffs = self.coefficients(contact_point, depth)
        rho = self.sample_rho_
        src = self._stretch(rho)
        K = len(rho)
        prof = np.stack([np.stack([np.interp(src, self.rho_, coeffs[:, h, c])
                                   for c in range(3)], -1) for h in range(coeffs.shape[1])], 1)
        theta = 2 * np.pi * np.arange(n_angles) / n_angles
        vals = np.einsum('jh,khc->kjc', harmonic_basis(theta, (coeffs.shape[1] - 1) // 2), prof)
        inside = rho <= self.probe_radius_
        vals[inside] = 0.0
        vals[inside, :, 0] = max(float(depth), 0.0)
        fade = 1.0 - _smoothstep((rho - self.taper * self.probe_radius_)
                                 / ((self.reach - self.taper) * self.probe_radius_))
        return vals * fade[:, None, None] if K else vals


def fe_samples(data: DisplacementSet, index: int, depth_index: int, n_angles: int = 32
               ) -> np.ndarray:
    """(K, J, 3) the FE field of one (point, depth) on the polar grid, from its harmonics."""
    theta = 2 * np.pi * np.arange(n_angles) / n_angles
    return np.einsum('jh,khc->kjc', harmonic_basis(theta, data.harmonics),
                     data.coeffs[index, depth_index])


def holdout_errors(data: DisplacementSet, form: str = 'interpolant', folds: int = 5,
                   seed: int = 0, hold_depth: int | None = None, **params) -> dict[str, float]:
    """Error of a model form against FE fields it never saw (grouped by loading point).

    Each fold fits on the other points and compares with the held-out points' FE fields on the
    polar grid, area-weighted (rho d rho: as a uniform surface mesh's vertices would weigh), as
    the RMS vector error over depth, per region:
    ``annulus`` a < rho <= 3 a (the visible dent outside the probe: the hard part), ``dent``
    rho <= 3 a (footprint included), ``all`` rho <= R_MAX a. ``hold_depth``: also leave that depth
    index out of the fit (tests the interpolation in depth). Returns the worst and the RMS over
    held-out fields of each ratio, and the footprint's largest deviation from the depth [m].
    """
    ok = np.flatnonzero(np.all(np.isfinite(data.coeffs), axis=(1, 2, 3, 4)))
    stub = ForceDataset(X=np.zeros((len(ok), 4)), Y=np.zeros((len(ok), 3)), point=ok)
    a = data.probe_radius
    rho = data.rho
    edges = np.concatenate([[0.0], 0.5 * (rho[1:] + rho[:-1]), [rho[-1]]])
    area = np.pi * (edges[1:] ** 2 - edges[:-1] ** 2)  # annulus area per radius
    regions = {'annulus': (rho > a) & (rho <= 3 * a + 1e-12), 'dent': rho <= 3 * a + 1e-12,
               'all': rho <= R_MAX * a + 1e-12}
    ratios = {r: [] for r in regions}
    foot = 0.0
    for keep, held in fold_indices(stub, folds, seed):
        sub = _subset(data, ok[keep], drop_depth=hold_depth)
        model = DeformationModel(form=form, **params).fit(sub)
        for i in ok[held]:
            for j, d in enumerate(data.depths):
                if hold_depth is not None and j != hold_depth:
                    continue
                want = fe_samples(data, i, j)
                got = model.field_samples(data.surface_point[i], d)
                e2 = np.sum((got - want) ** 2, axis=2).mean(axis=1)  # (K,) mean over angles
                for r, m in regions.items():
                    ratios[r].append(np.sqrt(np.sum(e2[m] * area[m]) / np.sum(area[m])) / d)
                foot = max(foot, float(np.abs(got[rho <= a, :, 0] - d).max()))
    out = {}
    for r, v in ratios.items():
        v = np.asarray(v)
        out[f'{r}_rms_over_depth'] = float(np.sqrt(np.mean(v ** 2)))
        out[f'{r}_worst_over_depth'] = float(v.max())
    out['footprint_max_dev_m'] = foot
    out['n_fields'] = int(len(ratios['dent']))
    return out


def _subset(data: DisplacementSet, rows: np.ndarray, drop_depth: int | None = None
            ) -> DisplacementSet:
    keep_d = np.array([j for j in range(len(data.depths)) if j != drop_depth])
    return DisplacementSet(point=data.point[rows], surface_point=data.surface_point[rows],
                           direction=data.direction[rows], depths=data.depths[keep_d],
                           rho=data.rho, coeffs=data.coeffs[rows][:, keep_d],
                           truncation_rms=data.truncation_rms[rows][:, keep_d],
                           meta=dict(data.meta))
