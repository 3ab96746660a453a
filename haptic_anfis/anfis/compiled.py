"""The compiled real-time evaluation path (numba, ``cache=True``): forces and their Jacobian.

For one query, each input has at most two non-zero MFs (a guarantee of the MF constraints, see
:mod:`.membership`), so only the ≤ 2^d rules that fire are visited — 16 for four inputs, instead of
the 54 or 128 of the whole grid. Same arithmetic and out-of-range policy as the numpy path
(:meth:`SugenoModel.predict`); the two agree to rounding (tested to 1e-12 N).

The force model's query is (x, y, z, depth). Its single-output Sugeno models may read a subset of
the query's columns (``cols``; e.g. (y, z, depth) when x is redundant on the skin), and the output
may be scaled by one query column (``scale_col``, the depth: F = depth · g(inputs), so that the force
is exactly zero at contact and grows continuously from it); ``scale_col = -1`` means no scaling.
The scale factor is max(depth, 0): a negative depth (no contact) gives 0 N, never a pull.

All parameters of several single-output models are packed into one float array and one int array so
that a call from Python passes few arguments (numba's dispatch cost grows with their number).

Packed layout, for ``n_out`` models over ``d`` model inputs read from an ``nq``-column query:

ints   ``ip``: [n_out, d, nq, scale_col, cols[0..d), then per output o: nmf[o, 0..d),
               stride[o, 0..d), mf_off[o], coef_off[o]]
floats ``fp``: per output o at the offsets: lo[d], hi[d], elo[d], ehi[d], then the MF triples
               (a, b, c) input by input, and at coef_off[o] the (R, d + 1) consequents row-major.

Derivatives (:func:`jac_xyzd`, :func:`eval_jac_batch`): exact derivatives of the piecewise-linear
memberships and linear consequents, w.r.t. the query columns. Where an input is clamped (outside
[lo, hi] for the memberships, outside the extrapolation box for the consequents) the clamped part
has zero derivative. At a kink (an MF's foot or peak, a domain edge) the derivative is one-sided:
that of the piece the point's interval search selects.
"""
from __future__ import annotations

from typing import Any

import numba
import numpy as np

from .sugeno import SugenoModel

#: Index of the first per-output header entry after the global header ``[n_out, d, nq, scale_col]``.
_GLOBAL = 4


