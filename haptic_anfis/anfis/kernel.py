"""Compiled (numba, ``cache=True``) evaluation of an :class:`~.estimator.ANFIS`, every MF family.

The same arithmetic as the numpy path (:meth:`.estimator.ANFIS.predict`; tested to agree to
rounding): normalise the query to the unit cube, memberships at the query clamped to [0, 1] and
normalised per input (in the log domain for the smooth families), consequents at the query clamped
to the extrapolation box, every rule visited (free MFs may overlap more than their neighbours, so
no interval search).

Packed layout: ints ``ip`` = [family code, d, k, m_0 .. m_{d-1}]; floats ``fp`` = [lo (d),
span (d), membership clamp high (d: 1, or 0 for a constant input), consequent clamp low (d),
consequent clamp high (d), the MF rows input by input (m_i × k), the consequents (R × (d + 1))].
"""
from __future__ import annotations

import math

import numba
import numpy as np

from .compiled import rule_output

#: family name -> code in ``ip[0]``
CODES = {'triangular': 0, 'trapezoidal': 1, 'gbell': 2, 'gaussian': 3}


def pack(family: str, premise: list[np.ndarray], theta: np.ndarray, lo: np.ndarray,
         span: np.ndarray, ext: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """(fp, ip) for the kernels from a fitted model's normalised parameters."""
    d = len(premise)
    k = premise[0].shape[1]
    mhi = np.where(ext[1] > 0, 1.0, 0.0)
    fp = np.concatenate([lo, span, mhi, ext[0], ext[1], *[P.ravel() for P in premise],
                         theta.ravel()]).astype(np.float64)
    ip = np.array([CODES[family], d, k, *[len(P) for P in premise]], dtype=np.int64)
    return np.ascontiguousarray(fp), ip


@numba.njit(cache=True, nogil=True)
def _eval(q, fp, ip, ws):
    """One query ``q`` (d,) -> output; NaN if ``q`` holds NaN or Inf. ``ws``: scratch of at least
    Σ m_i + d floats."""
    code = ip[0]
    d = ip[1]
    k = ip[2]
    ue = ws[:d]
    mus = ws[d:]
    off = 5 * d                       # first MF row
    mo = 0                            # first membership of input i in ``mus``
    for i in range(d):
        x = q[i]
        if not math.isfinite(x):
            return np.nan
        u = (x - fp[i]) / fp[d + i]
        um = min(max(u, 0.0), fp[2 * d + i])
        ue[i] = min(max(u, fp[3 * d + i]), fp[4 * d + i])
        m = ip[3 + i]
        top = -np.inf
        for j in range(m):
            p = off + k * j
            if code == 0:             # triangle (a, b, c)
                a, b, c = fp[p], fp[p + 1], fp[p + 2]
                v = (um - a) / (b - a) if um <= b else (c - um) / (c - b)
                mus[mo + j] = min(max(v, 0.0), 1.0)
            elif code == 1:           # trapezoid (a, b, c, e)
                a, b, c, e = fp[p], fp[p + 1], fp[p + 2], fp[p + 3]
                v = min(min((um - a) / (b - a), (e - um) / (e - c)), 1.0)
                mus[mo + j] = max(v, 0.0)
            else:                     # smooth: log memberships first
                if code == 2:         # gbell (a, b, c)
                    z = abs((um - fp[p + 2]) / fp[p])
                    if z > 0.0:
                        L = 2.0 * fp[p + 1] * math.log(z)
                        # -log(1 + e^L) without overflow
                        lm = -(L + math.log1p(math.exp(-L))) if L > 0.0 \
                            else -math.log1p(math.exp(L))
                    else:
                        lm = 0.0
                else:                 # gaussian (sigma, c)
                    z = (um - fp[p + 1]) / fp[p]
                    lm = -0.5 * z * z
                mus[mo + j] = lm
                top = max(top, lm)
        s = 0.0
        if code >= 2:
            for j in range(m):
                mus[mo + j] = math.exp(mus[mo + j] - top)
        for j in range(m):
            s += mus[mo + j]
        for j in range(m):
            mus[mo + j] /= s
        off += k * m
        mo += m
    R = 1
    for i in range(d):
        R *= ip[3 + i]
    acc = 0.0
    for r in range(R):
        idx = r
        w = 1.0
        base = mo                     # walk inputs from the last (fastest) to the first
        for i in range(d - 1, -1, -1):
            m = ip[3 + i]
            base -= m
            w *= mus[base + idx % m]
            idx //= m
        if w == 0.0:
            continue
        acc += w * rule_output(fp, off + r * (d + 1), d, ue)
    return acc


@numba.njit(cache=True, nogil=True)
def eval_one(q, fp, ip):
    """Single query (d,) -> output (NaN on a non-finite input)."""
    n = 0
    for i in range(ip[1]):
        n += ip[3 + i]
    return _eval(q, fp, ip, np.empty(n + ip[1]))


@numba.njit(cache=True, nogil=True)
def eval_batch(X, fp, ip):
    """Batch X (n, d) -> (n,); rows with a non-finite input give NaN."""
    n = 0
    for i in range(ip[1]):
        n += ip[3 + i]
    ws = np.empty(n + ip[1])
    out = np.empty(X.shape[0])
    for r in range(X.shape[0]):
        out[r] = _eval(X[r], fp, ip, ws)
    return out
