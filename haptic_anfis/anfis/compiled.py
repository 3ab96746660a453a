"""The compiled real-time evaluation path (numba, ``cache=True``): forces and their Jacobian.

The force model is three triangular :class:`~.estimator.ANFIS` estimators (Fx, Fy, Fz). For one
query each input's memberships are computed for all of its MFs and only those that are non-zero
kept, so only the rules that fire are visited: with MFs on the initial pinned partition (feet on the
neighbouring peaks) at most two per input, 8 of 72 rules for 6-6-2; trained MFs may widen, and
then a few more. Same arithmetic and out-of-range policy as the estimators' numpy path
(:meth:`.estimator.ANFIS.predict`); the two agree to rounding (tested to 1e-12 N).

The force model's query is (x, y, z, depth). Its single-output models may read a subset of the
query's columns (``cols``; e.g. (y, z, depth) when x is redundant on the skin), and the output
may be scaled by one query column (``scale_col``, the depth: F = depth · g(inputs), so that the force
is exactly zero at contact and grows continuously from it); ``scale_col = -1`` means no scaling.
The scale factor is max(depth, 0): a negative depth (no contact) gives 0 N, never a pull.

All parameters of several single-output models are packed into one float array and one int array so
that a call from Python passes few arguments (numba's dispatch cost grows with their number).

Packed layout, for ``n_out`` models over ``d`` model inputs read from an ``nq``-column query, at
most ``M`` MFs on any input:

ints   ``ip``: [n_out, d, nq, scale_col, M, cols[0..d), then per output o: nmf[o, 0..d),
               stride[o, 0..d), mf_off[o], coef_off[o]]
floats ``fp``: per output o at the offsets: lo[d], hi[d], elo[d], ehi[d], then the MF triples
               (a, b, c) input by input, and at coef_off[o] the (R, d + 1) consequents row-major,
               all in input units.

Derivatives (:func:`jac_xyzd`, :func:`eval_jac_batch`): exact derivatives of the piecewise-linear
memberships and linear consequents, w.r.t. the query columns. Where an input is clamped (outside
[lo, hi] for the memberships, outside the extrapolation box for the consequents) the clamped part
has zero derivative. At a kink (an MF's foot or peak, a domain edge) the derivative is one-sided:
that of the piece the point lies on (the left piece at a peak).
"""
from __future__ import annotations

from typing import Any

import numba
import numpy as np

#: Index of the first per-output header entry after the global header
#: ``[n_out, d, nq, scale_col, M]``.
_GLOBAL = 5