def pack(models: list[SugenoModel], cols: tuple[int, ...] | None = None, scale_col: int = -1,
         n_query: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Pack single-output models sharing their inputs into (fp, ip) for the kernels.

    Args:
        models: the outputs' models, all with the same number of inputs d.
        cols: (d,) query column each model input reads (default 0..d-1).
        scale_col: query column that multiplies every output (-1: none).
        n_query: number of query columns (default d).
    """
    d = models[0].n_inputs
    if any(m.n_inputs != d for m in models):
        raise ValueError('all packed models need the same number of inputs')
    cols = tuple(range(d)) if cols is None else tuple(int(c) for c in cols)
    nq = d if n_query is None else int(n_query)
    if len(cols) != d or any(not 0 <= c < nq for c in cols) or not -1 <= scale_col < nq:
        raise ValueError(f'bad input columns {cols} / scale column {scale_col} for {nq} query columns')
    ints: list[int] = [len(models), d, nq, int(scale_col), *cols]
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


@numba.njit(cache=True, nogil=True, inline='always')
def _tri(x, a, b, c):
    if x <= b:
        v = (x - a) / (b - a)
    else:
        v = (c - x) / (c - b)
    return min(max(v, 0.0), 1.0)


@numba.njit(cache=True, nogil=True, inline='always')
def _dtri(x, a, b, c):
    """d tri / dx on the piece ``x`` lies on (0 outside the support)."""
    if x <= b:
        if x > a:
            return 1.0 / (b - a)
        return 0.0
    if x < c:
        return -1.0 / (c - b)
    return 0.0


@numba.njit(cache=True, nogil=True, inline='always')
def rule_output(fp, c, d, x):
    """First-order consequent of the rule whose (p_1 .. p_d, q) start at ``fp[c]``: q + Σ p_i x_i."""
    f = fp[c + d]
    for i in range(d):
        f += fp[c + i] * x[i]
    return f


@numba.njit(cache=True, nogil=True)
def _eval_point(q, fp, ip, out, J, want_jac, ws):
    """Evaluate every packed model at one query ``q`` (nq,) into ``out`` (n_out,), and with
    ``want_jac`` the Jacobian ``J`` (n_out, nq) [output unit / query unit].

    Returns False (and leaves ``out``/``J`` untouched) if ``q`` holds NaN or Inf.
    """
    n_out = ip[0]
    d = ip[1]
    nq = ip[2]
    scol = ip[3]
    for i in range(nq):
        if not np.isfinite(q[i]):
            return False
    # Scratch ``ws`` (at least 6 d floats) comes from the caller: one heap allocation per query
    # (or per batch) instead of seven; this runs once per servo tick (README "Measured").
    mu0 = ws[:d]
    mu1 = ws[d:2 * d]
    dmu1 = ws[2 * d:3 * d]  # d μ̄1 / d u_i (μ̄0 = 1 - μ̄1, so d μ̄0 = -d μ̄1); 0 where clamped
    inb = ws[3 * d:4 * d]   # 1 where the consequent input is inside its extrapolation box, else 0
    xe = ws[4 * d:5 * d]
    grad = ws[5 * d:6 * d]
    s = 1.0
    ds = 0.0
    if scol >= 0:
        s = max(q[scol], 0.0)
        ds = 1.0 if q[scol] > 0.0 else 0.0
    for o in range(n_out):
        h = _GLOBAL + d + o * (2 * d + 2)
        base = ip[h + 2 * d]
        coef_off = ip[h + 2 * d + 1]
        mf = base + 4 * d
        rbase = 0  # the rule of the lower MF of every input's interval
        for i in range(d):
            u = q[ip[_GLOBAL + i]]
            lo = fp[base + i]
            hi = fp[base + d + i]
            xm = min(max(u, lo), hi)
            elo = fp[base + 2 * d + i]
            ehi = fp[base + 3 * d + i]
            xe[i] = min(max(u, elo), ehi)
            if want_jac:
                inb[i] = 1.0 if elo < u < ehi else 0.0
            m = ip[h + i]
            # Interval [b_j, b_j+1] holding xm; only MFs j and j + 1 can be non-zero there.
            j = 0
            while j < m - 2 and fp[mf + 3 * (j + 1) + 1] <= xm:
                j += 1
            a0, b0, c0 = fp[mf + 3 * j], fp[mf + 3 * j + 1], fp[mf + 3 * j + 2]
            g0 = _tri(xm, a0, b0, c0)
            g1 = 0.0
            d0 = 0.0
            d1 = 0.0
            if m > 1:
                a1, b1, c1 = fp[mf + 3 * j + 3], fp[mf + 3 * j + 4], fp[mf + 3 * j + 5]
                g1 = _tri(xm, a1, b1, c1)
                if want_jac and lo < u < hi:
                    d0 = _dtri(xm, a0, b0, c0)
                    d1 = _dtri(xm, a1, b1, c1)
            isg = 1.0 / (g0 + g1)
            rbase += j * ip[h + d + i]
            mu0[i] = g0 * isg
            mu1[i] = g1 * isg
            if want_jac:
                dmu1[i] = (d1 * g0 - g1 * d0) * isg * isg
            mf += 3 * m
        acc = 0.0
        for i in range(d):
            grad[i] = 0.0
        for combo in range(1 << d):
            w = 1.0
            rule = rbase
            exists = True
            for i in range(d):
                if (combo >> i) & 1:
                    exists = exists and ip[h + i] > 1  # a single-MF input has no second MF
                    w *= mu1[i]
                    rule += ip[h + d + i]
                else:
                    w *= mu0[i]
            if not exists or (w == 0.0 and not want_jac):
                continue
            c = coef_off + rule * (d + 1)
            f = rule_output(fp, c, d, xe)
            acc += w * f
            if want_jac:
                for i in range(d):
                    # ∂w/∂u_i: the product with input i's factor replaced by its derivative.
                    dw = 1.0
                    for k in range(d):
                        if k == i:
                            dw *= dmu1[k] if (combo >> k) & 1 else -dmu1[k]
                        elif (combo >> k) & 1:
                            dw *= mu1[k]
                        else:
                            dw *= mu0[k]
                    if dw != 0.0:
                        grad[i] += dw * f
                    if w != 0.0:
                        grad[i] += w * fp[c + i] * inb[i]
        out[o] = s * acc
        if want_jac:
            for k in range(nq):
                J[o, k] = 0.0
            for i in range(d):
                J[o, ip[_GLOBAL + i]] += s * grad[i]
            if scol >= 0:
                J[o, scol] += ds * acc
    return True


@numba.njit(cache=True, nogil=True)
def eval_xyzd(x, y, z, depth, fp, ip):
    """Real-time entry point for the 4-column (x, y, z, depth), 3-output force model.

    Returns:
        (Fx, Fy, Fz, ok): ok is False (forces 0) if an input is NaN or Inf.
    """
    buf = np.zeros(7 + 6 * ip[1])  # query (4), forces (3), scratch: one allocation
    q = buf[:4]
    q[0] = x
    q[1] = y
    q[2] = z
    q[3] = depth
    out = buf[4:7]
    J = buf[:0].reshape((0, 0))
    ok = _eval_point(q, fp, ip, out, J, False, buf[7:])
    return out[0], out[1], out[2], ok


@numba.njit(cache=True, nogil=True)
def force_xyzd(x, y, z, depth, fp, ip):
    """:func:`eval_xyzd` for Python's real-time call (``ForceModel.predict_one``): returns
    (Fx, Fy, Fz) and raises ``ValueError`` on a NaN/Inf input instead of returning a flag (one
    tuple fewer to unpack and rebuild per query)."""
    fx, fy, fz, ok = eval_xyzd(x, y, z, depth, fp, ip)
    if not ok:
        raise ValueError('non-finite input')
    return fx, fy, fz


@numba.njit(cache=True, nogil=True)
def jac_xyzd(x, y, z, depth, fp, ip):
    """Real-time forces and Jacobian for one (x, y, z, depth) query [m].

    Returns:
        (F (3,) [N], J (3, 4) [N/m] with J[a, b] = dF_a/dq_b, ok): ok is False (F and J zero) if an
        input is NaN or Inf.
    """
    q = np.empty(4)
    q[0] = x
    q[1] = y
    q[2] = z
    q[3] = depth
    out = np.zeros(3)
    J = np.zeros((3, 4))
    ok = _eval_point(q, fp, ip, out, J, True, np.empty(6 * ip[1]))
    return out, J, ok


@numba.njit(cache=True, nogil=True)
def eval_batch(X, fp, ip):
    """Compiled batch path: X (n, nq) -> (n, n_out); rows with NaN/Inf inputs come out NaN."""
    n = X.shape[0]
    out = np.empty((n, ip[0]))
    row = np.empty(ip[0])
    J = np.empty((0, 0))
    ws = np.empty(6 * ip[1])
    for k in range(n):
        if _eval_point(X[k], fp, ip, row, J, False, ws):
            out[k] = row
        else:
            out[k] = np.nan
    return out


@numba.njit(cache=True, nogil=True)
def eval_jac_batch(X, fp, ip):
    """Compiled batch forces and Jacobians: X (n, nq) -> (F (n, n_out), J (n, n_out, nq));
    rows with NaN/Inf inputs come out NaN."""
    n = X.shape[0]
    F = np.empty((n, ip[0]))
    Jb = np.empty((n, ip[0], X.shape[1]))
    row = np.empty(ip[0])
    J = np.empty((ip[0], X.shape[1]))
    ws = np.empty(6 * ip[1])
    for k in range(n):
        if _eval_point(X[k], fp, ip, row, J, True, ws):
            F[k] = row
            Jb[k] = J
        else:
            F[k] = np.nan
            Jb[k] = np.nan
    return F, Jb


def entry_points(fp: np.ndarray, ip: np.ndarray) -> tuple[Any, Any]:
    """The compiled (force_xyzd, jac_xyzd) for float queries and these packed parameters, called
    without numba's type dispatch (measured: ~0.35 µs of a ~2.3 µs query on the shared 2-core
    machine; README "Measured"). They take the same arguments; non-float queries are converted
    (ints, numpy floats) or raise ``TypeError``, never compile a new specialisation in the servo
    loop as the dispatcher would. Call :func:`warm_up` first."""
    wanted = tuple(numba.typeof(v) for v in (0.0, 0.0, 0.0, 0.0, fp, ip))
    out = []
    for kernel in (force_xyzd, jac_xyzd):
        cres = kernel.overloads.get(wanted)
        if cres is None:  # not compiled for these types (warm_up not called): the dispatcher
            out.append(kernel)
        else:
            out.append(cres.entry_point)
    return out[0], out[1]


def warm_up(fp: np.ndarray, ip: np.ndarray) -> None:
    """Compile (or load from the cache) every kernel before the real-time loop needs it."""
    eval_xyzd(0.0, 0.0, 0.0, 0.0, fp, ip)
    force_xyzd(0.0, 0.0, 0.0, 0.0, fp, ip)
    jac_xyzd(0.0, 0.0, 0.0, 0.0, fp, ip)
    X = np.zeros((1, int(ip[2])))
    eval_batch(X, fp, ip)
    eval_jac_batch(X, fp, ip)
