"""Triangular membership functions on a grid partition of one input, with their constraints.

One input with ``m`` MFs has parameters ``P`` of shape (m, 3): row j is the triangle (a_j, b_j, c_j),
feet a_j < c_j and peak b_j. The constraints kept after every gradient step (see :func:`project`):

- peaks ordered with a minimum gap, the outer peaks pinned to the domain edges:
  b_0 = lo < b_1 < ... < b_{m-1} = hi;
- each foot lies between its own peak and the neighbouring peak: b_{j-1} <= a_j <= b_j - eps and
  b_j + eps <= c_j <= b_{j+1};
- neighbours overlap: a_{j+1} <= c_j - eps, so some MF is positive everywhere on [lo, hi].

Together these guarantee that at any point of the domain at most two neighbouring MFs are non-zero
(the compiled path evaluates only those) and that their sum is positive (no input ever fires no
rule). The outer feet a_0 and c_{m-1} lie outside the domain and are never used because inputs are
clamped to [lo, hi] before membership is computed. A single MF (m = 1) is the constant 1.
"""
from __future__ import annotations

import numpy as np

#: Minimum distance between a peak and its own feet, as a fraction of the domain width.
MIN_WIDTH = 1e-3
#: Minimum distance between neighbouring peaks, as a fraction of the uniform spacing.
MIN_PEAK_GAP = 0.1


def grid_partition(lo: float, hi: float, m: int) -> np.ndarray:
    """Uniform triangular partition of [lo, hi] into ``m`` MFs (memberships sum to 1).

    Returns:
        (m, 3) array of (a, b, c) per MF, in the units of ``lo``/``hi``.
    """
    if m < 1:
        raise ValueError(f'number of membership functions must be >= 1, got {m}')
    if not (np.isfinite(lo) and np.isfinite(hi) and hi > lo):
        raise ValueError(f'input domain must be finite with hi > lo, got [{lo}, {hi}]')
    if m == 1:
        w = hi - lo
        return np.array([[lo - w, 0.5 * (lo + hi), hi + w]])
    b = np.linspace(lo, hi, m)
    a = np.concatenate([[lo - (b[1] - lo)], b[:-1]])  # outer feet: same formula as project()
    c = np.concatenate([b[1:], [hi + (hi - b[-2])]])
    return np.column_stack([a, b, c])


def project(P: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Nearest-repair of MF parameters onto the constraint set (see the module docstring).

    Also repairs arbitrary input (reordered, degenerate or coincident parameters), so it can be
    applied after every gradient step and to user-supplied initial parameters.

    Args:
        P: (m, 3) parameters (a, b, c).
        lo, hi: the input's domain.
    Returns:
        A new (m, 3) array that satisfies every constraint.
    """
    P = np.array(P, dtype=np.float64, copy=True)
    m = len(P)
    if P.shape != (m, 3) or m < 1:
        raise ValueError(f'MF parameters must have shape (m, 3) with m >= 1, got {P.shape}')
    if m == 1 or not np.all(np.isfinite(P)):
        return grid_partition(lo, hi, m)  # nothing to train (m = 1) or nothing to repair from
    width = hi - lo
    eps = MIN_WIDTH * width
    gap = MIN_PEAK_GAP * width / (m - 1)
    b = np.sort(P[:, 1])  # a step that swapped two peaks swaps them back
    b[0], b[-1] = lo, hi
    for j in range(1, m - 1):  # forward then backward pass keeps the minimum gap to both sides
        b[j] = max(b[j], b[j - 1] + gap)
    for j in range(m - 2, 0, -1):
        b[j] = min(b[j], b[j + 1] - gap)
    a = P[:, 0].copy()
    c = P[:, 2].copy()
    a[1:] = np.clip(a[1:], b[:-1], b[1:] - eps)
    c[:-1] = np.clip(c[:-1], b[:-1] + eps, b[1:])
    # Neighbours must overlap by eps; if not, meet in the middle (stays within both clip ranges
    # because the peaks are at least gap >= 2 eps apart).
    for j in range(m - 1):
        if a[j + 1] > c[j] - eps:
            mid = 0.5 * (a[j + 1] + c[j])
            a[j + 1] = mid - 0.5 * eps
            c[j] = mid + 0.5 * eps
    a[0] = lo - (b[1] - lo)
    c[-1] = hi + (hi - b[-2])
    return np.column_stack([a, b, c])


def check(P: np.ndarray, lo: float, hi: float, name: str = 'input') -> None:
    """Raise ``ValueError`` if ``P`` violates the constraints (used when loading a model)."""
    P = np.asarray(P, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3 or len(P) < 1:
        raise ValueError(f'{name}: MF parameters must have shape (m, 3), got {P.shape}')
    if not np.all(np.isfinite(P)):
        raise ValueError(f'{name}: MF parameters hold non-finite numbers')
    a, b, c = P.T
    if not (np.all(a < b) and np.all(b < c)):
        raise ValueError(f'{name}: every triangle needs a < b < c')
    if len(P) == 1:
        if not (a[0] <= lo and c[0] >= hi):
            raise ValueError(f'{name}: a single MF must cover the domain [{lo}, {hi}]')
        return
    tol = 1e-12 * max(1.0, abs(lo), abs(hi))
    if abs(b[0] - lo) > tol or abs(b[-1] - hi) > tol:
        raise ValueError(f'{name}: outer MF peaks must sit on the domain edges {lo}, {hi}')
    if not np.all(np.diff(b) > 0):
        raise ValueError(f'{name}: MF peaks must be strictly increasing')
    if not (np.all(a[1:] >= b[:-1] - tol) and np.all(c[:-1] <= b[1:] + tol)):
        raise ValueError(f'{name}: an MF foot reaches past its neighbour\'s peak')
    if not np.all(a[1:] < c[:-1]):
        raise ValueError(f'{name}: neighbouring MFs do not overlap (a gap where no rule fires)')


def membership(x: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Membership grades of samples ``x`` (n,) in each MF of ``P`` (m, 3) -> (n, m), in [0, 1].

    μ = max(0, min((x - a)/(b - a), (c - x)/(c - b))), equal to 1 at the peak.
    """
    x = np.asarray(x, dtype=np.float64)[:, None]
    a, b, c = P[:, 0], P[:, 1], P[:, 2]
    left = (x - a) / (b - a)
    right = (c - x) / (c - b)
    return np.clip(np.where(x <= b, left, right), 0.0, 1.0)


def membership_grad(x: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Derivatives of :func:`membership` w.r.t. (a, b, c) -> (n, m, 3).

    One-sided at the kinks (peak and feet): the derivative of the branch the sample lies on,
    zero outside the support.
    """
    x = np.asarray(x, dtype=np.float64)[:, None]
    a, b, c = P[:, 0], P[:, 1], P[:, 2]
    on_left = (x > a) & (x <= b)
    on_right = (x > b) & (x < c)
    dl = (b - a) ** 2
    dr = (c - b) ** 2
    g = np.zeros(x.shape[:1] + P.shape)
    g[..., 0] = np.where(on_left, (x - b) / dl, 0.0)
    g[..., 1] = np.where(on_left, -(x - a) / dl, 0.0) + np.where(on_right, (c - x) / dr, 0.0)
    g[..., 2] = np.where(on_right, (x - b) / dr, 0.0)
    return g
