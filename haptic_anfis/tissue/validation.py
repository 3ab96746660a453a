"""Analytic references for a rigid flat circular punch, used to validate the FE model.

- Sneddon (1965): punch of radius ``a`` pressed ``delta`` into an elastic half-space,
  F = 2 a E delta / (1 - nu^2).
- Hayes, Keer, Herrmann & Mockros (1972, J. Biomech. 5:541): the same punch on an elastic layer of
  thickness ``h`` bonded to a rigid base, F = kappa(a/h, nu) * Sneddon. ``hayes_kappa`` computes
  kappa by solving the Fredholm integral equation of that problem numerically (Nystrom method),
  rather than interpolating the paper's table, so any a/h and nu can be checked.

SI units: metres, pascals, newtons.
"""
from __future__ import annotations

import numpy as np

from .fe import solve_load_path
from .mesh import Domain, build_mesh


def sneddon_force(a: float, youngs: float, nu: float, delta: float | np.ndarray) -> np.ndarray:
    """Sneddon's flat-punch force [N] on a half-space: radius a [m], E [Pa], depth delta [m]."""
    return 2.0 * a * youngs * np.asarray(delta, dtype=float) / (1.0 - nu ** 2)


def _one_minus_layer_kernel(x: np.ndarray, nu: float) -> np.ndarray:
    """1 - L(x) for a layer bonded to a rigid base; L -> 1 is the half-space (x = xi * h).

    L(x) = (2 eta sinh 2x - 4x) / (2 eta cosh 2x + eta^2 + 1 + 4x^2), eta = 3 - 4 nu; written with
    exp(-2x) factors so that large x does not overflow.
    """
    eta = 3.0 - 4.0 * nu
    e2, e4 = np.exp(-2.0 * x), np.exp(-4.0 * x)
    den = eta * (1.0 + e4) + (eta ** 2 + 1.0 + 4.0 * x ** 2) * e2
    return (2.0 * eta * e4 + (eta ** 2 + 1.0 + 4.0 * x ** 2 + 4.0 * x) * e2) / den


def hayes_kappa(a_over_h: float, nu: float = 0.5, n: int = 32) -> float:
    """Finite-thickness correction kappa = F_layer / F_Sneddon for a flat punch on a bonded layer.

    Solves phi(t) - (1/pi) int_0^1 phi(s) [M(t-s) + M(t+s)] ds = 1 on t in [0, 1] with
    M(y) = lambda int_0^inf (1 - L(x)) cos(lambda x y) dx, lambda = a/h; kappa = int_0^1 phi.
    (kappa -> 1 as a/h -> 0.) Hayes et al. (1972) tabulate the same quantity.
    """
    lam = float(a_over_h)
    if lam <= 0.0:
        return 1.0
    t, w = np.polynomial.legendre.leggauss(n)
    t, w = 0.5 * (t + 1.0), 0.5 * w
    # 1 - L decays like x^2 exp(-2x): x up to 25 is exact to ~1e-19.
    x = np.linspace(0.0, 25.0, 5001)
    g = _one_minus_layer_kernel(x, nu)
    dx = x[1] - x[0]
    wx = np.full_like(x, dx)
    wx[0] = wx[-1] = 0.5 * dx

    def kern(y: np.ndarray) -> np.ndarray:
        return lam * (np.cos(lam * np.multiply.outer(y, x)) @ (g * wx))

    diff = np.subtract.outer(t, t)
    summ = np.add.outer(t, t)
    K = (kern(diff.ravel()) + kern(summ.ravel())).reshape(n, n) / np.pi
    phi = np.linalg.solve(np.eye(n) - K * w[None, :], np.ones(n))
    return float(w @ phi)


def hayes_force(a: float, h: float, youngs: float, nu: float, delta: float | np.ndarray
                ) -> np.ndarray:
    """Flat-punch force [N] on a layer of thickness h [m] bonded to a rigid base (small strain)."""
    return hayes_kappa(a / h, nu) * sneddon_force(a, youngs, nu, delta)


def fe_punch_on_layer(h: float, a: float = 8e-3, youngs: float = 33e3, nu: float = 0.499,
                      depths: tuple[float, ...] = (0.2e-3,), probe_cells: int = 10,
                      radius: float | None = None, max_step: float = 2e-3, refine: int = 1,
                      bonded: bool = True, depth_refine: int | None = None,
                      outer_refine: int | None = None, edge_offset: float = 0.0):
    """FE flat bonded punch (radius a [m]) on a flat layer of thickness h [m], bonded to a rigid
    base, laterally ``radius`` [m] wide (default 5 h) with a free side: the Hayes et al. set-up,
    meshed and solved exactly as the breast is. Returns fe.LoadPathResult (forces in N)."""
    radius = radius or 5.0 * h
    dom = Domain(ry=radius, rz=radius, height=lambda y, z: np.full(np.shape(y), h), fix_rim=False)
    mesh = build_mesh(dom, (0.0, 0.0), a, probe_cells, refine=refine, depth_refine=depth_refine,
                      outer_refine=outer_refine, edge_offset=edge_offset)
    mu = youngs / (2.0 * (1.0 + nu))
    bulk = mu * 2.0 * (1.0 + nu) / (3.0 * (1.0 - 2.0 * nu))
    return solve_load_path(mesh, mu, bulk, (-1.0, 0.0, 0.0), depths, max_step, bonded=bonded)
