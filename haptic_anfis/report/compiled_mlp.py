"""An MLP peer whose forward pass is compiled the same way as our ANFIS (numba, packed parameters,
one scalar-argument call per query), so that the report's speed comparison measures the models and
not Python call overhead. Weights come from the scikit-learn MLP the peer trains.

Packed layout ``fp``: mu[4], sd[4], ymu[3], ysd[3], then per layer l: W_l (n_in, n_out) row-major,
b_l (n_out); ``ip``: [n_layers, n_0 = 4, n_1, ..., n_L = 3]. Hidden layers use tanh, the output is
linear (scikit-learn's MLPRegressor with ``activation='tanh'``).
"""
from __future__ import annotations

import numba
import numpy as np


def pack_mlp(coefs: list[np.ndarray], intercepts: list[np.ndarray], mu: np.ndarray, sd: np.ndarray,
             ymu: np.ndarray, ysd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(fp, ip) of a tanh MLP with input standardisation (mu, sd) and output (ymu, ysd)."""
    sizes = [coefs[0].shape[0]] + [W.shape[1] for W in coefs]
    parts = [mu, sd, ymu, ysd]
    for W, b in zip(coefs, intercepts):
        parts += [np.ascontiguousarray(W).ravel(), b]
    fp = np.concatenate([np.asarray(p, dtype=np.float64).ravel() for p in parts])
    return fp, np.asarray([len(coefs), *sizes], dtype=np.int64)


@numba.njit(cache=True, nogil=True)
def _forward(q, fp, ip, out):
    n_layers = ip[0]
    width = 0
    for l in range(n_layers + 1):
        width = max(width, ip[1 + l])
    a = np.empty(width)
    h = np.empty(width)
    for i in range(4):
        a[i] = (q[i] - fp[i]) / fp[4 + i]
    pos = 14
    for l in range(n_layers):
        n_in = ip[1 + l]
        n_out = ip[2 + l]
        W = pos
        b = pos + n_in * n_out
        for j in range(n_out):
            s = fp[b + j]
            for i in range(n_in):
                s += a[i] * fp[W + i * n_out + j]
            h[j] = np.tanh(s) if l < n_layers - 1 else s
        for j in range(n_out):
            a[j] = h[j]
        pos = b + n_out
    for k in range(3):
        out[k] = a[k] * fp[11 + k] + fp[8 + k]


@numba.njit(cache=True, nogil=True)
def mlp_one(x, y, z, depth, fp, ip):
    """One query (metres) -> (Fx, Fy, Fz) [N]."""
    q = np.empty(4)
    q[0] = x
    q[1] = y
    q[2] = z
    q[3] = depth
    out = np.empty(3)
    _forward(q, fp, ip, out)
    return out[0], out[1], out[2]


@numba.njit(cache=True, nogil=True)
def mlp_batch(X, fp, ip):
    """(n, 4) -> (n, 3)."""
    out = np.empty((X.shape[0], 3))
    for k in range(X.shape[0]):
        _forward(X[k], fp, ip, out[k])
    return out
