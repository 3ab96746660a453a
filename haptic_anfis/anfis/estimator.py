"""``ANFIS``: a general first-order Sugeno ANFIS regressor (n inputs, one output, grid partition).

Scikit-learn conventions without the dependency: keyword-only hyper-parameters stored unchanged by
``__init__``, ``fit`` returns ``self``, learned attributes end in ``_``, ``get_params`` /
``set_params``, ``score`` is R². Inputs and output in any consistent units.

    model = ANFIS(n_mfs=2, mf='gbell', epochs=500).fit(X, y)
    y_hat = model.predict(X_new)          # numpy batch path
    v = model.predict_one(x)              # compiled single query (numba)

Learning is Jang's (1993) hybrid rule (:mod:`.hybrid`): least-squares consequents, a gradient step
on every MF parameter, Jang's step-size adaptation, and a guard that rejects a step raising the
training error. When ``ridge`` is None the ridge of the consequent least squares is chosen from
``ridge_grid`` (0 included) on a held-out ``validation_fraction`` of the training data, then the
model is refitted on all of it.

Out-of-range policy: memberships are computed at the input clamped to its training range (the rules
of the nearest edge fire: never no rule, never 0 / 0); the consequents' linear terms extrapolate
``extrapolation`` of the range past it and saturate beyond. A constant training column is kept but
carries nothing: it is evaluated at its one training value.
"""
from __future__ import annotations

import inspect
import time
from typing import Any, Sequence

import numpy as np

from ..errors import HapticAnfisError
from . import families as fam
from . import kernel
from .hybrid import Fit, design, hybrid_fit, memberships, weighted_rmse

#: Ridge weights tried when ``ridge`` is None (relative to the largest squared singular value).
RIDGE_GRID = (0.0, 1e-10, 1e-8, 1e-6, 1e-4)


class ANFISInputError(HapticAnfisError, ValueError):
    """Bad data or hyper-parameters given to :class:`ANFIS` (one line naming what and why)."""