def pack(estimators: list[Any], cols: tuple[int, ...] | None = None, scale_col: int = -1,
         n_query: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Pack fitted triangular :class:`~.estimator.ANFIS` estimators sharing their inputs into
    (fp, ip) for the kernels.

    Args:
        estimators: the outputs' estimators, all with the same number of inputs d.
        cols: (d,) query column each model input reads (default 0..d-1).
        scale_col: query column that multiplies every output (-1: none).
        n_query: number of query columns (default d).
    """
    d = estimators[0].n_features_in_
    if any(e.n_features_in_ != d for e in estimators):
        raise ValueError('all packed models need the same number of inputs')
    if any(e.mf != 'triangular' for e in estimators):
        raise ValueError('the force model\'s compiled path takes triangular MFs only, got '
                         f'{[e.mf for e in estimators]}')
    cols = tuple(range(d)) if cols is None else tuple(int(c) for c in cols)
    nq = d if n_query is None else int(n_query)
    if len(cols) != d or any(not 0 <= c < nq for c in cols) or not -1 <= scale_col < nq:
        raise ValueError(f'bad input columns {cols} / scale column {scale_col} for {nq} query columns')
    M = max(len(P) for e in estimators for P in e.mf_params_)
    ints: list[int] = [len(estimators), d, nq, int(scale_col), M, *cols]
    floats: list[np.ndarray] = []
    pos = 0
    for e in estimators:
        st = tuple(len(P) for P in e.mf_params_)
        strides = [int(np.prod(st[i + 1:])) for i in range(d)]
        lo, hi = e.input_min_, e.input_max_
        ext = np.broadcast_to(np.asarray(e.extrapolation, dtype=np.float64), (d,)) * (hi - lo)
        block = [lo, hi, lo - ext, hi + ext]
        mf_off = pos + 4 * d
        mfs = np.concatenate([P.ravel() for P in e.mf_params_])
        coef_off = mf_off + mfs.size
        block += [mfs, e.consequents_.ravel()]
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


@numba.njit(cache=True, nogil=True, inline='always')
def scratch_len(ip):
    """Floats of scratch :func:`_eval_point` needs: per input M (MF index, μ̄, dμ̄/du), the count
    and the odometer's digit, the clamped consequent input, the in-box flag and the gradient."""
    return 3 * ip[1] * ip[4] + 5 * ip[1]


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
    M = ip[4]
    for i in range(nq):
        if not np.isfinite(q[i]):
            return False
    # Scratch ``ws`` (:func:`scratch_len` floats) comes from the caller: one heap allocation per
    # query (or per batch); this runs once per servo tick (README "Measured").
    act = ws[:d * M]              # per input: indices of its non-zero MFs (as floats)
    mub = ws[d * M:2 * d * M]     # their normalised memberships μ̄
    dmub = ws[2 * d * M:3 * d * M]  # d μ̄ / d u_i; 0 where the membership input is clamped
    r0 = 3 * d * M
    cnt = ws[r0:r0 + d]
    xe = ws[r0 + d:r0 + 2 * d]
    inb = ws[r0 + 2 * d:r0 + 3 * d]  # 1 where the consequent input is inside its box, else 0
    grad = ws[r0 + 3 * d:r0 + 4 * d]
    digit = ws[r0 + 4 * d:r0 + 5 * d]  # the rule being visited: one active MF per input
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
        total = 1
        for i in range(d):
            u = q[ip[_GLOBAL + i]]
            lo = fp[base + i]
            hi = fp[base + d + i]
            xm = min(max(u, lo), hi)
            elo = fp[base + 2 * d + i]
            ehi = fp[base + 3 * d + i]
            xe[i] = min(max(u, elo), ehi)
            inb[i] = 1.0 if elo < u < ehi else 0.0
            slope = want_jac and lo < u < hi
            m = ip[h + i]
            k = 0
            S = 0.0
            dS = 0.0
            for j in range(m):
                a = fp[mf + 3 * j]
                c = fp[mf + 3 * j + 2]
                if xm <= a or xm >= c:   # outside the support: μ = 0 (and no rule to visit)
                    continue
                b = fp[mf + 3 * j + 1]
                g = _tri(xm, a, b, c)
                if g > 0.0:
                    dg = _dtri(xm, a, b, c) if slope else 0.0
                    act[i * M + k] = j
                    mub[i * M + k] = g
                    dmub[i * M + k] = dg
                    S += g
                    dS += dg
                    k += 1
            isg = 1.0 / S
            for t in range(k):
                g = mub[i * M + t]
                dmub[i * M + t] = (dmub[i * M + t] * S - g * dS) * isg * isg
                mub[i * M + t] = g * isg
            cnt[i] = k
            total *= k
            mf += 3 * m
        acc = 0.0
        for i in range(d):
            grad[i] = 0.0
            digit[i] = 0.0
        for _ in range(total):
            w = 1.0
            rule = 0
            for i in range(d):
                t = i * M + int(digit[i])
                w *= mub[t]
                rule += int(act[t]) * ip[h + d + i]
            c = coef_off + rule * (d + 1)
            f = rule_output(fp, c, d, xe)
            acc += w * f
            if want_jac:
                for i in range(d):
                    # ∂w/∂u_i: the product with input i's factor replaced by its derivative.
                    dw = dmub[i * M + int(digit[i])]
                    if dw != 0.0:
                        for k in range(d):
                            if k != i:
                                dw *= mub[k * M + int(digit[k])]
                        grad[i] += dw * f
                    grad[i] += w * fp[c + i] * inb[i]
            for i in range(d):      # next rule: the odometer's first digit turns fastest
                digit[i] += 1.0
                if digit[i] < cnt[i]:
                    break
                digit[i] = 0.0
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
    buf = np.empty(7 + scratch_len(ip))  # query (4), forces (3), scratch: one allocation
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
    ok = _eval_point(q, fp, ip, out, J, True, np.empty(scratch_len(ip)))
    return out, J, ok


@numba.njit(cache=True, nogil=True)
def eval_batch(X, fp, ip):
    """Compiled batch path: X (n, nq) -> (n, n_out); rows with NaN/Inf inputs come out NaN."""
    n = X.shape[0]
    out = np.empty((n, ip[0]))
    row = np.empty(ip[0])
    J = np.empty((0, 0))
    ws = np.empty(scratch_len(ip))
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
    ws = np.empty(scratch_len(ip))
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
