"""Jang's hybrid learning for a single-output first-order Sugeno grid on the unit cube.

Works on inputs already normalised to [0, 1] (:class:`~haptic_anfis.anfis.estimator.ANFIS` maps
each input's training range onto it). Each epoch:

1. forward pass: the consequents by least squares with the MFs fixed (one SVD of the design matrix:
   singular values below ``rcond`` times the largest are cut, so a rank-deficient design — a
   constant input, an MF no sample excites, more unknowns than samples — has the minimum-norm
   solution; an optional ridge λ = ridge · s_max² damps the small ones);
2. backward pass: one gradient step on every premise parameter with the consequents fixed, of length
   ``step`` in the normalised parameter space (Jang's η = κ / ‖∂E/∂α‖), projected back onto the MF
   constraints (:func:`.families.project`).

The step size κ follows Jang's (1993) heuristics on the sequence of epoch errors: ×1.1 after four
decreases in a row, ×0.9 after two up-down alternations. On top, a guard: a step whose re-solved
training error is above the current one is rejected and κ halved, so the training error never rises
from one accepted epoch to the next (with a ridge > 0 the least squares alone does not promise
that).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg

from . import families as fam

#: Smallest relative ridge solved by Cholesky of the normal equations (below: SVD): the normal
#: equations' condition number is at most 1 / ridge = 1e6, so the solution keeps ~10 digits.
CHOLESKY_RIDGE = 1e-6
#: Factor on κ after a rejected step.
REJECT_SHRINK = 0.5
LETTERS = 'abcdefghijklmnopqrstuvwxy'


@dataclass
class Fit:
    """Outcome of :func:`hybrid_fit` (normalised units)."""

    premise: list[np.ndarray]
    theta: np.ndarray                      # (R, d + 1) consequents over (u_1 .. u_d, 1)
    train_rmse: list[float] = field(default_factory=list)   # after each epoch (non-increasing)
    check_rmse: list[float] = field(default_factory=list)   # after each epoch, with checking data
    best_epoch: int = 1                                      # 1-based epoch the parameters are from
    steps: list[float] = field(default_factory=list)        # κ used by each epoch's step
    rejected: int = 0                                        # steps the guard refused


def rule_weights(mubar: list[np.ndarray]) -> np.ndarray:
    """Normalised firing strengths w̄ (n, R), rules in C order over the MF indices (the last input
    varies fastest). With a full grid and the product t-norm, Σ_r w_r = Π_i Σ_j μ_ij, so normalising
    per input first is exact and cannot underflow."""
    w = mubar[0]
    for mu in mubar[1:]:
        w = (w[:, :, None] * mu[:, None, :]).reshape(len(w), -1)
    return w


def design(mubar: list[np.ndarray], Ue: np.ndarray) -> np.ndarray:
    """Φ (n, R (d + 1)) with y = Φ @ θ.ravel(): column r (d+1) + k is w̄_r u_k (u_d = 1)."""
    w = rule_weights(mubar)
    u1 = np.column_stack([Ue, np.ones(len(Ue))])
    return (w[:, :, None] * u1[:, None, :]).reshape(len(Ue), -1)


def least_squares(Phi: np.ndarray, t: np.ndarray, ridge: float, rcond: float,
                  toward_linear: int = 0) -> np.ndarray:
    """min ‖Φθ - t‖² + λ‖θ - θ₀‖², λ = ridge · s_max(Φ)².

    θ₀ = 0, or with ``toward_linear`` = d + 1 (the consequent width) every rule's θ₀ is one global
    linear fit (ordinary least squares on the d + 1 columns Σ_r Φ_r, which are [u, 1] because the
    normalised firing strengths sum to 1): a rule the data barely excite then falls back to the
    global linear trend instead of to zero (a grid over a round patch of data leaves its corner
    rules nearly empty, and their partial firing at the rim would pull the output toward 0).

    With ``ridge`` >= :data:`CHOLESKY_RIDGE` the normal equations (ΦᵀΦ + λI) θ = Φᵀt are solved by
    Cholesky: their condition number is at most 1 / ridge, and on a loaded machine it is ~30x
    faster than the SVD (the force model's 745 × 288 design: 0.1 s per SVD single-threaded).
    Otherwise by SVD with singular values below ``rcond · s_max`` cut (minimum norm on a
    rank-deficient Φ)."""
    if toward_linear:
        n, P = Phi.shape
        X1 = Phi.reshape(n, P // toward_linear, toward_linear).sum(axis=1)
        theta_g = np.linalg.lstsq(X1, t, rcond=None)[0]
        return least_squares(Phi, t - X1 @ theta_g, ridge, rcond) + np.tile(theta_g,
                                                                            P // toward_linear)
    if ridge >= CHOLESKY_RIDGE:
        G = Phi.T @ Phi
        lam = ridge * largest_eigenvalue(G)
        if lam > 0.0:
            try:
                return scipy.linalg.cho_solve(
                    scipy.linalg.cho_factor(G + lam * np.eye(len(G)), check_finite=False),
                    Phi.T @ t, check_finite=False)
            except np.linalg.LinAlgError:
                pass   # lost to rounding: the SVD below
    Uv, s, Vt = np.linalg.svd(Phi, full_matrices=False)
    if s.size == 0 or s[0] == 0.0:
        return np.zeros(Phi.shape[1])
    keep = s > rcond * s[0]
    lam = ridge * s[0] ** 2
    inv = np.where(keep, s / np.where(keep, s * s + lam, 1.0), 0.0)
    return Vt.T @ (inv * (Uv.T @ t))


def largest_eigenvalue(G: np.ndarray) -> float:
    """Largest eigenvalue of a symmetric positive semi-definite matrix (s_max² of Φ)."""
    if not len(G):
        return 0.0
    return float(scipy.linalg.eigh(G, eigvals_only=True, subset_by_index=[len(G) - 1, len(G) - 1],
                                   check_finite=False)[0])


def memberships(family: str, premise: list[np.ndarray], Um: np.ndarray
                ) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Per input: normalised memberships (n, m_i) and their scaled derivatives (n, m_i, k)."""
    out = [fam.normalized(family, Um[:, i], P) for i, P in enumerate(premise)]
    return [o[0] for o in out], [o[1] for o in out]


def _solve(family, premise, Um, Ue, t, ridge, rcond, sw, toward_linear):
    """Consequents by weighted least squares (rows scaled by ``sw`` = √weight, or None) and the
    weighted half sum of squares E = ½ Σ v r²."""
    mubar, D = memberships(family, premise, Um)
    Phi = design(mubar, Ue)
    theta = least_squares(Phi if sw is None else Phi * sw[:, None], t if sw is None else t * sw,
                          ridge, rcond, Ue.shape[1] + 1 if toward_linear else 0)
    r = Phi @ theta - t
    rw = r if sw is None else r * sw
    return theta, 0.5 * float(rw @ rw), mubar, D


def weighted_rmse(family: str, premise: list[np.ndarray], theta: np.ndarray, Um: np.ndarray,
                  Ue: np.ndarray, t: np.ndarray, weight: np.ndarray | None) -> float:
    """√(mean(v (y - t)²)) of the model (premise, theta) on normalised data."""
    mubar, _ = memberships(family, premise, Um)
    r = design(mubar, Ue) @ theta.ravel() - t
    return float(np.sqrt(np.mean(r * r if weight is None else weight * r * r)))


def premise_gradient(premise: list[np.ndarray], mubar: list[np.ndarray], D: list[np.ndarray],
                     Ue: np.ndarray, theta: np.ndarray, t: np.ndarray,
                     weight: np.ndarray | None = None) -> list[np.ndarray]:
    """∂E/∂P for E = ½ Σ v (y - t)² (sample weights v, default 1), consequents fixed; per input an
    (m_i, k) array.

    ∂y/∂P_ij = (G_ij - y) D_ij with G_ij = Σ over the rules using MF j of input i of f_r times the
    other inputs' normalised memberships (the chain rule through the normalisation)."""
    n, d = Ue.shape
    shape = tuple(len(P) for P in premise)
    f = (Ue @ theta[:, :-1].T + theta[:, -1]).reshape((n, *shape))
    L = LETTERS[:d]
    w = rule_weights(mubar).reshape(f.shape)
    y = np.einsum(f'z{L},z{L}->z', w, f)
    err = y - t if weight is None else (y - t) * weight
    grads = []
    for i in range(d):
        ops = [f] + [mubar[k] for k in range(d) if k != i]
        subs = [f'z{L}'] + [f'z{L[k]}' for k in range(d) if k != i]
        G = np.einsum(','.join(subs) + f'->z{L[i]}', *ops)
        grads.append(np.einsum('n,nm,nmk->mk', err, G - y[:, None], D[i]))
    return grads


def hybrid_fit(family: str, premise: list[np.ndarray], Um: np.ndarray, Ue: np.ndarray,
               t: np.ndarray, *, epochs: int, step: float, ridge: float, rcond: float,
               weight: np.ndarray | None = None, toward_linear: bool = False,
               check: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None] | None = None
               ) -> Fit:
    """Train ``premise`` (initial MFs, repaired onto the constraints) and the consequents.

    Args:
        Um: (n, d) inputs for the memberships, in [0, 1]; Ue: (n, d) inputs for the consequents.
        t: (n,) targets. epochs: epochs (least-squares solves). step: initial κ.
        weight: (n,) sample weights v > 0 of the squared error (default 1).
        toward_linear: shrink the consequents toward one global linear fit instead of toward
            zero (:func:`least_squares`).
        check: checking data (Um, Ue, t, weight or None): when given, the parameters kept are
            those of the epoch with the lowest weighted checking RMSE (Jang's checking data),
            else the last epoch's (the lowest training error: the guard never lets it rise).
    """
    premise = [fam.project(family, P) for P in premise]
    sw = None if weight is None else np.sqrt(weight)
    theta, E, mubar, D = _solve(family, premise, Um, Ue, t, ridge, rcond, sw, toward_linear)
    fit = Fit(premise=premise, theta=theta)
    n = len(t)
    fit.train_rmse.append(float(np.sqrt(2.0 * E / n)))
    best = np.inf

    def keep_best(epoch: int) -> None:
        nonlocal best
        if check is None:
            return
        v = weighted_rmse(family, premise, theta.reshape(-1, Ue.shape[1] + 1), *check)
        fit.check_rmse.append(v)
        if v < best:
            best, fit.best_epoch = v, epoch
            fit.premise, fit.theta = premise, theta.reshape(-1, Ue.shape[1] + 1)

    keep_best(1)
    tried: list[float] = [E]   # every epoch's error, accepted or not (Jang's heuristics read these)
    grads = None
    for _ in range(epochs - 1):
        if grads is None:
            grads = premise_gradient(premise, mubar, D, Ue, theta.reshape(-1, Ue.shape[1] + 1), t,
                                     weight)
        gnorm = np.sqrt(sum(float((g * g).sum()) for g in grads))
        if gnorm == 0.0 or not np.isfinite(gnorm) or E == 0.0:
            break   # a stationary point (or all inputs single-MF): nothing left to move
        fit.steps.append(step)
        cand = [fam.project(family, P - (step / gnorm) * g) for P, g in zip(premise, grads)]
        c_theta, c_E, c_mubar, c_D = _solve(family, cand, Um, Ue, t, ridge, rcond, sw,
                                            toward_linear)
        tried.append(c_E)
        if c_E <= E:
            premise, theta, E, mubar, D = cand, c_theta, c_E, c_mubar, c_D
            grads = None
        else:
            fit.rejected += 1
            step *= REJECT_SHRINK
        fit.train_rmse.append(float(np.sqrt(2.0 * E / n)))
        keep_best(len(fit.train_rmse))
        if len(tried) >= 5:
            s = np.sign(np.diff(tried[-5:]))
            if np.all(s < 0):
                step *= 1.1
            elif s[0] > 0 > s[1] and s[2] > 0 > s[3]:
                step *= 0.9
    if check is None:
        fit.premise, fit.theta = premise, theta.reshape(-1, Ue.shape[1] + 1)
        fit.best_epoch = len(fit.train_rmse)
    return fit
