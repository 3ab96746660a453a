"""A single-output first-order Takagi–Sugeno fuzzy model on a grid partition (the ANFIS network).

The paper's equations (2)–(7), layer by layer, for d inputs with m_i triangular MFs each:

1. membership   μ_ij = tri(x_i; a_ij, b_ij, c_ij)
2. firing       w_r = Π_i μ_{i, j_i(r)}       (product t-norm; rule r = one MF per input)
3. normalise    w̄_r = w_r / Σ_s w_s
4. consequent   f_r = p_r · x + q_r           (first order)
5. output       y = Σ_r w̄_r f_r

Rules are numbered in C order over the MF indices (the last input varies fastest). For a full grid
with the product t-norm, Σ_r w_r = Π_i Σ_j μ_ij, so step 3 is done per input (μ̄_ij = μ_ij / Σ_j μ_ij)
before the product: identical in exact arithmetic, and immune to underflow of the product.

Out-of-range policy (inputs outside the trained domain [lo, hi]):
- memberships are computed at the input clamped to [lo, hi], so the rules of the nearest domain edge
  fire — never no rule, never a silent 0 N or NaN;
- consequents are evaluated at the input clamped to the *extrapolation box*
  [lo - e_i (hi - lo), hi + e_i (hi - lo)], with a per-input fraction e_i (``extrapolation``).
  The force model's default is e = (0, 0, 0, 0.25): positions outside the palpated region saturate
  (the force of the nearest trained point: contact points off the data carry no information, and a
  first-order rule extrapolated sideways can change sign), while depth extrapolates linearly up to a
  quarter of its range past the data (force keeps growing past the deepest sample, and falls toward
  zero below the shallowest) and saturates beyond.
Non-finite inputs raise ``ValueError``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import membership as mfun

#: Per-input extrapolation fractions of the force model's inputs (x, y, z, depth).
DEFAULT_EXTRAPOLATION = (0.0, 0.0, 0.0, 0.25)
#: The same for the depth-scaled form F = depth · g: g saturates in depth, so below the shallowest
#: sample F falls linearly to 0 at contact and past the deepest it grows linearly; y and z
#: consequents extend 15 % of their range past the data (the rim of the palpated disc: grouped-CV
#: Fx RMSE 0.103 -> 0.076 N, seed 0) and saturate beyond.
DEFAULT_EXTRAPOLATION_SCALED = (0.0, 0.15, 0.15, 0.0)


def check_finite_inputs(X: np.ndarray, names: tuple[str, ...] | None = None) -> np.ndarray:
    """Return ``X`` as a float (n, d) array or raise ``ValueError`` naming a non-finite input."""
    X = np.asarray(X, dtype=np.float64)
    if X.ndim == 1:
        X = X[None, :]
    bad = ~np.isfinite(X)
    if bad.any():
        row, col = np.argwhere(bad)[0]
        label = names[col] if names is not None and col < len(names) else f'column {col}'
        raise ValueError(f'non-finite input {label} = {X[row, col]!r} (sample {row}); '
                         'inputs must be finite numbers')
    return X


@dataclass
class SugenoModel:
    """One output of the force model.

    Attributes:
        mfs: per input, an (m_i, 3) array of triangle parameters (a, b, c), input units.
        coef: (R, d + 1) consequent coefficients per rule: (p_1 .. p_d, q); R = Π m_i.
        lo, hi: (d,) trained input domain.
        extrapolation: per input (d,) (or one number for all), width of the extrapolation band
            outside [lo, hi] as a fraction of hi - lo.
    """

    mfs: list[np.ndarray]
    coef: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    extrapolation: np.ndarray | float = 0.0

    def __post_init__(self) -> None:
        self.extrapolation = np.broadcast_to(
            np.asarray(self.extrapolation, dtype=np.float64), (len(self.mfs),)).copy()

    @property
    def n_inputs(self) -> int:
        return len(self.mfs)

    @property
    def structure(self) -> tuple[int, ...]:
        """MF count per input, e.g. (3, 3, 3, 2)."""
        return tuple(len(P) for P in self.mfs)

    @property
    def n_rules(self) -> int:
        return int(np.prod(self.structure))

    @property
    def n_params(self) -> int:
        """Trainable parameters: consequents plus free MF parameters.

        Per input with m >= 2 triangles, 3m - 4 MF parameters are free: the outer peaks are pinned
        to the domain edges and the outer feet lie outside it, unused; a single MF has none."""
        return self.coef.size + sum(3 * m - 4 for m in self.structure if m >= 2)

    # ---- forward pass ---------------------------------------------------------------------
    def clamp(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(inputs for memberships, inputs for consequents): see the out-of-range policy."""
        span = self.hi - self.lo
        Xm = np.clip(X, self.lo, self.hi)
        e = self.extrapolation * span
        Xe = np.clip(X, self.lo - e, self.hi + e)
        return Xm, Xe

    def normalized_memberships(self, Xm: np.ndarray) -> list[np.ndarray]:
        """Per input, (n, m_i) memberships normalised to sum 1 over the input's MFs."""
        out = []
        for i, P in enumerate(self.mfs):
            mu = mfun.membership(Xm[:, i], P)
            out.append(mu / mu.sum(axis=1, keepdims=True))
        return out

    @staticmethod
    def rule_weights(mubar: list[np.ndarray]) -> np.ndarray:
        """Normalised firing strengths w̄ (n, R) from per-input normalised memberships."""
        w = mubar[0]
        for mu in mubar[1:]:
            w = (w[:, :, None] * mu[:, None, :]).reshape(len(w), -1)
        return w

    def predict(self, X: np.ndarray) -> np.ndarray:
        """Batch evaluation (numpy path). X (n, d) -> y (n,)."""
        X = check_finite_inputs(X)
        Xm, Xe = self.clamp(X)
        w = self.rule_weights(self.normalized_memberships(Xm))
        f = Xe @ self.coef[:, :-1].T + self.coef[:, -1]
        return np.einsum('nr,nr->n', w, f)

    # ---- pieces used by training ------------------------------------------------------------
    def design_matrix(self, X: np.ndarray) -> np.ndarray:
        """Φ (n, R (d + 1)) with y = Φ @ coef.ravel(): column r (d+1) + k is w̄_r x_k (x_{d} = 1)."""
        Xm, Xe = self.clamp(X)
        w = self.rule_weights(self.normalized_memberships(Xm))
        xe1 = np.column_stack([Xe, np.ones(len(Xe))])
        return (w[:, :, None] * xe1[:, None, :]).reshape(len(X), -1)

    def mf_gradient(self, X: np.ndarray, target: np.ndarray, weight: np.ndarray | None = None
                    ) -> tuple[list[np.ndarray], float]:
        """Gradient of E = ½ Σ v (y - t)² w.r.t. every MF parameter, consequents held fixed.

        Args:
            X: (n, d) inputs inside the domain.
            target: (n,) desired outputs.
            weight: (n,) sample weights v (default 1). A scaled output F = s·y fitted to F_t is
                ``target = F_t / s``, ``weight = s²``.
        Returns:
            (per input an (m_i, 3) gradient, E). Pinned parameters (outer peaks and outer feet) and
            single-MF inputs get zero gradient.
        """
        Xm, Xe = self.clamp(X)
        n, d = X.shape
        mus = [mfun.membership(Xm[:, i], P) for i, P in enumerate(self.mfs)]
        sums = [mu.sum(axis=1) for mu in mus]
        mubar = [mu / s[:, None] for mu, s in zip(mus, sums)]
        f = (Xe @ self.coef[:, :-1].T + self.coef[:, -1]).reshape((n, *self.structure))
        letters = 'abcdefghijklm'[:d]
        w = self.rule_weights(mubar).reshape(f.shape)
        y = np.einsum(f'z{letters},z{letters}->z', w, f)
        err = y - target
        werr = err if weight is None else err * weight
        grads = []
        for i, P in enumerate(self.mfs):
            if len(P) == 1:
                grads.append(np.zeros_like(P))
                continue
            # G[n, j] = Σ over rules with MF j on input i of f_r Π_{k≠i} μ̄_k.
            operands = [f] + [mubar[k] for k in range(d) if k != i]
            subs = [f'z{letters}'] + [f'z{letters[k]}' for k in range(d) if k != i]
            G = np.einsum(','.join(subs) + f'->z{letters[i]}', *operands)
            dy_dmu = (G - y[:, None]) / sums[i][:, None]  # through the normalisation
            dmu = mfun.membership_grad(Xm[:, i], P)          # (n, m, 3)
            g = np.einsum('n,nm,nmk->mk', werr, dy_dmu, dmu)
            g[0, :2] = 0.0   # a_0 unused, b_0 pinned
            g[-1, 1:] = 0.0  # b_{m-1} pinned, c_{m-1} unused
            grads.append(g)
        return grads, 0.5 * float(werr @ err)

    # ---- units ------------------------------------------------------------------------------
    def rescaled(self, offset: np.ndarray, scale: np.ndarray) -> 'SugenoModel':
        """The same model for inputs x = offset + scale * u, given this model on u.

        Used to train on normalised inputs (u in [0, 1]) and store physical units.
        """
        lo, hi = offset + scale * self.lo, offset + scale * self.hi
        mfs = [offset[i] + scale[i] * P for i, P in enumerate(self.mfs)]
        for i, P in enumerate(mfs):  # keep the outer peaks exactly on the domain edges
            if len(P) > 1:
                P[0, 1], P[-1, 1] = lo[i], hi[i]
        p = self.coef[:, :-1] / scale
        q = self.coef[:, -1] - p @ offset
        return SugenoModel(mfs=mfs, coef=np.column_stack([p, q]), lo=lo, hi=hi,
                           extrapolation=self.extrapolation)

    def validate(self, name: str = 'model') -> None:
        """Raise ``ValueError`` if shapes, finiteness or MF constraints are violated."""
        d = len(self.mfs)
        lo, hi = np.asarray(self.lo, float), np.asarray(self.hi, float)
        if lo.shape != (d,) or hi.shape != (d,):
            raise ValueError(f'{name}: input range must have {d} entries, got {lo.shape}, {hi.shape}')
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(hi > lo)):
            raise ValueError(f'{name}: input range must be finite with max > min')
        for i, P in enumerate(self.mfs):
            mfun.check(P, lo[i], hi[i], name=f'{name} input {i}')
        R = int(np.prod([len(P) for P in self.mfs]))
        if np.shape(self.coef) != (R, d + 1):
            raise ValueError(f'{name}: consequents must have shape ({R}, {d + 1}) for structure '
                             f'{self.structure}, got {np.shape(self.coef)}')
        if not np.all(np.isfinite(self.coef)):
            raise ValueError(f'{name}: consequents hold non-finite numbers')
        e = np.asarray(self.extrapolation, dtype=np.float64)
        if e.shape != (d,) or not (np.all(np.isfinite(e)) and np.all(e >= 0)):
            raise ValueError(f'{name}: extrapolation must be {d} finite numbers >= 0')
