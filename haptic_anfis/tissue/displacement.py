"""The skin's FE displacement field, stored compactly in the probe's frame, beside the force data.

Every FE load path (``fe.solve_load_path``) yields the displacement of every skin node at every
recorded depth. The display needs the dent around the probe, not thousands of nodes per sample, so
each field is resampled on a polar grid in the **probe frame** and reduced to a few angular
harmonics per radius:

- Probe frame at a loading point c with unit direction d (into the tissue): e1 is +y projected onto
  the plane normal to d (+z if d is along y), e2 = d x e1. A skin point X has axial coordinate
  s = (X - c).d, radius rho = |(X - c) - s d| and angle theta = atan2((X - c).e2, (X - c).e1): the
  skin as seen looking down the probe axis. Displacement components are (axial along d, radial
  along e_rho, tangential along e_theta), so an axisymmetric dent is pure harmonic 0.
- Radii: ``RHO_OVER_A`` times the probe radius a (0 .. 9 a, finest at the probe edge); angles:
  ``N_ANGLES`` evenly spaced; harmonics 0 .. ``HARMONICS`` (real Fourier coefficients
  [a0, a1, b1, a2, b2, ...]). The sampling is linear on the FE skin's triangles (the FE field is
  bilinear on its quads); points off the skin (beyond the clamped rim) are 0.
- Truncation (how much the harmonics lose) is recorded per sample as an RMS over the polar grid
  within 3 a.

File: ``<dataset>.displacement.npz`` beside ``<dataset>.csv`` (``displacement_path``), arrays plus a
JSON ``meta`` whose ``dataset_sha256`` is ``ForceDataset.sha256()`` of the CSV it belongs to (the
forces and the dent come from the same solves). SI units: m.
"""
from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ..errors import HapticAnfisError
from .dataset import load_dataset

GRID_VERSION = 1
#: sample radii over the probe radius: dense across the probe edge, geometric outside.
RHO_OVER_A = np.array([0.0, 0.25, 0.5, 0.75, 0.9, 1.0, 1.05, 1.1, 1.2, 1.3, 1.45, 1.6, 1.8, 2.0,
                       2.25, 2.5, 2.8, 3.2, 3.6, 4.0, 4.5, 5.0, 5.6, 6.3, 7.0, 8.0, 9.0])
N_ANGLES = 32
HARMONICS = 2
COMPONENTS = ('axial', 'radial', 'tangential')
SUFFIX = '.displacement.npz'


class DisplacementDataError(HapticAnfisError, ValueError):
    """A displacement file is missing, malformed, or belongs to another dataset."""


def probe_frame(direction: Sequence[float]) -> np.ndarray:
    """(3, 3) rows (d, e1, e2): the unit probe direction and the in-plane axes (module doc)."""
    d = np.asarray(direction, dtype=float)
    n = np.linalg.norm(d)
    if not np.isfinite(n) or n < 1e-12:
        raise ValueError(f'probe direction must be a finite non-zero vector, got {direction!r}')
    d = d / n
    ref = np.array([0.0, 1.0, 0.0])
    e1 = ref - (ref @ d) * d
    if np.linalg.norm(e1) < 1e-6:
        ref = np.array([0.0, 0.0, 1.0])
        e1 = ref - (ref @ d) * d
    e1 /= np.linalg.norm(e1)
    return np.array([d, e1, np.cross(d, e1)])


