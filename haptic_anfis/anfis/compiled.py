"""The compiled real-time evaluation path (numba, ``cache=True``).

For one query, each input has at most two non-zero MFs (a guarantee of the MF constraints, see
:mod:`.membership`), so only the ≤ 2^d rules that fire are visited — 16 for four inputs, instead of
the 54 or 128 of the whole grid. Same arithmetic and out-of-range policy as the numpy path
(:meth:`SugenoModel.predict`); the two agree to rounding (tested to 1e-12 N).

All parameters of several single-output models are packed into one float array and one int array so
that a call from Python passes few arguments (numba's dispatch cost grows with their number).

Packed layout, for ``n_out`` models over ``d`` inputs:

ints   ``ip``: [n_out, d, then per output o: nmf[o, 0..d), stride[o, 0..d), mf_off[o], coef_off[o]]
floats ``fp``: per output o at the offsets: lo[d], hi[d], elo[d], ehi[d], then the MF triples
               (a, b, c) input by input, and at coef_off[o] the (R, d + 1) consequents row-major.
"""
from __future__ import annotations

import numba
import numpy as np

from .sugeno import SugenoModel


def pack(models: list[SugenoModel]) -> tuple[np.ndarray, np.ndarray]:
    """Pack single-output models sharing the input count into (fp, ip) for the kernels."""
    d = models[0].n_inputs
    if any(m.n_inputs != d for m in models):
        raise ValueError('all packed models need the same number of inputs')
    ints: list[int] = [len(models), d]
    floats: list[np.ndarray] = []
    pos = 0
    for m in models:
        st = m.structure
        strides = [int(np.prod(st[i + 1:])) for i in range(d)]
        span = m.hi - m.lo
        e = m.extrapolation * span
        block = [m.lo, m.hi, m.lo - e, m.hi + e]
        mf_off = pos + 4 * d
        mfs = np.concatenate([P.ravel() for P in m.mfs])
        coef_off = mf_off + mfs.size
        block += [mfs, m.coef.ravel()]
        flat = np.concatenate([np.asarray(b, dtype=np.float64).ravel() for b in block])
        floats.append(flat)
        ints += [*st, *strides, pos, coef_off]
        pos += flat.size
    return np.ascontiguousarray(np.concatenate(floats)), np.asarray(ints, dtype=np.int64)


@numba.njit(cache=True, nogil=True)
def _eval_point(q, fp, ip, out):
    """Evaluate every packed model at one query ``q`` (d,) into ``out`` (n_out,).

    Returns False (and leaves ``out`` untouched) if ``q`` holds NaN or Inf.
    """
    n_out = ip[0]
    d = ip[1]
    for i in range(d):
        if not np.isfinite(q[i]):
            return False
    j0 = np.empty(d, dtype=np.int64)
    mu0 = np.empty(d)
    mu1 = np.empty(d)
    xe = np.empty(d)
    for o in range(n_out):
        h = 2 + o * (2 * d + 2)
        base = ip[h + 2 * d]
        coef_off = ip[h + 2 * d + 1]
        mf = base + 4 * d
        for i in range(d):
            lo = fp[base + i]
            hi = fp[base + d + i]
            xm = min(max(q[i], lo), hi)
            xe[i] = min(max(q[i], fp[base + 2 * d + i]), fp[base + 3 * d + i])
            m = ip[h + i]
            # Interval [b_j, b_j+1] holding xm; only MFs j and j + 1 can be non-zero there.
            j = 0
            while j < m - 2 and fp[mf + 3 * (j + 1) + 1] <= xm:
                j += 1
            g0 = _tri(xm, fp[mf + 3 * j], fp[mf + 3 * j + 1], fp[mf + 3 * j + 2])
            g1 = 0.0
            if m > 1:
                g1 = _tri(xm, fp[mf + 3 * j + 3], fp[mf + 3 * j + 4], fp[mf + 3 * j + 5])
            s = g0 + g1
            j0[i] = j
            mu0[i] = g0 / s
            mu1[i] = g1 / s
            mf += 3 * m
        acc = 0.0
        for combo in range(1 << d):
            w = 1.0
            rule = 0
            for i in range(d):
                if (combo >> i) & 1:
                    w *= mu1[i]
                    rule += (j0[i] + 1) * ip[h + d + i]
                else:
                    w *= mu0[i]
                    rule += j0[i] * ip[h + d + i]
            if w == 0.0:
                continue  # also skips the non-existent second MF of a single-MF input
            c = coef_off + rule * (d + 1)
            f = fp[c + d]
            for i in range(d):
                f += fp[c + i] * xe[i]
            acc += w * f
        out[o] = acc
    return True


@numba.njit(cache=True, nogil=True, inline='always')
def _tri(x, a, b, c):
    if x <= b:
        v = (x - a) / (b - a)
    else:
        v = (c - x) / (c - b)
    return min(max(v, 0.0), 1.0)


@numba.njit(cache=True, nogil=True)
def eval_xyzd(x, y, z, depth, fp, ip):
    """Real-time entry point for the 4-input, 3-output force model.

    Returns:
        (Fx, Fy, Fz, ok): ok is False (forces 0) if an input is NaN or Inf.
    """
    q = np.empty(4)
    q[0] = x
    q[1] = y
    q[2] = z
    q[3] = depth
    out = np.zeros(3)
    ok = _eval_point(q, fp, ip, out)
    return out[0], out[1], out[2], ok


@numba.njit(cache=True, nogil=True)
def eval_batch(X, fp, ip):
    """Compiled batch path: X (n, d) -> (n, n_out); rows with NaN/Inf inputs come out NaN."""
    n = X.shape[0]
    out = np.empty((n, ip[0]))
    row = np.empty(ip[0])
    for k in range(n):
        if _eval_point(X[k], fp, ip, row):
            out[k] = row
        else:
            out[k] = np.nan
    return out


def warm_up(fp: np.ndarray, ip: np.ndarray) -> None:
    """Compile (or load from the cache) every kernel before the real-time loop needs it."""
    eval_xyzd(0.0, 0.0, 0.0, 0.0, fp, ip)
    eval_batch(np.zeros((1, int(ip[1]))), fp, ip)
