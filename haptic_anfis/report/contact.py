"""The contact-onset check: what a force model gives as the probe touches the skin and presses in.

At every surface point of the dataset, with the contact point on the undeformed surface:
- |F| at depth 0 (a non-zero value is a force step, a "click", the instant contact begins);
- |F| / ε at depth ε = 0.1 mm (a bounded ratio means the force grows continuously from 0);
- the force's component along the surface's outward normal, over depths from 0 to 1.25 × the
  deepest sample: a negative value pulls the probe into the tissue.
Pure numpy; the model only needs ``predict(X (n, 4)) -> (n, 3)``.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ..tissue.dataset import ForceDataset

ONSET_EPS_M = 1e-4


def outward_normals(ds: ForceDataset, xyz: np.ndarray) -> np.ndarray:
    """Unit outward normals (n, 3) at surface points ``xyz`` (n, 3) [m].

    The semi-ellipsoid of the dataset's scene (provenance ``scene_si.radii``, centred on the origin,
    +x out of the body) when known; otherwise +x, the indentation axis of the FE sweep.
    """
    radii = (ds.provenance.get('scene_si') or {}).get('radii')
    if radii is None or len(radii) != 3:
        n = np.zeros_like(xyz)
        n[:, 0] = 1.0
        return n
    n = xyz / np.asarray(radii, dtype=np.float64) ** 2
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def contact_onset(model: Any, ds: ForceDataset, eps: float = ONSET_EPS_M,
                  n_depths: int = 41) -> dict[str, Any]:
    """Measure the onset of contact over the dataset's surface points (see the module docstring).

    Returns:
        {'max_force_at_zero_N', 'worst_point_at_zero' (x, y, z), 'force_at_zero_N' (3,) there,
         'max_slope_at_eps_N_per_m', 'min_normal_force_N', 'n_points_pulling', 'n_points', 'eps_m',
         'depth_max_m'}.
    """
    _, first = np.unique(ds.point, return_index=True)
    xyz = ds.X[first, :3]
    P = len(xyz)
    zero = np.column_stack([xyz, np.zeros(P)])
    F0 = np.asarray(model.predict(zero))
    mag0 = np.linalg.norm(F0, axis=1)
    k = int(np.argmax(mag0))
    Fe = np.asarray(model.predict(np.column_stack([xyz, np.full(P, eps)])))
    d_max = 1.25 * float(ds.X[:, 3].max())
    depths = np.linspace(0.0, d_max, n_depths)
    Q = np.column_stack([np.repeat(xyz, n_depths, axis=0), np.tile(depths, P)])
    Fn = np.einsum('ij,ij->i', np.asarray(model.predict(Q)), np.repeat(outward_normals(ds, xyz),
                                                                       n_depths, axis=0))
    Fn = Fn.reshape(P, n_depths)
    return {'max_force_at_zero_N': float(mag0[k]), 'worst_point_at_zero': xyz[k].tolist(),
            'force_at_zero_N': F0[k].tolist(),
            'max_slope_at_eps_N_per_m': float(np.linalg.norm(Fe, axis=1).max() / eps),
            'min_normal_force_N': float(Fn.min()),
            'n_points_pulling': int(np.sum(np.any(Fn < 0.0, axis=1))), 'n_points': P,
            'eps_m': eps, 'depth_max_m': d_max}