def polar_coordinates(points: np.ndarray, centre: Sequence[float], frame: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Axial s, radius rho, angle theta (each (n,)) of points (n, 3) [m] in the probe frame."""
    v = (np.asarray(points, dtype=float) - np.asarray(centre, dtype=float)) @ frame.T
    return v[:, 0], np.hypot(v[:, 1], v[:, 2]), np.arctan2(v[:, 2], v[:, 1])


def polar_basis(theta: np.ndarray, frame: np.ndarray) -> np.ndarray:
    """(n, 3, 3) unit vectors (axial, radial, tangential) [tissue frame] at angles theta (n,)."""
    c, s = np.cos(theta)[:, None], np.sin(theta)[:, None]
    d, e1, e2 = frame
    radial = c * e1 + s * e2
    tangential = -s * e1 + c * e2
    return np.stack([np.broadcast_to(d, radial.shape), radial, tangential], axis=1)


def _locate(tri_xy: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Triangle index (n,) (-1 if none) and barycentric weights (n, 3) of 2-D points q (n, 2) in
    triangles tri_xy (T, 3, 2). Brute force, vectorised: ~10^3 points x 10^3 triangles."""
    a, b, c = tri_xy[:, 0], tri_xy[:, 1], tri_xy[:, 2]
    v0, v1 = b - a, c - a
    det = v0[:, 0] * v1[:, 1] - v0[:, 1] * v1[:, 0]  # (T,)
    w = q[:, None, :] - a[None]  # (n, T, 2)
    l1 = (w[..., 0] * v1[None, :, 1] - w[..., 1] * v1[None, :, 0]) / det
    l2 = (v0[None, :, 0] * w[..., 1] - v0[None, :, 1] * w[..., 0]) / det
    l0 = 1.0 - l1 - l2
    inside = (l0 >= -1e-9) & (l1 >= -1e-9) & (l2 >= -1e-9)
    hit = inside.any(axis=1)
    t = np.where(hit, inside.argmax(axis=1), -1)
    rows = np.arange(len(q))
    bary = np.stack([l0[rows, t], l1[rows, t], l2[rows, t]], axis=1)
    return t, np.where(hit[:, None], bary, 0.0)


def sample_polar(skin_points: np.ndarray, skin_quads: np.ndarray, displacements: np.ndarray,
                 centre: Sequence[float], direction: Sequence[float], rho: np.ndarray,
                 n_angles: int = N_ANGLES) -> np.ndarray:
    """Resample skin displacements on the probe-frame polar grid.

    Args:
        skin_points: (S, 3) undeformed skin nodes [m]; skin_quads: (Q, 4) faces, indices into them.
        displacements: (D, S, 3) node displacements [m] (tissue frame) at D depths.
        centre, direction: loading point (3,) [m] and unit direction into the tissue (3,).
        rho: (K,) sample radii [m].
    Returns:
        (D, K, J, 3) components (axial, radial, tangential) [m] at radius rho[k] and angle
        2 pi j / J; 0 where the grid point is off the skin (beyond the clamped rim).
    """
    frame = probe_frame(direction)
    v = (np.asarray(skin_points, dtype=float) - np.asarray(centre, dtype=float)) @ frame.T
    xy = v[:, 1:]
    quads = np.asarray(skin_quads)
    tris = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    t_xy = xy[tris]
    area = 0.5 * ((t_xy[:, 1, 0] - t_xy[:, 0, 0]) * (t_xy[:, 2, 1] - t_xy[:, 0, 1])
                  - (t_xy[:, 1, 1] - t_xy[:, 0, 1]) * (t_xy[:, 2, 0] - t_xy[:, 0, 0]))
    # Seen down the probe axis the skin facing the probe has one orientation; where the dome
    # turns away (far down its flank) projected triangles flip and would overlap: drop those.
    r_c = np.hypot(*t_xy.mean(axis=1).T)
    front = np.sign(area[r_c <= np.quantile(r_c, 0.05)].sum())  # those nearest the probe axis
    keep = area * front > 0
    tris, t_xy = tris[keep], t_xy[keep]
    theta = 2.0 * np.pi * np.arange(n_angles) / n_angles
    r, th = np.meshgrid(np.asarray(rho, dtype=float), theta, indexing='ij')
    q = np.column_stack([(r * np.cos(th)).ravel(), (r * np.sin(th)).ravel()])
    t, bary = _locate(t_xy, q)
    u = np.asarray(displacements, dtype=float)
    ug = np.einsum('nk,dnkc->dnc', bary, u[:, tris[np.maximum(t, 0)]])  # (D, n, 3) tissue frame
    basis = polar_basis(th.ravel(), frame)  # (n, 3, 3)
    comp = np.einsum('dnc,nmc->dnm', ug, basis)
    comp[:, t < 0] = 0.0
    return comp.reshape(len(u), len(rho), n_angles, 3)


def to_harmonics(samples: np.ndarray, order: int = HARMONICS) -> np.ndarray:
    """Real Fourier coefficients (..., 2 order + 1, C) [a0, a1, b1, ...] of samples (..., J, C)
    taken at the J angles 2 pi j / J."""
    J = samples.shape[-2]
    if J <= 2 * order:
        raise ValueError(f'{J} angles cannot resolve harmonics up to {order}')
    th = 2.0 * np.pi * np.arange(J) / J
    rows = [np.full(J, 1.0 / J)]
    for m in range(1, order + 1):
        rows += [2.0 / J * np.cos(m * th), 2.0 / J * np.sin(m * th)]
    return np.einsum('hj,...jc->...hc', np.array(rows), samples)


def harmonic_basis(theta: np.ndarray, order: int) -> np.ndarray:
    """(n, 2 order + 1) values [1, cos t, sin t, cos 2t, ...] at angles theta (n,)."""
    cols = [np.ones_like(theta)]
    for m in range(1, order + 1):
        cols += [np.cos(m * theta), np.sin(m * theta)]
    return np.stack(cols, axis=-1)


def from_harmonics(coeffs: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Samples (..., n, C) at angles theta (n,) from coefficients (..., 2 M + 1, C)."""
    order = (coeffs.shape[-2] - 1) // 2
    return np.einsum('nh,...hc->...nc', harmonic_basis(np.asarray(theta, dtype=float), order),
                     coeffs)


def profile_record(result: Any, centre: Sequence[float], direction: Sequence[float],
                   probe_radius: float) -> dict[str, Any]:
    """The JSON-able displacement record of one FE load path (``fe.LoadPathResult`` with its mesh):
    harmonics on the polar grid for every recorded depth, and the truncation RMS."""
    mesh = result.mesh
    rho = RHO_OVER_A * probe_radius
    D = len(result.depths)
    if mesh is None or D == 0 or len(mesh.skin) == 0:
        coeffs = np.zeros((D, len(rho), 2 * HARMONICS + 1, 3))
        trunc = np.zeros(D)
    else:
        local = np.full(len(mesh.points), -1, dtype=np.int64)
        local[mesh.skin] = np.arange(len(mesh.skin))
        samples = sample_polar(mesh.points[mesh.skin], local[mesh.skin_quads],
                               result.skin_displacements, centre, direction, rho)
        coeffs = to_harmonics(samples)
        theta = 2.0 * np.pi * np.arange(N_ANGLES) / N_ANGLES
        err = samples - from_harmonics(coeffs, theta)
        inner = RHO_OVER_A <= 3.0
        trunc = np.sqrt((err[:, inner] ** 2).sum(-1).mean(axis=(1, 2)))
    return {'grid_version': GRID_VERSION, 'rho_m': rho.tolist(), 'n_angles': N_ANGLES,
            'harmonics': HARMONICS, 'components': list(COMPONENTS),
            'coeffs_m': np.round(coeffs, 9).tolist(), 'truncation_rms_m': trunc.tolist(),
            'footprint_radius_m': float(getattr(mesh, 'footprint_radius', 0.0) or 0.0)}


def record_is_current(rec: dict[str, Any]) -> bool:
    """Whether a sweep work record carries a displacement profile of this grid version."""
    disp = rec.get('displacement')
    return isinstance(disp, dict) and disp.get('grid_version') == GRID_VERSION


@dataclass
class DisplacementSet:
    """Skin displacement profiles of a sweep, one per (loading point, depth).

    Attributes:
        point: (P,) loading-point ids (as in the force dataset's ``point`` column).
        surface_point: (P, 3) loading points on the undeformed skin [m].
        direction: (P, 3) unit probe directions into the tissue.
        depths: (D,) depths [m]; rho: (K,) sample radii [m].
        coeffs: (P, D, K, 2M + 1, 3) harmonics [m] of the (axial, radial, tangential)
            displacement; NaN where a point failed before that depth.
        truncation_rms: (P, D) RMS [m] of what the harmonics drop within 3 probe radii.
        meta: provenance; ``dataset_sha256`` ties it to its force CSV.
    """

    point: np.ndarray
    surface_point: np.ndarray
    direction: np.ndarray
    depths: np.ndarray
    rho: np.ndarray
    coeffs: np.ndarray
    truncation_rms: np.ndarray
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        P, D, K = len(self.point), len(self.depths), len(self.rho)
        self.coeffs = np.asarray(self.coeffs, dtype=np.float64)
        if self.coeffs.ndim != 5 or self.coeffs.shape[:3] != (P, D, K) \
                or self.coeffs.shape[4] != 3 or self.coeffs.shape[3] % 2 != 1:
            raise DisplacementDataError(
                f'displacement coefficients have shape {self.coeffs.shape}; expected '
                f'({P}, {D}, {K}, 2M+1, 3) for {P} points, {D} depths, {K} radii')
        if self.surface_point.shape != (P, 3) or self.direction.shape != (P, 3):
            raise DisplacementDataError('surface_point and direction must be (P, 3)')

    @property
    def harmonics(self) -> int:
        return (self.coeffs.shape[3] - 1) // 2

    @property
    def probe_radius(self) -> float:
        return float(self.meta.get('probe_radius_m', self.rho[RHO_OVER_A == 1.0][0]
                                   if len(self.rho) == len(RHO_OVER_A) else np.nan))


def displacements_from_records(records: list[dict[str, Any]], depths: Sequence[float],
                               meta: dict[str, Any]) -> DisplacementSet:
    """Assemble sweep work records (each with a ``displacement`` entry) into a DisplacementSet."""
    recs = sorted((r for r in records if record_is_current(r)), key=lambda r: r['point'])
    if not recs:
        raise DisplacementDataError('no sweep record carries a displacement profile')
    depths = np.asarray(depths, dtype=float)
    first = recs[0]['displacement']
    rho = np.asarray(first['rho_m'])
    H = 2 * first['harmonics'] + 1
    coeffs = np.full((len(recs), len(depths), len(rho), H, 3), np.nan)
    trunc = np.full((len(recs), len(depths)), np.nan)
    dirs = np.zeros((len(recs), 3))
    for i, r in enumerate(recs):
        disp = r['displacement']
        c = np.asarray(disp['coeffs_m'], dtype=float).reshape(-1, len(rho), H, 3)
        for k, d in enumerate(r['depths_m'][:len(c)]):
            j = int(np.argmin(np.abs(depths - d)))
            coeffs[i, j] = c[k]
            trunc[i, j] = disp['truncation_rms_m'][k]
        dirs[i] = r.get('direction', [np.nan] * 3)
    fp = [r['displacement'].get('footprint_radius_m') or np.nan for r in recs]
    meta = {'footprint_radius_m': float(np.nanmedian(fp)) if np.isfinite(fp).any() else None,
            **meta}
    return DisplacementSet(point=np.array([r['point'] for r in recs], dtype=np.int64),
                           surface_point=np.array([r['surface_point_m'] for r in recs]),
                           direction=dirs, depths=depths, rho=rho, coeffs=coeffs,
                           truncation_rms=trunc, meta=dict(meta))


def displacement_path(dataset_csv: str | os.PathLike) -> Path:
    """Where a force dataset's displacement file lives: ``<name>.displacement.npz`` beside it."""
    p = Path(dataset_csv)
    return p.with_name(p.stem + SUFFIX)


def save_displacements(data: DisplacementSet, path: str | os.PathLike) -> Path:
    """Write ``data`` as a compressed npz (float32 coefficients; atomic)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    meta = {'grid_version': GRID_VERSION, 'n_angles': N_ANGLES, 'components': list(COMPONENTS),
            'units': 'm; probe frame (see haptic_anfis.tissue.displacement)',
            'created': time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime()), **data.meta}
    tmp = path.with_name(path.name + '.tmp.npz')
    np.savez_compressed(tmp, point=data.point, surface_point=data.surface_point,
                        direction=data.direction, depths=data.depths, rho=data.rho,
                        coeffs=data.coeffs.astype(np.float32),
                        truncation_rms=data.truncation_rms, meta=np.array(json.dumps(meta)))
    os.replace(tmp, path)
    return path


def load_displacements(path: str | os.PathLike, dataset_sha256: str | None = None
                       ) -> DisplacementSet:
    """Read a displacement file; with ``dataset_sha256``, check it belongs to that force data.

    Raises:
        DisplacementDataError: missing/malformed file, or the hash names another dataset.
    """
    path = Path(path)
    if not path.is_file():
        raise DisplacementDataError(f'displacement file {str(path)!r} does not exist')
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
        meta = json.loads(str(arrays.pop('meta')))
        data = DisplacementSet(**{k: arrays[k] for k in (
            'point', 'surface_point', 'direction', 'depths', 'rho', 'coeffs', 'truncation_rms')},
            meta=meta)
    except DisplacementDataError:
        raise
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise DisplacementDataError(f'displacement file {str(path)!r} is not readable: '
                                    f'{exc}') from None
    if meta.get('grid_version') != GRID_VERSION:
        raise DisplacementDataError(f'displacement file {str(path)!r} has grid version '
                                    f'{meta.get("grid_version")!r}; expected {GRID_VERSION}')
    if dataset_sha256 is not None and meta.get('dataset_sha256') != dataset_sha256:
        raise DisplacementDataError(
            f'displacement file {str(path)!r} belongs to dataset {meta.get("dataset_sha256")!r}, '
            f'not {dataset_sha256!r}; regenerate it with haptic-anfis dataset')
    return data


def ship_beside(new_csv: str | os.PathLike, old_csv: str | os.PathLike,
                rtol: float = 1e-9) -> Path:
    """Key a re-run sweep's displacement file to an existing force CSV whose forces it reproduces.

    A shipped force model is trained on ``old_csv``; re-running the sweep to get the skin
    displacements gives the same forces up to float noise but a different file hash. If every
    sample's inputs are identical and every force agrees within ``rtol`` times the largest force,
    the new displacement file is written beside ``old_csv`` with ``old_csv``'s hash (and the
    measured difference in ``meta``), leaving ``old_csv`` untouched.

    Raises:
        DisplacementDataError: the samples differ, or the forces differ beyond ``rtol``.
    """
    new, old = load_dataset(new_csv), load_dataset(old_csv)
    if len(new) != len(old) or not np.array_equal(new.point, old.point) \
            or not np.array_equal(new.X, old.X):
        raise DisplacementDataError(f'{new_csv} and {old_csv} hold different samples')
    diff = float(np.abs(new.Y - old.Y).max() / np.abs(old.Y).max())
    if diff > rtol:
        raise DisplacementDataError(f'forces differ by {diff:.3g} of the largest force '
                                    f'(> {rtol:g}): ship the new dataset instead')
    data = load_displacements(displacement_path(new_csv), dataset_sha256=new.sha256())
    data.meta.update(dataset_sha256=old.sha256(), forces_max_rel_diff_vs_dataset=diff,
                     solved_as=str(new_csv))
    return save_displacements(data, displacement_path(old_csv))


if __name__ == '__main__':  # python -m haptic_anfis.tissue.displacement NEW.csv OLD.csv
    import sys

    print(ship_beside(sys.argv[1], sys.argv[2]))
