"""The simulated trainee's lump detector: where do the FORCES say a lump is? (no ROS)

Input: what a trainee feels and knows of its own hand — contact points (n, 3) [m], depths (n,) [m]
and the rendered force magnitudes (n,) [N] (the wrench topic), never the case file. Idea: a
homogeneous breast gives a force map that varies smoothly over the breast and with depth; a stiff
lump adds a local bump (+12 % at 2 mm to +22 % at 16 mm over the default tumour). So fit
log F = smooth(y, z) + g(log depth) by least squares (a quartic in y, z and a quadratic in log
depth), bin the residuals on a ``cell`` grid, and report cells whose mean residual stands out
by at least ``min_rel`` (relative force excess) AND ``k_sigma`` robust standard deviations of all
cells. The fit is repeated without the samples near each found bump, so a bump does not lift its
own baseline; at most ``max_lumps`` are returned.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


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
    return np.c_[np.ones_like(y), y, z, y * y, z * z, y * z, y ** 3, z ** 3, y * y * z, y * z * z,
                 y ** 4, z ** 4, y * y * z * z, y ** 3 * z, y * z ** 3, ld, ld * ld]


def detect_lumps(points: np.ndarray, depths: np.ndarray, forces: np.ndarray, *,
                 min_depth: float = 0.004, max_depth: float = 0.016, cell: float = 0.006,
                 min_samples: int = 5, min_rel: float = 0.06, k_sigma: float = 5.0,
                 exclude: float = 0.020,
                 max_lumps: int = 3) -> list[Detection]:
    """Suspected lumps from force samples; ``points`` (n, 3) contact points [m], ``depths`` (n,)
    [m], ``forces`` (n,) force magnitudes [N]. Only samples ``min_depth`` to ``max_depth`` deep
    count: the lump is felt at medium / deep pressure, and past 16 mm (the deepest FE sample) the
    force model extrapolates and then saturates, so force no longer says anything about the tissue.
    Returns [] when nothing stands out."""
    P = np.asarray(points, float).reshape(-1, 3)
    d = np.asarray(depths, float).reshape(-1)
    F = np.asarray(forces, float).reshape(-1)
    ok = np.isfinite(P).all(axis=1) & np.isfinite(d) & np.isfinite(F) & (d >= min_depth) & (d <= max_depth) \
        & (F > 0)
    y, z, ld, lf = P[ok, 1], P[ok, 2], np.log(d[ok]), np.log(F[ok])
    found: list[Detection] = []
    use = np.ones(len(y), bool)
    while len(found) < max_lumps and use.sum() > 40:
        A = _design(y, z, ld)
        coef, *_ = np.linalg.lstsq(A[use], lf[use], rcond=None)
        res = lf - A @ coef
        key = np.c_[np.floor(y / cell), np.floor(z / cell)].astype(np.int64)
        cells, inv, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
        inv = inv.reshape(-1)
        mean = np.bincount(inv, res) / counts
        good = counts >= min_samples
        if good.sum() < 10:
            break
        m = mean[good]
        sig = 1.4826 * np.median(np.abs(m - np.median(m)))
        # candidate cells not already taken by a found lump
        cand = good & use[np.argsort(inv)][np.searchsorted(np.sort(inv), np.arange(len(cells)))]
        score = np.where(cand, mean, -np.inf)
        i = int(np.argmax(score))
        excess = float(np.expm1(mean[i]))
        if not (np.isfinite(score[i]) and mean[i] >= np.log1p(min_rel)
                and mean[i] >= k_sigma * max(sig, 1e-6)):
            break
        sel = inv == i
        yc, zc = float(y[sel].mean()), float(z[sel].mean())
        # centre of mass of the excess around the peak cell (sharper than one cell)
        near = (np.hypot(y - yc, z - zc) <= 1.5 * cell) & (res > 0)
        if near.sum() >= min_samples:
            w = res[near]
            yc, zc = float((y[near] * w).sum() / w.sum()), float((z[near] * w).sum() / w.sum())
        found.append(Detection(yc, zc, excess, float(mean[i] / max(sig, 1e-6)), int(sel.sum())))
        use &= np.hypot(y - yc, z - zc) > exclude
    return found
