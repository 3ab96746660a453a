"""The field's membership-function families for :class:`~haptic_anfis.anfis.estimator.ANFIS`.

Every function here works on one input normalised to the unit domain u in [0, 1] (the estimator
maps each input's training range onto it), so the minimum widths and gaps below mean the same for
any data scale. One input with ``m`` MFs has an (m, k) parameter array, one row per MF:

============== ===== ========================================= =====================================
family          k     row                                        membership
============== ===== ========================================= =====================================
'triangular'    3     (a, b, c): feet a, c, peak b               max(0, min((u-a)/(b-a), (c-u)/(c-b)))
'trapezoidal'   4     (a, b, c, d): feet a, d, shoulders b, c    max(0, min((u-a)/(b-a), 1, (d-u)/(d-c)))
'gbell'         3     (a, b, c): half-width a, slope b, centre c 1 / (1 + |(u-c)/a|^(2b))
'gaussian'      2     (sigma, c): width sigma, centre c          exp(-((u-c)/sigma)^2 / 2)
============== ===== ========================================= =====================================

Every parameter is free (Jang 1993): an MF may widen, narrow and move. :func:`project` keeps them in
the constraint set after each gradient step:

- centres (the peak, the middle of the plateau, c) ordered with a minimum gap of :data:`MIN_GAP` of
  the uniform spacing — the MFs keep their linguistic order — and inside [0, 1] for the
  piecewise-linear families (a peak outside the domain could leave an MF firing nowhere), within
  :data:`CENTRE_MARGIN` of it for the smooth ones: a bell or Gaussian centred past the edge of the
  range is monotone over it, the shape a 2-MF partition needs for a curved trend (Jang's premise
  parameters are unconstrained; the margin only keeps the centre near the data);
- widths at least :data:`MIN_WIDTH` (no zero-width MF, whose derivative would be infinite);
  gbell slopes within [:data:`MIN_SLOPE`, :data:`MAX_SLOPE`] (below 1/2 the bell has a cusp at
  its centre; above, |u|^(2b) overflows);
- for the two piecewise-linear families, coverage: the first MF's left foot below 0, the last one's
  right foot above 1, and neighbours overlapping, so some MF is positive everywhere on [0, 1] (the
  smooth families are positive everywhere by construction).

:func:`normalized` returns memberships normalised over the input's MFs (their sum is 1), computed in
the log domain for the smooth families so that a far-out sample never gives 0 / 0.
"""
from __future__ import annotations

import numpy as np
import scipy.special

from . import membership as tri

#: The supported families and their parameters per MF.
FAMILIES = {'triangular': 3, 'trapezoidal': 4, 'gbell': 3, 'gaussian': 2}
#: Smallest width (feet to peak, half-width, sigma) in units of the input's range.
MIN_WIDTH = 1e-3
#: Smallest gap between neighbouring centres, as a fraction of the uniform spacing.
MIN_GAP = 0.1
#: How far (in units of the input's range) a smooth MF's centre may lie outside [0, 1].
CENTRE_MARGIN = 1.0
#: Slope range of the generalized bell.
MIN_SLOPE, MAX_SLOPE = 0.5, 50.0


def check_family(family: object) -> str:
    """Return ``family`` or raise ``ValueError`` naming the families there are."""
    if not isinstance(family, str) or family not in FAMILIES:
        raise ValueError(f'mf: expected one of {sorted(FAMILIES)}, got {family!r}')
    return family


def n_free(family: str, m: int) -> int:
    """Free (trained) premise parameters of one input with ``m`` MFs: all of every MF's."""
    return FAMILIES[family] * m


def initial(family: str, m: int) -> np.ndarray:
    """The grid partition of [0, 1] into ``m`` MFs (MATLAB ``genfis`` conventions): centres evenly
    spaced from 0 to 1, neighbours crossing at membership 1/2 (gbell, Gaussian) or summing to 1
    (triangular, trapezoidal). One MF covers the whole domain."""
    s = 1.0 / (m - 1) if m > 1 else 1.0                 # spacing of the centres
    c = np.linspace(0.0, 1.0, m) if m > 1 else np.array([0.5])
    if family == 'triangular':
        return np.column_stack([c - s, c, c + s]) if m > 1 else np.array([[-1.0, 0.5, 2.0]])
    if family == 'trapezoidal':
        if m == 1:
            return np.array([[-1.0, 0.0, 1.0, 2.0]])
        return np.column_stack([c - 0.75 * s, c - 0.25 * s, c + 0.25 * s, c + 0.75 * s])
    if family == 'gbell':
        return np.column_stack([np.full(m, s / 2), np.full(m, 2.0), c])
    if family == 'gaussian':
        return np.column_stack([np.full(m, s / (2 * np.sqrt(2 * np.log(2)))), c])
    raise ValueError(f'mf: expected one of {sorted(FAMILIES)}, got {family!r}')


