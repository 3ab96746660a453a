"""A clearly labelled SYNTHETIC force dataset (no finite-element solve behind it).

It stood in for the FE dataset before the tissue/FE pipeline shipped one; now it is a fast,
deterministic fixture for tests. Geometry and sampling follow the paper's set-up; the forces come
from a closed-form approximation, NOT from mechanics we have validated:

- Tissue frame: the chest wall is the plane x = 0 and +x points out of the body (the paper's x axis,
  perpendicular to the body). The breast is the semi-ellipsoid
  (x/Rx)^2 + (y/Ry)^2 + (z/Rz)^2 = 1, x >= 0. The probe indents along -x.
- Axial force: a flat circular punch (radius a) on an incompressible layer of local thickness h,
  F = 2 a E delta / (1 - nu^2) * kappa(a/h) * (1 + s * delta / h): Sneddon's solution with an
  approximate finite-thickness factor kappa = 1 + 1.4 a/h (about the Hayes et al. 1972 value for
  a/h = 0.2) and an ad-hoc strain-stiffening term.
- A stiff inclusion raises the force above it (a Gaussian bump growing with depth).
- Lateral forces follow the surface slope; 0.5 % multiplicative noise (seeded) stands in for FE noise.
"""
from __future__ import annotations

import numpy as np

from .dataset import ForceDataset

#: Depths of the paper's protocol [m].
PAPER_DEPTHS_M = (0.002, 0.005, 0.008, 0.012, 0.016)


def surface_x(y: np.ndarray, z: np.ndarray, radii: tuple[float, float, float]) -> np.ndarray:
    """Height [m] of the semi-ellipsoid surface above the chest wall at (y, z) [m]."""
    rx, ry, rz = radii
    return rx * np.sqrt(np.clip(1.0 - (y / ry) ** 2 - (z / rz) ** 2, 0.0, None))


def make_synthetic_dataset(
    seed: int = 0,
    radii: tuple[float, float, float] = (0.045, 0.070, 0.070),
    spacing: float = 0.008,
    palpable_radius: float = 0.055,
    depths: tuple[float, ...] = PAPER_DEPTHS_M,
    probe_radius: float = 0.008,
    youngs_modulus: float = 20e3,
    tumour_yz: tuple[float, float] = (0.015, -0.010),
    tumour_sigma: float = 0.010,
    tumour_gain: float = 0.20,
    noise: float = 0.005,
    x_range: tuple[float, float] | None = None,
) -> ForceDataset:
    """Build the synthetic dataset (SI units; see the module docstring).

    Surface points lie on a square grid of ``spacing`` in the (y, z) chest plane, inside a disc of
    ``palpable_radius``; every point is indented to every depth in ``depths``. ``x_range`` (lo, hi) [m]: instead of the
    skin height, each point's x (the layer thickness under the probe) is drawn uniformly from it,
    independently of (y, z) — data not sampled on one skin surface (an indenter over slabs).

    Returns:
        ForceDataset with ``X`` (n, 4) = (x, y, z, depth) [m] and ``Y`` (n, 3) = (Fx, Fy, Fz) [N].
    """
    rng = np.random.default_rng(seed)
    half = int(np.floor(palpable_radius / spacing))
    g = np.arange(-half, half + 1) * spacing
    yy, zz = np.meshgrid(g, g, indexing='ij')
    keep = yy ** 2 + zz ** 2 <= palpable_radius ** 2 + 1e-12
    y, z = yy[keep], zz[keep]
    x = surface_x(y, z, radii) if x_range is None else rng.uniform(*x_range, len(y))
    rx, ry, rz = radii
    # Outward surface normal of the ellipsoid (gradient of its implicit function).
    n = np.stack([x / rx ** 2, y / ry ** 2, z / rz ** 2], axis=1)
    n /= np.linalg.norm(n, axis=1, keepdims=True)

    d = np.asarray(depths, dtype=np.float64)
    P, D = len(x), len(d)
    pid = np.repeat(np.arange(P), D)
    xs, ys, zs = (np.repeat(v, D) for v in (x, y, z))
    ns = np.repeat(n, D, axis=0)
    delta = np.tile(d, P)

    nu = 0.5
    h = xs  # layer thickness above the (rigid) chest wall along the indentation axis
    kappa = 1.0 + 1.4 * probe_radius / h
    stiffening = 1.0 + 0.5 * delta / h
    fx = 2.0 * probe_radius * youngs_modulus * delta / (1.0 - nu ** 2) * kappa * stiffening
    dist2 = (ys - tumour_yz[0]) ** 2 + (zs - tumour_yz[1]) ** 2
    fx *= 1.0 + tumour_gain * (delta / max(depths)) * np.exp(-dist2 / (2.0 * tumour_sigma ** 2))
    # The tissue pushes the probe along its normal; the probe is held on its axis, so the lateral
    # reaction is a fraction of the slope's tangent.
    slope = ns[:, 1:] / ns[:, :1]
    lateral = 0.15 * fx[:, None] * slope
    F = np.column_stack([fx, lateral])
    F *= 1.0 + noise * rng.standard_normal(F.shape)
    provenance = {
        'kind': 'SYNTHETIC PLACEHOLDER (closed-form approximation, no FE solve)',
        'generator': 'haptic_anfis.tissue.synthetic.make_synthetic_dataset',
        'seed': seed, 'radii_m': list(radii), 'spacing_m': spacing,
        'palpable_radius_m': palpable_radius, 'depths_m': list(depths),
        'probe_radius_m': probe_radius, 'youngs_modulus_Pa': youngs_modulus,
        'tumour_yz_m': list(tumour_yz), 'n_points': int(P), 'n_samples': int(P * D),
        'x_range_m': None if x_range is None else list(x_range),
    }
    return ForceDataset(X=np.column_stack([xs, ys, zs, delta]), Y=F, point=pid, provenance=provenance)
