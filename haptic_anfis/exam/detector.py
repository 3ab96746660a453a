"""The simulated trainee's lump detector: where do the FORCES say a lump is? (no ROS)

Input: what a trainee feels and knows of its own hand — contact points (n, 3) [m], depths (n,) [m]
and the rendered force magnitudes (n,) [N] (the wrench topic), never the case file. Idea: a
homogeneous breast gives a force map that varies smoothly over the breast and with depth; a stiff
lump adds a local bump (+12 % at 2 mm to +22 % at 16 mm over the default tumour). So fit
log F = smooth(y, z) + g(log depth) (a quartic in y, z and a quadratic in log depth), bin the
residuals on a ``cell`` grid, and report cells whose mean residual stands out by at least
``min_rel`` (relative force excess) AND ``k_sigma`` robust standard deviations of all cells.

The fit is robust (iteratively reweighted least squares with Tukey's biweight on the residuals):
an ordinary least-squares baseline bends towards a lump and hides part of it, and with several lumps it leaves structure that looks like lumps. Cells within ``edge`` of the
searched region's rim are not candidates: there the quartic is least constrained and bends
(the strongest "lumps" of two cases of the library were such rim artefacts). After each of the
strongest bumps, a lump or not, the fit is repeated without the samples within ``exclude`` of it
(``max_lumps`` + 2 bumps examined); at most ``max_lumps`` are returned.

Thresholds (``min_rel`` 9.5 %, ``k_sigma`` 1.0) chosen on a TUNING set of sessions (five cases of
the library, three trainee paths each) and tested on a disjoint TEST set (the other five cases,
three other paths): ``bench/bench_detector.py``, docs/exam_detector.md and
docs/measurements/detector.md (the tuning grid, the margin, sensitivity and false marks per case);
``test/unit/test_detector_protocol.py`` checks them against test/support/data/detector_sessions.npz.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Tukey biweight tuning constant (95 % efficiency at Gaussian residuals)
TUKEY_C = 4.685
#: reweighting passes of the robust fit (converged to < 0.1 % of the bump after 4 on the library)
IRLS_PASSES = 6
#: lengths are scaled by this [m] before the polynomial (a well-conditioned design matrix)
LENGTH_SCALE = 0.04
#: depths are centred on this [m] before the log-depth terms
DEPTH_REF = 0.008
#: strongest bumps examined beyond ``max_lumps`` (each leaves the baseline, lump or not)
CANDIDATES_BEYOND = 2


@dataclass(frozen=True)
class Detection:
    """A suspected lump: surface point (y, z) [m], relative force excess (0.15 = +15 %), its
    significance in robust standard deviations, samples in its cell."""
    y: float
    z: float
    excess: float
    sigma: float
    samples: int


def _design(y, z, ld):
    """(n, 17): quartic in (y, z) [scaled] and quadratic in centred log depth."""
    return np.c_[np.ones_like(y), y, z, y * y, z * z, y * z, y ** 3, z ** 3, y * y * z, y * z * z,
                 y ** 4, z ** 4, y * y * z * z, y ** 3 * z, y * z ** 3, ld, ld * ld]


def _mad_sigma(v: np.ndarray) -> float:
    return float(1.4826 * np.median(np.abs(v - np.median(v)))) if len(v) else 0.0


def robust_fit(A: np.ndarray, b: np.ndarray, use: np.ndarray,
               passes: int = IRLS_PASSES) -> np.ndarray:
    """Residuals ``b - A @ coef`` (n,) of a Tukey-biweight IRLS fit on the rows ``use`` (bool (n,)).

    Rank-deficient designs (samples on a line) are solved by lstsq's minimum-norm solution;
    when every residual is equal (MAD 0) the weights stay those of the previous pass."""
    w = use.astype(float)
    res = b.astype(float).copy()
    for k in range(max(1, passes)):
        sw = np.sqrt(w)
        coef, *_ = np.linalg.lstsq(A * sw[:, None], b * sw, rcond=None)
        res = b - A @ coef
        s = _mad_sigma(res[use])
        if k == passes - 1 or not s > 0:
            break
        u = res / (TUKEY_C * s)
        w = np.where(np.abs(u) < 1.0, (1.0 - u * u) ** 2, 0.0) * use
        if w.sum() < A.shape[1]:  # too few rows kept: stay with this pass's fit
            break
    return res


@dataclass(frozen=True)
class Candidate:
    """One bump the detector examines (in order): centre (y, z) [m], mean log-force residual of
    its peak cell (``excess`` = expm1 of it), that over the robust standard deviation of all cells
    (``sigma``), samples in the cell, and whether its centre lies inside the rim rule."""
    y: float
    z: float
    excess: float
    sigma: float
    samples: int
    inside: bool

    def passes(self, min_rel: float, k_sigma: float) -> bool:
        """A lump under thresholds ``min_rel`` (relative excess) and ``k_sigma``."""
        return self.inside and self.excess >= min_rel and self.sigma >= k_sigma


def detect_lumps(points: np.ndarray, depths: np.ndarray, forces: np.ndarray, *,
                 min_rel: float = 0.095, k_sigma: float = 1.0, max_lumps: int = 3,
                 **kw) -> list[Detection]:
    """Suspected lumps from force samples; ``points`` (n, 3) contact points [m], ``depths`` (n,)
    [m], ``forces`` (n,) force magnitudes [N]: the first ``max_lumps`` of the
    :func:`candidates` that stand out by ``min_rel`` AND ``k_sigma`` (``kw``: the candidates'
    settings). Returns [] when nothing stands out."""
    found = []
    for c in candidates(points, depths, forces, n=max_lumps + CANDIDATES_BEYOND, **kw):
        if c.passes(min_rel, k_sigma):
            found.append(Detection(c.y, c.z, c.excess, c.sigma, c.samples))
            if len(found) >= max_lumps:
                break
    return found


def candidates(points: np.ndarray, depths: np.ndarray, forces: np.ndarray, *,
               min_depth: float = 0.004, max_depth: float = 0.016, cell: float = 0.006,
               min_samples: int = 5, exclude: float = 0.025, edge: float = 0.006,
               n: int = 3 + CANDIDATES_BEYOND):
    """The ``n`` strongest bumps, in the order the detector examines them (a generator; the
    sequence does not depend on the thresholds, so thresholds can be applied afterwards:
    :meth:`Candidate.passes`). Only samples ``min_depth`` to ``max_depth`` deep
    count: the lump is felt at medium / deep pressure, and past 16 mm (the deepest FE sample) the
    force model extrapolates and then saturates, so force no longer says anything about the tissue.
    ``edge`` [m]: cells whose centre lies within this of the searched region's rim (the 99.5th
    percentile of the samples' distance from the (y, z) origin) are not candidates, and a bump
    whose centre of excess lies there is marked not ``inside``."""
    P = np.asarray(points, float).reshape(-1, 3)
    d = np.asarray(depths, float).reshape(-1)
    F = np.asarray(forces, float).reshape(-1)
    m = min(len(P), len(d), len(F))
    P, d, F = P[:m], d[:m], F[:m]
    with np.errstate(invalid='ignore'):
        ok = np.isfinite(P).all(axis=1) & np.isfinite(d) & np.isfinite(F) \
            & (d >= min_depth) & (d <= max_depth) & (F > 0)
    y, z = P[ok, 1], P[ok, 2]
    if len(y) <= 40:
        return
    ld, lf = np.log(d[ok] / DEPTH_REF), np.log(F[ok])
    A = _design(y / LENGTH_SCALE, z / LENGTH_SCALE, ld)
    key = np.c_[np.floor(y / cell), np.floor(z / cell)].astype(np.int64)
    cells, inv, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    inv = inv.reshape(-1)
    good = counts >= min_samples
    if good.sum() < 10:
        return
    rim = float(np.percentile(np.hypot(y, z), 99.5))
    cy = np.bincount(inv, y, minlength=len(cells)) / counts
    cz = np.bincount(inv, z, minlength=len(cells)) / counts
    inside = good & (np.hypot(cy, cz) <= rim - edge)
    use = np.ones(len(y), bool)
    for _ in range(n):
        if use.sum() <= 40:
            break
        res = robust_fit(A, lf, use)
        mean = np.bincount(inv, res, minlength=len(cells)) / counts
        sig = max(_mad_sigma(mean[good]), 1e-6)
        taken = np.bincount(inv, ~use, minlength=len(cells)) > 0  # cells of a found lump
        score = np.where(inside & ~taken, mean, -np.inf)
        i = int(np.argmax(score))
        if not np.isfinite(score[i]):
            break
        sel = inv == i
        yc, zc = float(y[sel].mean()), float(z[sel].mean())
        # centre of mass of the excess around the peak cell (sharper than one cell)
        near = (np.hypot(y - yc, z - zc) <= 1.5 * cell) & (res > 0)
        if near.sum() >= min_samples:
            w = res[near]
            yc, zc = float((y[near] * w).sum() / w.sum()), float((z[near] * w).sum() / w.sum())
        # the rim rule holds for the bump's centre too (a cell just inside can centre outside)
        yield Candidate(yc, zc, float(np.expm1(mean[i])), float(mean[i] / sig), int(sel.sum()),
                        bool(np.hypot(yc, zc) <= rim - edge))
        # found or not, the bump leaves the baseline: a sub-threshold lump still bends the fit
        # and can hide a stronger one elsewhere (two_lesions: 7 % then 10 %)
        use &= np.hypot(y - yc, z - zc) > exclude