def centre_column(family: str) -> int:
    """Column of the centre (the trapezoid's is the mean of columns 1 and 2)."""
    return {'triangular': 1, 'trapezoidal': 1, 'gbell': 2, 'gaussian': 1}[family]


def centres(family: str, P: np.ndarray) -> np.ndarray:
    if family == 'trapezoidal':
        return 0.5 * (P[:, 1] + P[:, 2])
    return P[:, centre_column(family)]


def _ordered(c: np.ndarray, margin: float = 0.0) -> np.ndarray:
    """Centres clipped to [-margin, 1 + margin] and spaced at least the minimum gap (forward then
    backward pass: each pass only moves a centre toward feasibility, and the backward one leaves
    every gap)."""
    m = len(c)
    c = np.clip(c, -margin, 1.0 + margin)
    if m < 2:
        return c
    gap = MIN_GAP / (m - 1)
    for j in range(1, m):
        c[j] = max(c[j], c[j - 1] + gap)
    c[-1] = min(c[-1], 1.0 + margin)
    for j in range(m - 2, -1, -1):
        c[j] = min(c[j], c[j + 1] - gap)
    return c


def project(family: str, P: np.ndarray) -> np.ndarray:
    """Nearest repair of (m, k) parameters onto the constraint set (see the module docstring).

    Repairs anything finite, including zero-width and reordered MFs; a non-finite array is
    replaced by the grid partition (nothing to repair from).
    """
    P = np.array(P, dtype=np.float64, copy=True)
    m, k = len(P), FAMILIES[family]
    if P.ndim != 2 or P.shape[1] != k or m < 1:
        raise ValueError(f'{family} MF parameters must have shape (m, {k}), got {P.shape}')
    if not np.all(np.isfinite(P)):
        return initial(family, m)
    eps = MIN_WIDTH
    if family == 'gbell':
        P[:, 0] = np.maximum(np.abs(P[:, 0]), eps)
        P[:, 1] = np.clip(P[:, 1], MIN_SLOPE, MAX_SLOPE)
        P[:, 2] = _ordered(P[:, 2], CENTRE_MARGIN)
        return P
    if family == 'gaussian':
        P[:, 0] = np.maximum(np.abs(P[:, 0]), eps)
        P[:, 1] = _ordered(P[:, 1], CENTRE_MARGIN)
        return P
    if family == 'triangular':
        b = _ordered(P[:, 1])
        a = np.minimum(P[:, 0], b - eps)
        c = np.maximum(P[:, 2], b + eps)
        left, right = a, c
        out = np.column_stack([a, b, c])
    else:  # trapezoidal: move each MF rigidly with its centre, then repair its shape
        old = centres(family, P)
        new = _ordered(old.copy())
        P += (new - old)[:, None]
        b = np.minimum(P[:, 1], new)             # shoulders either side of the centre
        c = np.maximum(P[:, 2], new)
        a = np.minimum(P[:, 0], b - eps)
        d = np.maximum(P[:, 3], c + eps)
        left, right = a, d
        out = np.column_stack([a, b, c, d])
    # Coverage: widen (never narrow) a foot where it is needed.
    left[0] = min(left[0], -eps)
    right[-1] = max(right[-1], 1.0 + eps)
    for j in range(m - 1):
        left[j + 1] = min(left[j + 1], right[j] - eps)
    out[:, 0], out[:, -1] = left, right
    return out