class ANFIS:
    """First-order Takagi-Sugeno ANFIS on a grid partition: X (n, d) -> y (n,).

    Args:
        n_mfs: MFs per input: one count for every input, or one per input.
        mf: MF family: 'triangular', 'trapezoidal', 'gbell' (Jang's) or 'gaussian'.
        epochs: epochs of hybrid learning (one least-squares solve each).
        step: initial step length κ of the premise gradient step, in units of the inputs' ranges.
        ridge: relative ridge of the consequent least squares; None: chosen by validation.
        ridge_grid: the ridges tried when ``ridge`` is None.
        ridge_target: what the ridge shrinks every rule's consequent toward: ``'zero'``, or
            ``'linear'``, one global linear fit of the data (rules the data barely excite then
            follow the global trend; :func:`.hybrid.least_squares`).
        validation_fraction: part of the training data held out to choose the ridge.
        rcond: singular values below this fraction of the largest are cut in the least squares.
        extrapolation: how far (fraction of each input's range) the consequents extrapolate:
            one number for every input, or one per input.
        random_state: seeds the validation split.

    Learned attributes: ``n_features_in_``, ``input_min_``, ``input_max_``, ``mf_params_`` (per
    input, the (m, k) MF parameters in input units), ``consequents_`` ((R, d + 1): p_1 .. p_d, q
    per rule, input units), ``ridge_``, ``ridge_scores_`` (validation RMSE per ridge tried),
    ``train_rmse_`` (per epoch), ``n_params_`` (free premise parameters + consequents),
    ``n_rules_``, ``rejected_steps_``, ``fit_seconds_``, ``best_epoch_`` (the epoch the
    parameters are from: the last one, or the best on ``validation_data``), ``validation_rmse_``
    (per epoch on ``validation_data``; empty without).
    """

    def __init__(self, *, n_mfs: int | Sequence[int] = 2, mf: str = 'gbell', epochs: int = 100,
                 step: float = 0.01, ridge: float | None = None,
                 ridge_grid: Sequence[float] = RIDGE_GRID, ridge_target: str = 'zero',
                 validation_fraction: float = 0.2,
                 rcond: float = 1e-12, extrapolation: float | Sequence[float] = 0.0,
                 random_state: int = 0) -> None:
        self.n_mfs = n_mfs
        self.mf = mf
        self.epochs = epochs
        self.step = step
        self.ridge = ridge
        self.ridge_grid = ridge_grid
        self.ridge_target = ridge_target
        self.validation_fraction = validation_fraction
        self.rcond = rcond
        self.extrapolation = extrapolation
        self.random_state = random_state

    # ---- scikit-learn plumbing ------------------------------------------------------------
    @classmethod
    def _param_names(cls) -> list[str]:
        return [p.name for p in inspect.signature(cls.__init__).parameters.values()
                if p.kind == p.KEYWORD_ONLY]

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self._param_names()}

    def set_params(self, **params: Any) -> 'ANFIS':
        names = self._param_names()
        for k, v in params.items():
            if k not in names:
                raise ANFISInputError(f'set_params: unknown parameter {k!r}; expected one of '
                                      f'{names}')
            setattr(self, k, v)
        return self

    def __repr__(self) -> str:
        return f'ANFIS({", ".join(f"{k}={v!r}" for k, v in self.get_params().items())})'

    # ---- checks ---------------------------------------------------------------------------
    def _check_params(self, d: int) -> tuple[str, tuple[int, ...]]:
        try:
            family = fam.check_family(self.mf)
        except ValueError as exc:
            raise ANFISInputError(str(exc)) from None
        m = self.n_mfs
        counts = (m,) * d if np.ndim(m) == 0 else tuple(m)
        if len(counts) != d or not all(isinstance(c, (int, np.integer)) and not isinstance(c, bool)
                                       and 1 <= c <= 20 for c in counts):
            raise ANFISInputError(f'n_mfs: expected an integer 1..20 or {d} of them (one per '
                                  f'input), got {m!r}')
        if int(np.prod(counts)) > 10_000:
            raise ANFISInputError(f'n_mfs {counts} make {int(np.prod(counts))} rules; expected at '
                                  'most 10000 (a grid partition grows as the product)')
        for name, ok, want in (
                ('epochs', isinstance(self.epochs, (int, np.integer))
                 and not isinstance(self.epochs, bool) and self.epochs >= 1, 'an integer >= 1'),
                ('step', _num(self.step) and self.step > 0, 'a number > 0'),
                ('ridge', self.ridge is None or (_num(self.ridge) and self.ridge >= 0),
                 'None or a number >= 0'),
                ('ridge_grid', len(self.ridge_grid) > 0 and all(_num(r) and r >= 0
                                                                for r in self.ridge_grid),
                 'a non-empty sequence of numbers >= 0'),
                ('ridge_target', self.ridge_target in ('zero', 'linear'), "'zero' or 'linear'"),
                ('validation_fraction', _num(self.validation_fraction)
                 and 0 < self.validation_fraction < 1, 'a number in (0, 1)'),
                ('rcond', _num(self.rcond) and 0 <= self.rcond < 1, 'a number in [0, 1)'),
                ('extrapolation', (np.ndim(self.extrapolation) == 0
                                   or (np.ndim(self.extrapolation) == 1
                                       and np.size(self.extrapolation) in (1, d)))
                 and all(_num(e) and e >= 0 for e in np.ravel(self.extrapolation)),
                 f'a number >= 0 or {d} of them (one per input)')):
            if not ok:
                raise ANFISInputError(f'{name}: expected {want}, got {getattr(self, name)!r}')
        return family, tuple(int(c) for c in counts)

    @staticmethod
    def _check_X(X: Any, d: int | None, what: str = 'X') -> np.ndarray:
        try:
            X = np.asarray(X, dtype=np.float64)
        except (TypeError, ValueError):
            raise ANFISInputError(f'{what}: expected a 2-D array of numbers') from None
        if X.ndim != 2 or X.shape[0] < 1 or X.shape[1] < 1:
            raise ANFISInputError(f'{what}: expected a 2-D array (n_samples, n_features), got '
                                  f'shape {X.shape}')
        if d is not None and X.shape[1] != d:
            raise ANFISInputError(f'{what}: expected {d} features (columns), got {X.shape[1]}')
        bad = ~np.isfinite(X)
        if bad.any():
            row, col = np.argwhere(bad)[0]
            raise ANFISInputError(f'{what}: non-finite value {float(X[row, col])!r} at sample '
                                  f'{row}, feature {col}; expected finite numbers')
        return X

    # ---- fit ------------------------------------------------------------------------------
    @staticmethod
    def _check_y(y: Any, n: int, what: str = 'y') -> np.ndarray:
        try:
            y = np.asarray(y, dtype=np.float64)
        except (TypeError, ValueError):
            raise ANFISInputError(f'{what}: expected a 1-D array of numbers') from None
        if y.ndim == 2 and y.shape[1] == 1:
            y = y[:, 0]
        if y.shape != (n,):
            raise ANFISInputError(f'{what}: expected shape ({n},) to match X, got {y.shape}')
        if not np.all(np.isfinite(y)):
            k = int(np.flatnonzero(~np.isfinite(y))[0])
            raise ANFISInputError(f'{what}: non-finite value {float(y[k])!r} at sample {k}; '
                                  'expected finite numbers')
        return y

    def _check_weight(self, w: Any, n: int, what: str = 'sample_weight') -> np.ndarray | None:
        if w is None:
            return None
        w = self._check_y(w, n, what)
        if not np.all(w > 0):
            k = int(np.argmin(w))
            raise ANFISInputError(f'{what}: {float(w[k])!r} at sample {k}; expected weights > 0')
        return w

    def fit(self, X: Any, y: Any, *, sample_weight: Any = None,
            validation_data: tuple | None = None) -> 'ANFIS':
        """Train on X (n, d) and y (n,) (or (n, 1)); returns self.

        Args:
            sample_weight: (n,) weights > 0 of each sample's squared error (default 1).
            validation_data: (X_val, y_val) or (X_val, y_val, weight_val), Jang's checking data:
                the parameters kept are those of the epoch with the lowest (weighted) RMSE on it.
        """
        X = self._check_X(X, None)
        n, d = X.shape
        family, counts = self._check_params(d)
        y = self._check_y(y, n)
        w = self._check_weight(sample_weight, n)
        t0 = time.perf_counter()
        self.n_features_in_ = d
        self.input_min_, self.input_max_ = X.min(axis=0), X.max(axis=0)
        self._family, self._counts = family, counts
        Um, Ue = self._normalise(X)
        check = None
        if validation_data is not None:
            if not isinstance(validation_data, tuple) or len(validation_data) not in (2, 3):
                raise ANFISInputError('validation_data: expected (X_val, y_val) or (X_val, y_val, '
                                      f'weight_val), got {type(validation_data).__name__}')
            Xv = self._check_X(validation_data[0], d, 'validation_data X')
            yv = self._check_y(validation_data[1], len(Xv), 'validation_data y')
            wv = self._check_weight(validation_data[2] if len(validation_data) == 3 else None,
                                    len(Xv), 'validation_data weight')
            check = (*self._normalise(Xv), yv, wv)
        premise0 = [fam.initial(family, m) for m in counts]
        kw = dict(epochs=int(self.epochs), step=float(self.step), rcond=float(self.rcond),
                  weight=w, toward_linear=self.ridge_target == 'linear')
        if self.ridge is None:
            self.ridge_scores_ = self._choose_ridge(family, premise0, Um, Ue, y, kw)
            self.ridge_ = min(self.ridge_scores_, key=lambda r: (self.ridge_scores_[r], r))
        else:
            self.ridge_, self.ridge_scores_ = float(self.ridge), {}
        res: Fit = hybrid_fit(family, premise0, Um, Ue, y, ridge=self.ridge_, check=check, **kw)
        self.train_rmse_ = res.train_rmse
        self.validation_rmse_ = res.check_rmse
        self.best_epoch_ = res.best_epoch
        self.rejected_steps_ = res.rejected
        self._set_learned(family, res.premise, res.theta)
        self.fit_seconds_ = time.perf_counter() - t0
        return self

    def _set_learned(self, family: str, premise: list[np.ndarray], theta: np.ndarray) -> None:
        """The learned attributes and the compiled kernel's arrays from normalised parameters."""
        self._family, self._counts = family, tuple(len(P) for P in premise)
        self._premise, self._theta = premise, theta
        self.n_rules_ = int(np.prod(self._counts))
        self.n_params_ = sum(fam.n_free(family, m) for m in self._counts) + theta.size
        self.mf_params_ = [self._to_input_units(i, P) for i, P in enumerate(premise)]
        span = self._span
        p = theta[:, :-1] / span
        self.consequents_ = np.column_stack([p, theta[:, -1] - p @ self.input_min_])
        self._fp, self._ip = kernel.pack(family, premise, theta, self.input_min_, span,
                                         self._ext_box())

    @classmethod
    def from_params(cls, *, mf: str, mf_params: Sequence[np.ndarray], consequents: np.ndarray,
                    input_min: np.ndarray, input_max: np.ndarray,
                    extrapolation: float | Sequence[float] = 0.0) -> 'ANFIS':
        """A fitted estimator from its parameters in input units (a model file's): per input the
        (m_i, k) MF rows (:mod:`.families`' layout, centres and widths in input units) and the
        (R, d + 1) consequents (p_1 .. p_d, q per rule). Raises :class:`ANFISInputError` on
        shapes, non-finite numbers or MFs outside the constraint set."""
        lo = np.asarray(input_min, dtype=np.float64)
        hi = np.asarray(input_max, dtype=np.float64)
        d = len(lo)
        self = cls(n_mfs=[len(P) for P in mf_params] or 1, mf=mf, extrapolation=extrapolation)
        if lo.shape != (d,) or hi.shape != (d,) or not (np.all(np.isfinite(lo))
                                                        and np.all(np.isfinite(hi))
                                                        and np.all(hi > lo)):
            raise ANFISInputError(f'input range: expected finite min < max per input, got '
                                  f'{lo.tolist()}, {hi.tolist()}')
        if len(mf_params) != d:
            raise ANFISInputError(f'mf_params: expected one array per input ({d}), got '
                                  f'{len(mf_params)}')
        family, counts = self._check_params(d)
        self.n_features_in_, self.input_min_, self.input_max_ = d, lo, hi
        self._family = family
        premise = []
        for i, P in enumerate(mf_params):
            Q = np.array(P, dtype=np.float64)
            if Q.shape != (counts[i], fam.FAMILIES[family]):
                raise ANFISInputError(f'input {i}: expected ({counts[i]}, '
                                      f'{fam.FAMILIES[family]}) {family} MF parameters, got '
                                      f'{Q.shape}')
            premise.append(self._to_unit(i, Q))
            try:
                fam.check(family, premise[-1])
            except ValueError as exc:
                raise ANFISInputError(f'input {i}: {exc}') from None
        coef = np.asarray(consequents, dtype=np.float64)
        R = int(np.prod(counts))
        if coef.shape != (R, d + 1) or not np.all(np.isfinite(coef)):
            raise ANFISInputError(f'consequents: expected ({R}, {d + 1}) finite numbers for '
                                  f'{counts} MFs, got shape {coef.shape}')
        span = self._span
        p = coef[:, :-1]
        theta = np.column_stack([p * span, coef[:, -1] + p @ lo])
        self._set_learned(family, premise, theta)
        return self

    def _choose_ridge(self, family, premise0, Um, Ue, y, kw) -> dict[float, float]:
        """Validation RMSE of each ridge of the grid, trained on the rest of the training data."""
        n = len(y)
        n_val = int(round(self.validation_fraction * n))
        grid = sorted({float(r) for r in self.ridge_grid})
        if n_val < 1 or n - n_val < 2:
            return {grid[0]: float('nan')}
        perm = np.random.default_rng(self.random_state).permutation(n)
        va, tr = perm[:n_val], perm[n_val:]
        w = kw['weight']
        kw = dict(kw, weight=None if w is None else w[tr])
        scores = {}
        for r in grid:
            res = hybrid_fit(family, premise0, Um[tr], Ue[tr], y[tr], ridge=r, **kw)
            scores[r] = weighted_rmse(family, res.premise, res.theta, Um[va], Ue[va], y[va],
                                      None if w is None else w[va])
        return scores

    # ---- units ----------------------------------------------------------------------------
    @property
    def _span(self) -> np.ndarray:
        span = self.input_max_ - self.input_min_
        return np.where(span > 0, span, 1.0)

    def _ext_box(self) -> tuple[np.ndarray, np.ndarray]:
        """(low, high) clamp of the normalised consequent inputs; a constant column: 0."""
        const = self.input_max_ <= self.input_min_
        e = np.where(const, 0.0, np.asarray(self.extrapolation, dtype=np.float64))
        return -e, np.where(const, 0.0, 1.0 + e)

    def _normalise(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        U = (X - self.input_min_) / self._span
        const = self.input_max_ <= self.input_min_
        Um = np.clip(U, 0.0, np.where(const, 0.0, 1.0))
        lo, hi = self._ext_box()
        return Um, np.clip(U, lo, hi)

    def _to_input_units(self, i: int, P: np.ndarray) -> np.ndarray:
        lo, s = self.input_min_[i], self._span[i]
        Q = P.copy()
        if self._family in ('triangular', 'trapezoidal'):
            return lo + s * Q
        Q[:, 0] *= s                       # width (gbell a, Gaussian sigma)
        Q[:, -1] = lo + s * Q[:, -1]       # centre; the gbell slope is dimensionless
        return Q

    def _to_unit(self, i: int, Q: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`_to_input_units`."""
        lo, s = self.input_min_[i], self._span[i]
        P = Q.copy()
        if self._family in ('triangular', 'trapezoidal'):
            return (P - lo) / s
        P[:, 0] /= s
        P[:, -1] = (P[:, -1] - lo) / s
        return P

    # ---- prediction -----------------------------------------------------------------------
    def _check_fitted(self) -> None:
        if not hasattr(self, '_theta'):
            raise ANFISInputError('ANFIS is not fitted: call fit(X, y) first')

    def predict(self, X: Any) -> np.ndarray:
        """Numpy batch path: X (n, d) -> (n,)."""
        self._check_fitted()
        X = self._check_X(X, self.n_features_in_)
        Um, Ue = self._normalise(X)
        mubar, _ = memberships(self._family, self._premise, Um)
        return design(mubar, Ue) @ self._theta.ravel()

    def predict_one(self, x: Any) -> float:
        """Compiled single query (numba, ~1 µs): x (d,) -> y. Raises on a non-finite input."""
        self._check_fitted()
        q = np.asarray(x, dtype=np.float64)
        if q.shape != (self.n_features_in_,):
            raise ANFISInputError(f'predict_one: expected {self.n_features_in_} numbers, got '
                                  f'shape {q.shape}')
        v = kernel.eval_one(q, self._fp, self._ip)
        if v != v:
            raise ANFISInputError(f'predict_one: non-finite input {q.tolist()}; expected finite '
                                  'numbers')
        return v

    def predict_compiled(self, X: Any) -> np.ndarray:
        """Compiled batch path: X (n, d) -> (n,); same numbers as :meth:`predict` to rounding."""
        self._check_fitted()
        X = np.ascontiguousarray(self._check_X(X, self.n_features_in_))
        return kernel.eval_batch(X, self._fp, self._ip)

    def score(self, X: Any, y: Any) -> float:
        """Coefficient of determination R² of :meth:`predict` on (X, y)."""
        y = np.asarray(y, dtype=np.float64).ravel()
        r = y - self.predict(X)
        ss = float(((y - y.mean()) ** 2).sum())
        return 1.0 - float(r @ r) / ss if ss > 0 else (1.0 if not np.any(r) else 0.0)


def _num(v: Any) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool) \
        and bool(np.isfinite(v))
