"""Hybrid learning for :class:`~haptic_anfis.anfis.sugeno.SugenoModel` (Jang 1993).

Each epoch: a forward pass solves the consequents by regularised least squares with the MFs fixed,
then a backward pass moves the MF parameters one gradient step with the consequents fixed, and the
MFs are projected back onto their constraints (ordered, non-degenerate, overlapping). The model with
the lowest checking (validation) error is kept, with the epoch it came from.

Training works on inputs normalised to [0, 1] (``fit_normalized``); :func:`train` wraps the
normalisation so callers pass and get physical units.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.linalg

from . import membership as mfun
from .sugeno import SugenoModel

#: Ridge weight relative to the largest squared singular value of the (column-scaled) design matrix:
#: none by default, since any ridge biases clean data (the force model sets its own,
#: :data:`.defaults.FORCE_MODEL_RIDGE`, chosen by grouped CV on FE data).
DEFAULT_RIDGE = 0.0
#: In the fallback solve, eigenvalues below this fraction of the largest are cut off outright.
SVD_CUTOFF = 1e-12


def _largest_eigenvalue(G: np.ndarray, iterations: int = 50) -> float:
    """Largest eigenvalue of a symmetric PSD matrix with non-negative entries (power iteration from
    the all-ones vector: deterministic, and cheap next to a full decomposition)."""
    v = np.ones(len(G)) / np.sqrt(len(G))
    lam = 0.0
    for _ in range(iterations):
        w = G @ v
        norm = np.linalg.norm(w)
        if norm == 0.0:
            return 0.0
        v = w / norm
        if abs(norm - lam) <= 1e-10 * norm:
            break
        lam = norm
    return float(v @ G @ v)


def solve_consequents(Phi: np.ndarray, t: np.ndarray, ridge: float = DEFAULT_RIDGE, *,
                      n_inputs: int) -> np.ndarray:
    """Regularised least squares for the consequents, stable when Φ is rank deficient.

    A triangular grid partition makes the first-order consequent columns linearly dependent (the
    normalised weights sum to one), and a big structure has more unknowns than samples (128 rules ×
    5 = 640 against ~600), where min-norm least squares blows up. Here every rule's coefficients are
    written θ_r = θ_g + δ_r around one global linear fit θ_g (ordinary least squares on the d + 1
    columns), and the deviations are ridge-regularised: min ||Φ δ - (t - X̃ θ_g)||² + λ ||δ||² with
    λ = ridge · s_max(Φ)² (relative, so it means the same for any data scale). A rule the data
    barely excites therefore falls back to the global linear trend instead of an arbitrary large
    slope: what matters when the haptic probe reaches a grid cell that held few samples.

    Solved through the smaller Gram matrix (ΦΦᵀ when there are fewer samples than unknowns, else
    ΦᵀΦ) plus λI, which is positive definite, by Cholesky: ~10× cheaper than an SVD of Φ, and
    training solves this once per epoch. If Cholesky still fails (λ lost to rounding), an
    eigen-decomposition with a hard cut-off of negligible eigenvalues takes over.

    Args:
        Phi: (n, R (d + 1)) design matrix of :meth:`SugenoModel.design_matrix`.
        t: (n,) targets.
        n_inputs: d, the number of model inputs (Φ has R (d + 1) columns).
    Returns:
        (R (d + 1),) coefficients.
    """
    n, P = Phi.shape
    if isinstance(n_inputs, bool) or not isinstance(n_inputs, (int, np.integer)) or n_inputs < 1:
        raise ValueError(f'solve_consequents: n_inputs must be an integer >= 1, got {n_inputs!r}')
    d1 = int(n_inputs) + 1
    if P % d1:
        raise ValueError(f'design matrix has {P} columns, not a multiple of d + 1 = {d1}')
    R = P // d1
    X1 = Phi.reshape(n, R, d1).sum(axis=1)  # Σ_r w̄_r = 1, so this is [x, 1] (rows × s if scaled)
    theta_g = np.linalg.lstsq(X1, t, rcond=None)[0]
    resid = t - X1 @ theta_g
    dual = n < P
    G = Phi @ Phi.T if dual else Phi.T @ Phi
    lam_max = _largest_eigenvalue(G)
    if lam_max == 0.0:
        return np.tile(theta_g, R)
    rhs = resid if dual else Phi.T @ resid
    A = G + (ridge * lam_max) * np.eye(len(G))
    try:
        z = scipy.linalg.cho_solve(scipy.linalg.cho_factor(A, check_finite=False), rhs,
                                   check_finite=False)
    except np.linalg.LinAlgError:
        ev, V = np.linalg.eigh(A)
        inv = np.where(ev > SVD_CUTOFF * ev[-1], 1.0 / np.where(ev > 0, ev, 1.0), 0.0)
        z = V @ (inv * (V.T @ rhs))
    delta = Phi.T @ z if dual else z
    return delta + np.tile(theta_g, R)


@dataclass
class TrainResult:
    """Outcome of :func:`train`.

    Attributes:
        model: the best model (lowest checking error, or lowest training error without checking data).
        best_epoch: 1-based epoch the model comes from.
        train_rmse, check_rmse: per-epoch RMSE histories (check is empty without checking data).
        n_params: the model's trained parameters when ``model`` is not a SugenoModel.
    """

    model: Any
    best_epoch: int
    train_rmse: list[float] = field(default_factory=list)
    check_rmse: list[float] = field(default_factory=list)
    n_params: int | None = None


def _rmse(y: np.ndarray, t: np.ndarray) -> float:
    return float(np.sqrt(np.mean((y - t) ** 2)))


def fit_normalized(U: np.ndarray, t: np.ndarray, structure: tuple[int, ...], epochs: int = 60,
                   U_check: np.ndarray | None = None, t_check: np.ndarray | None = None,
                   step: float = 0.01, ridge: float = DEFAULT_RIDGE, patience: int = 20,
                   initial_mfs: list[np.ndarray] | None = None, scale: np.ndarray | None = None,
                   scale_check: np.ndarray | None = None, guard: bool = True) -> TrainResult:
    """Hybrid training on normalised inputs U in [0, 1]^d.

    Args:
        U: (n, d) training inputs; t: (n,) targets.
        structure: MF count per input.
        epochs: maximum number of epochs (each = one least-squares solve + one gradient step).
        U_check, t_check: checking data used to pick the epoch (optional).
        step: initial gradient step length in normalised units; adapted with Jang's heuristics
            (×1.1 after 4 consecutive error decreases, ×0.9 after two up-down alternations).
        patience: stop when the checking error has not improved for this many epochs.
        initial_mfs: optional initial MF parameters (repaired onto the constraints).
        scale, scale_check: (n,) positive factors s of the scaled form: the fitted output is
            s · y(U) (the force model's F = depth · g), so the consequents solve the least squares
            on the rows of Φ times s and the MF gradient weighs by s² (both still the hybrid rule
            on the error of s · y). Targets ``t`` and the reported RMSEs are of s · y.
        guard: reject a step whose epoch ends with a higher training error than the last accepted
            one (its MFs are restored and the step halved), so the training error never rises.
    """
    d = U.shape[1]
    if len(structure) != d:
        raise ValueError(f'structure {structure} has {len(structure)} entries for {d} inputs')
    if any(int(m) < 1 or int(m) > 20 for m in structure):
        raise ValueError(f'MF counts must be between 1 and 20, got {structure}')
    lo, hi = np.zeros(d), np.ones(d)
    if initial_mfs is None:
        mfs = [mfun.grid_partition(0.0, 1.0, int(m)) for m in structure]
    else:
        mfs = [mfun.project(P, 0.0, 1.0) for P in initial_mfs]
    R = int(np.prod(structure))
    model = SugenoModel(mfs=mfs, coef=np.zeros((R, d + 1)), lo=lo, hi=hi, extrapolation=0.0)
    has_check = U_check is not None and t_check is not None and len(U_check) > 0
    result = TrainResult(model=copy.deepcopy(model), best_epoch=0)
    best = np.inf
    errors: list[float] = []
    since_best = 0
    if scale is not None:
        scale = np.asarray(scale, dtype=np.float64)
        if scale.shape != t.shape or not np.all(scale > 0):
            raise ValueError('scale must hold one positive factor per training sample')
        t_fit, w_fit = t / scale, scale * scale
    else:
        t_fit, w_fit = t, None
    s_check = 1.0 if scale_check is None else np.asarray(scale_check, dtype=np.float64)
    accepted = None   # (mfs, coef, E, grads) of the last accepted epoch, for the guard
    for epoch in range(1, epochs + 1):
        Phi = model.design_matrix(U)
        if scale is not None:
            Phi *= scale[:, None]
        model.coef = solve_consequents(Phi, t, ridge, n_inputs=d).reshape(R, d + 1)
        grads, E = model.mf_gradient(U, t_fit, w_fit)
        if guard and accepted is not None and E > accepted[2]:
            # The last step raised the training error: undo it and retry with half the step.
            model.mfs, model.coef, E, grads = accepted
            step *= 0.5
        accepted = (model.mfs, model.coef, E, grads)
        train_err = float(np.sqrt(2.0 * E / len(t)))
        result.train_rmse.append(train_err)
        score = train_err
        if has_check:
            score = _rmse(s_check * model.predict(U_check), t_check)
            result.check_rmse.append(score)
        if score < best:
            best, since_best = score, 0
            result.model, result.best_epoch = copy.deepcopy(model), epoch
        else:
            since_best += 1
            if since_best >= patience:
                break
        # Jang's step-size heuristics on the training error.
        errors.append(E)
        if len(errors) >= 5 and all(errors[-k] < errors[-k - 1] for k in range(1, 5)):
            step *= 1.1
        elif len(errors) >= 5:
            diffs = np.sign(np.diff(errors[-5:]))
            if diffs[-1] < 0 < diffs[-2] and diffs[-3] < 0 < diffs[-4]:
                step *= 0.9
        gnorm = np.sqrt(sum(float((g * g).sum()) for g in grads))
        if gnorm == 0.0 or not np.isfinite(gnorm):
            continue  # nothing to move (all inputs single-MF, or at a stationary point)
        model.mfs = [mfun.project(P - step * g / gnorm, 0.0, 1.0) for P, g in zip(model.mfs, grads)]
    return result


def train(X: np.ndarray, t: np.ndarray, structure: tuple[int, ...], epochs: int = 60,
          X_check: np.ndarray | None = None, t_check: np.ndarray | None = None,
          lo: np.ndarray | None = None, hi: np.ndarray | None = None, **kwargs) -> TrainResult:
    """Hybrid training in physical units (see :func:`fit_normalized` for the keyword arguments).

    Args:
        X: (n, d) inputs; t: (n,) targets; structure: MF counts per input.
        lo, hi: (d,) input domain (default: the data's range). Checking inputs outside it are fine:
            they are evaluated with the out-of-range policy.
    Returns:
        TrainResult whose ``model`` takes physical inputs.
    """
    X = np.asarray(X, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)
    lo = X.min(axis=0) if lo is None else np.asarray(lo, dtype=np.float64)
    hi = X.max(axis=0) if hi is None else np.asarray(hi, dtype=np.float64)
    span = hi - lo
    if np.any(span <= 0):
        col = int(np.argmin(span))
        raise ValueError(f'input {col} takes a single value in the training data; it cannot be '
                         'partitioned (drop it or give it a range)')
    norm = (lambda A: (np.asarray(A, dtype=np.float64) - lo) / span)
    res = fit_normalized(norm(X), t, tuple(int(m) for m in structure), epochs,
                         None if X_check is None else norm(X_check), t_check, **kwargs)
    res.model = res.model.rescaled(lo, span)
    return res