def check(family: str, P: np.ndarray) -> None:
    """Raise ``ValueError`` (one line) if normalised parameters ``P`` (m, k) lie outside the
    constraint set :func:`project` keeps (used when a model file is read): finite, widths > 0,
    centres strictly increasing, and for the piecewise-linear families every point of [0, 1]
    under some MF."""
    P = np.asarray(P, dtype=np.float64)
    k = FAMILIES[family]
    if P.ndim != 2 or P.shape[1] != k or len(P) < 1:
        raise ValueError(f'{family} MF parameters must have shape (m, {k}), got {P.shape}')
    if not np.all(np.isfinite(P)):
        raise ValueError('MF parameters hold non-finite numbers')
    if not np.all(np.diff(centres(family, P)) > 0):
        raise ValueError('MF centres must be strictly increasing')
    if family in ('gbell', 'gaussian'):
        if not np.all(P[:, 0] > 0):
            raise ValueError('every MF needs a width > 0')
        if family == 'gbell' and not np.all(P[:, 1] > 0):
            raise ValueError('every generalized bell needs a slope > 0')
        return
    if not np.all(np.diff(P, axis=1) >= 0) or not np.all(P[:, 0] < P[:, 1]) \
            or not np.all(P[:, -2] < P[:, -1]):
        raise ValueError(f'every {family} MF needs ordered corners with non-zero slopes')
    left, right = P[:, 0], P[:, -1]
    if not (left[0] < 0.0 and right[-1] > 1.0 and np.all(left[1:] < right[:-1])
            and np.all(P[:-1, 1] <= P[1:, 1])):
        raise ValueError('the MFs leave part of the input range uncovered (a gap where no rule '
                         'fires)')


def normalized(family: str, u: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Normalised memberships of samples ``u`` (n,) and their parameter derivatives.

    Returns:
        (mubar (n, m) with rows summing to 1, D (n, m, k)) where D[n, j, :] = (∂μ_j/∂P_j) / Σ_l μ_l:
        the derivative of MF j's raw membership divided by the sum, which is what the chain rule
        through the normalisation needs (see :meth:`.estimator.ANFIS`'s gradient). One-sided at the
        kinks of the piecewise-linear families.
    """
    u = np.asarray(u, dtype=np.float64)
    if family == 'triangular':
        mu = tri.membership(u, P)
        s = mu.sum(axis=1, keepdims=True)
        return mu / s, tri.membership_grad(u, P) / s[:, :, None]
    if family == 'trapezoidal':
        mu, g = _trapezoid(u, P)
        s = mu.sum(axis=1, keepdims=True)
        return mu / s, g / s[:, :, None]
    z = u[:, None] - P[None, :, -1]                     # u - c
    if family == 'gaussian':
        sig = P[None, :, 0]
        logmu = -0.5 * (z / sig) ** 2
        dlog = np.stack([z * z / sig ** 3, z / sig ** 2], axis=-1)
    else:
        a, b = P[None, :, 0], P[None, :, 1]
        absz = np.abs(z / a)
        with np.errstate(divide='ignore'):
            L = 2.0 * b * np.log(absz)                  # log |z/a|^(2b); -inf at the centre
        logmu = -np.logaddexp(0.0, L)
        one_minus = scipy.special.expit(L)              # 1 - μ = q / (1 + q)
        safe = absz > 0
        dz = np.where(safe, z, 1.0)
        dlog = np.stack([2.0 * b / a * one_minus,
                         np.where(safe, -2.0 * np.log(np.where(safe, absz, 1.0)) * one_minus, 0.0),
                         np.where(safe, 2.0 * b * one_minus / dz, 0.0)], axis=-1)
    w = np.exp(logmu - logmu.max(axis=1, keepdims=True))
    mubar = w / w.sum(axis=1, keepdims=True)
    return mubar, mubar[:, :, None] * dlog


def _trapezoid(u: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Trapezoid memberships (n, m) and their derivatives w.r.t. (a, b, c, d) (n, m, 4)."""
    x = u[:, None]
    a, b, c, d = (P[None, :, i] for i in range(4))
    up = (x - a) / (b - a)
    down = (d - x) / (d - c)
    mu = np.clip(np.minimum(np.minimum(up, down), 1.0), 0.0, 1.0)
    on_up = (x > a) & (x < b)
    on_down = (x > c) & (x < d)
    g = np.zeros(mu.shape + (4,))
    g[..., 0] = np.where(on_up, (x - b) / (b - a) ** 2, 0.0)
    g[..., 1] = np.where(on_up, -(x - a) / (b - a) ** 2, 0.0)
    g[..., 2] = np.where(on_down, (d - x) / (d - c) ** 2, 0.0)
    g[..., 3] = np.where(on_down, (x - c) / (d - c) ** 2, 0.0)
    return mu, g


def raw(family: str, u: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Raw (unnormalised) memberships (n, m) in [0, 1], for plots and tests."""
    u = np.asarray(u, dtype=np.float64)
    if family == 'triangular':
        return tri.membership(u, P)
    if family == 'trapezoidal':
        return _trapezoid(u, P)[0]
    z = u[:, None] - P[None, :, -1]
    if family == 'gaussian':
        return np.exp(-0.5 * (z / P[None, :, 0]) ** 2)
    return 1.0 / (1.0 + np.abs(z / P[None, :, 0]) ** (2.0 * P[None, :, 1]))
