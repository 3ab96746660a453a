"""Structure selection: how many MFs each input needs (the paper's 20 % hold-out procedure).

Greedy forward search from the smallest grid: at each round, try adding one MF to each input in
turn, train every candidate on the training part and score it on the held-out validation part; move
to the best candidate while it improves the validation RMSE by more than ``tol``. Finally pick the
*smallest* structure tried (fewest rules, then fewest parameters) whose validation RMSE is within
``tol`` of the best one: model only what the scene needs. Every candidate is reported.

With ``ridges`` (several ridge weights of the consequent least squares) every structure is
scored with each of them, on the same validation folds, and the ridge is chosen with the
structure: among the structures within ``tol`` the smallest, and for it the ridge of the lowest
validation RMSE. A bigger grid fitted to a few hundred FE points overfits at a small ridge
(the validation RMSE rises from 5-5-2 to 7-7-2 on the graded cases); a larger ridge lets the
validation decide, instead of the structure ladder alone.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from .training import TrainResult, train


@dataclass
class Candidate:
    """One structure tried: its validation score and the epoch that scored it."""

    structure: tuple[int, ...]
    n_rules: int
    n_params: int
    train_rmse: float
    val_rmse: float
    best_epoch: int
    seconds: float
    ridge: float | None = None  # the ridge it was scored with (None: the trainer's default)


@dataclass
class SearchResult:
    chosen: Candidate
    candidates: list[Candidate] = field(default_factory=list)


def search_structure(X: np.ndarray, t: np.ndarray, X_val: np.ndarray | None = None,
                     t_val: np.ndarray | None = None, start: tuple[int, ...] = (2, 2, 2, 2),
                     max_mfs: tuple[int, ...] = (5, 5, 5, 3),
                     candidates: list[tuple[int, ...]] | None = None, tol: float = 0.0,
                     epochs: int = 40, lo: np.ndarray | None = None, hi: np.ndarray | None = None,
                     folds: list[tuple[np.ndarray, np.ndarray]] | None = None,
                     scale: np.ndarray | None = None, scale_val: np.ndarray | None = None,
                     ridges: Sequence[float] | None = None,
                     trainer: Callable[..., TrainResult] = train, **train_kwargs) -> SearchResult:
    """Choose MF counts per input by validation RMSE.

    Args:
        X, t: (n, d) training inputs and (n,) targets.
        X_val, t_val: validation inputs and targets (the held-out 20 % of the training part).
        folds: instead of X_val/t_val, (fit, validation) index pairs into X for k-fold scoring:
            a candidate's validation RMSE is then the root mean of its per-fold mean squares
            (train RMSE and best epoch likewise averaged). A few dozen validation points make a
            single hold-out's ranking noisy; k folds see every training point once.
        start: first structure of the greedy search.
        max_mfs: per-input upper bound of the greedy search.
        candidates: if given, an explicit list of structures (grid search) instead of greedy.
        tol: relative tolerance: a bigger structure must beat the best by more than this.
        epochs: maximum epochs per candidate.
        lo, hi: input domain (default: range of ``X``).
        scale, scale_val: (n,) output factors of the scaled form (see
            :func:`~.training.fit_normalized`) for ``X`` and ``X_val``.
        ridges: ridge weights to score every structure with (the chosen one is
            ``chosen.ridge``); None: ``train_kwargs``' ridge (or the trainer's default) only.
        trainer: trains one candidate, with :func:`~.training.train`'s signature and result
            (the force model passes one that fits an :class:`~.estimator.ANFIS`).
    """
    if (folds is None) == (X_val is None or t_val is None):
        raise ValueError('search_structure needs either X_val and t_val or folds')
    sc = (lambda idx: None) if scale is None else (lambda idx: scale[idx])  # noqa: E731
    parts = ([(X, t, X_val, t_val, scale, scale_val)] if folds is None else
             [(X[f], t[f], X[v], t[v], sc(f), sc(v)) for f, v in folds])
    if ridges is not None:
        ridges = [float(r) for r in ridges]
        if not ridges or not all(np.isfinite(r) and r >= 0 for r in ridges):
            raise ValueError(f'ridges: expected finite weights >= 0, got {ridges!r}')
        train_kwargs.pop('ridge', None)
    tried: dict[tuple[tuple[int, ...], float | None], Candidate] = {}

    def score(st: tuple[int, ...], ridge: float | None) -> Candidate:
        if (st, ridge) not in tried:
            t0 = time.perf_counter()
            kw = train_kwargs if ridge is None else dict(train_kwargs, ridge=ridge)
            scores = []
            for Xf, tf, Xv, tv, sf, sv in parts:
                res: TrainResult = trainer(Xf, tf, st, epochs, X_check=Xv, t_check=tv, lo=lo, hi=hi,
                                         scale=sf, scale_check=sv, **kw)
                k = res.best_epoch - 1
                scores.append((res.train_rmse[k], res.check_rmse[k], res.best_epoch))
            tr, va, ep = np.array(scores).T
            n_params = res.n_params if res.n_params is not None else res.model.n_params
            tried[st, ridge] = Candidate(st, int(np.prod(st)), n_params,
                                         float(np.sqrt(np.mean(tr ** 2))),
                                         float(np.sqrt(np.mean(va ** 2))),
                                         int(round(ep.mean())), time.perf_counter() - t0, ridge)
        return tried[st, ridge]

    def evaluate(st: tuple[int, ...]) -> Candidate:
        """The structure scored with every ridge; its best one."""
        return min((score(st, r) for r in (ridges or [None])), key=lambda c: c.val_rmse)

    if candidates:
        for st in candidates:
            if len(st) != X.shape[1]:
                raise ValueError(f'candidate structure {st} needs {X.shape[1]} entries')
            evaluate(tuple(int(m) for m in st))
    else:
        current = evaluate(tuple(start))
        while True:
            steps = []
            for i in range(len(current.structure)):
                if current.structure[i] < max_mfs[i]:
                    st = list(current.structure)
                    st[i] += 1
                    steps.append(evaluate(tuple(st)))
            if not steps:
                break
            best_step = min(steps, key=lambda c: c.val_rmse)
            if best_step.val_rmse < current.val_rmse * (1.0 - tol):
                current = best_step
            else:
                break
    best_val = min(c.val_rmse for c in tried.values())
    ok = [c for c in tried.values() if c.val_rmse <= best_val * (1.0 + tol)]
    chosen = min(ok, key=lambda c: (c.n_rules, c.n_params, c.val_rmse))
    return SearchResult(chosen=chosen, candidates=list(tried.values()))
