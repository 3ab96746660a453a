"""The shipped training configuration — the one source of truth for the defaults of
:class:`~haptic_anfis.anfis.ForceModel`, ``haptic-anfis train``, the trainer node and
``config/force_model.yaml`` (a test asserts the file equals :data:`SHIPPED`) — and the check that
decides whether the depth-scaled form may drop the x input.

Units: metres (inputs), newtons (forces). No ROS.
"""
from __future__ import annotations

from types import MappingProxyType
from typing import Any

import numpy as np

from .sugeno import DEFAULT_EXTRAPOLATION_SCALED

__all__ = ['FORCE_MODEL_RIDGE', 'LEGACY_RIDGE', 'SHIPPED', 'SHIPPED_INPUTS', 'SHIPPED_STRUCTURE', 'X_CHECK_TOL',
           'X_MFS', 'AUTO', 'x_explained_by_yz']

#: ``inputs`` / ``structure`` value meaning "decided from the data" (the default)
AUTO = 'auto'
#: the ANFIS inputs the shipped structure was chosen for (grouped 5-fold CV over surface points)
SHIPPED_INPUTS = ('y', 'z', 'depth')
#: per-output (Fx, Fy, Fz) MF counts over :data:`SHIPPED_INPUTS` (6-6-2, 6-6-2, 5-5-2)
SHIPPED_STRUCTURE = ((6, 6, 2), (6, 6, 2), (5, 5, 2))
#: the force model's relative ridge per output (Fx, Fy, Fz) of the consequent least squares, which
#: shrinks every rule toward one global linear fit (part of the shipped configuration, chosen by
#: grouped 5-fold CV on the FE data, seed 0: 1e-6 / 3e-6 / 1e-5 from 1e-6 .. 1e-4; with the MFs
#: free to widen, Fz wants more shrinkage than the other two)
FORCE_MODEL_RIDGE = (1e-6, 3e-6, 1e-5)
#: the ridge of model files that do not record theirs (all were trained with it)
LEGACY_RIDGE = 1e-6
#: upper bound of the structure search's MF count on x when x is kept
X_MFS = 3
#: x is "a function of (y, z)" when the leave-one-out RMS error of a smooth (polynomial)
#: regression of x on (y, z) over the distinct loading points is below this fraction of x's
#: spread (std). Measured on the skin of the shipped FE data: 0.2 % with its 149 points, 0.3-0.5 %
#: on 30 of them, 2-8 % on 12-25 (lower degrees fit the dome's rim worse); data whose x varies
#: independently: ~100 %. 20 % separates the two with a wide margin on either side.
X_CHECK_TOL = 0.2

#: ForceModel keyword arguments (and the test split) of the shipped model: config/force_model.yaml
#: holds exactly these. ``inputs='auto'``: (y, z, depth) when the data show x is a function of
#: (y, z) (:func:`x_explained_by_yz`), else (x, y, z, depth) ('plain' form: all four).
#: ``structure='auto'``: :data:`SHIPPED_STRUCTURE` when the inputs are :data:`SHIPPED_INPUTS` and
#: no ``candidates`` are given, else the k-fold structure search.
SHIPPED: MappingProxyType = MappingProxyType({
    'form': 'depth_scaled',
    'inputs': AUTO,
    'structure': AUTO,
    'epochs': (40, 40, 80),   # per output: Fz, with its stronger shrinkage, keeps improving
    'search_epochs': 10,
    'max_mfs': None,          # per input: x 3 (X_MFS), y 5, z 5, depth 3
    'tol': 0.0,
    'ridge': FORCE_MODEL_RIDGE,   # per output (Fx, Fy, Fz)
    'search_folds': 5,
    'val_fraction': 0.0,
    'test_fraction': 0.2,
    'split': 'point',
    'extrapolation': DEFAULT_EXTRAPOLATION_SCALED,   # (0, 0.15, 0.15, 0): the depth-scaled form's
    'seed': 0,
})


def _poly(y: np.ndarray, z: np.ndarray, degree: int) -> np.ndarray:
    """Design matrix of the full polynomial of ``degree`` in (y, z), inputs scaled to [-1, 1]."""
    def unit(v):
        c, s = (v.max() + v.min()) / 2, (v.max() - v.min()) / 2
        return (v - c) / (s if s > 0 else 1.0)
    u, v = unit(y), unit(z)
    return np.column_stack([u ** i * v ** j for i in range(degree + 1)
                            for j in range(degree + 1 - i)])


def x_explained_by_yz(X: np.ndarray, tol: float = X_CHECK_TOL) -> dict[str, Any]:
    """Does x follow from (y, z) in ``X`` (n, 4) = (x, y, z, depth) [m]?

    Over the distinct (x, y, z) loading points, x is regressed on the full polynomial in (y, z)
    of the highest degree <= 4 that has at least twice as many points as terms (quartic from 30
    points, cubic from 20, quadratic from 12) by least squares; the leave-one-out residuals
    (hat-matrix formula, so a regression that merely interpolates few points does not pass) give
    ``rel_rmse`` = RMS / std(x). x is dropped when ``rel_rmse < tol``; with fewer than 12 points
    nothing is shown: x is kept (a constant x carries nothing: dropped).

    Returns:
        {'drop_x': bool, 'rel_rmse': float | None, 'tol', 'n_points', 'reason'} (JSON-able).
    """
    P = np.unique(np.asarray(X, float)[:, :3], axis=0)
    x, y, z = P[:, 0], P[:, 1], P[:, 2]
    degree = next((d for d in (4, 3, 2) if len(P) >= (d + 1) * (d + 2)), None)
    out = {'test': 'leave-one-out polynomial regression of x on (y, z) over the loading points',
           'degree': degree, 'tol': tol, 'n_points': int(len(P)), 'rel_rmse': None}
    spread = float(np.std(x))
    if len(P) and spread <= 1e-12 * max(1.0, float(np.abs(x).max())):
        return {**out, 'drop_x': True, 'reason': 'x is constant: it carries no information'}
    if degree is None:
        return {**out, 'drop_x': False,
                'reason': f'{len(P)} loading points, fewer than 12: cannot show that x follows '
                          'from (y, z); x kept'}
    A = _poly(y, z, degree)
    Q, _ = np.linalg.qr(A)
    h = np.einsum('ij,ij->i', Q, Q)                      # leverages
    e = x - Q @ (Q.T @ x)
    loo = e / np.maximum(1.0 - h, 1e-9)
    rel = float(np.sqrt(np.mean(loo ** 2)) / spread)
    drop = rel < tol
    return {**out, 'drop_x': bool(drop), 'rel_rmse': round(rel, 6),
            'reason': (f'x follows from (y, z) to {100 * rel:.2f} % of its spread (< '
                       f'{100 * tol:.0f} %): x dropped') if drop else
                      (f'x varies independently of (y, z) ({100 * rel:.1f} % of its spread '
                       f'unexplained, >= {100 * tol:.0f} %): x kept')}
