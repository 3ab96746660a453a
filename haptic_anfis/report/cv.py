"""Grouped cross-validation of force models: every depth of a surface point in the same fold.

For each seed the surface points are shuffled into ``k`` folds (:func:`~haptic_anfis.tissue.dataset.fold_indices`);
each fold is predicted by a model trained on the other folds, so every sample gets one out-of-fold
prediction per seed. The score of a seed is the out-of-fold RMSE per output over the whole dataset;
the table gives its mean ± standard deviation over the seeds (a model's own seed follows the CV seed).
"""
from __future__ import annotations

import time
from typing import Any, Callable, Sequence

import numpy as np

from ..tissue.dataset import ForceDataset, fold_indices

#: The default protocol: 5 folds over loading points, 3 seeds.
DEFAULT_FOLDS = 5
DEFAULT_SEEDS = (0, 1, 2)


def group_cv(ds: ForceDataset, make_model: Callable[[int], Any], folds: int = DEFAULT_FOLDS,
             seeds: Sequence[int] = DEFAULT_SEEDS) -> dict[str, Any]:
    """Out-of-fold RMSE of one model family.

    Args:
        ds: the dataset.
        make_model: ``seed -> model`` with ``fit(X, Y, groups=...)`` and ``predict(X) -> (n, 3)``.
        folds: k of the k-fold split over surface points.
        seeds: one full k-fold run per seed.
    Returns:
        {'rmse': (n_seeds, 3) per-seed out-of-fold RMSE [N], 'mean', 'std': (3,) [N] over seeds
        (std with ddof = 1), 'fit_s': mean seconds per fit, 'folds', 'seeds'}.
    """
    per_seed = []
    fit_s = []
    for seed in seeds:
        pred = np.full_like(ds.Y, np.nan)
        for keep, held in fold_indices(ds, folds, seed, by='point'):
            t0 = time.perf_counter()
            model = make_model(seed)
            model.fit(ds.X[keep], ds.Y[keep], groups=ds.point[keep])
            fit_s.append(time.perf_counter() - t0)
            pred[held] = model.predict(ds.X[held])
            if hasattr(model, 'close'):
                model.close()
        per_seed.append(np.sqrt(np.mean((pred - ds.Y) ** 2, axis=0)))
    r = np.array(per_seed)
    return {'rmse': r, 'mean': r.mean(axis=0),
            'std': r.std(axis=0, ddof=1) if len(r) > 1 else np.zeros(3),
            'fit_s': float(np.mean(fit_s)), 'folds': folds, 'seeds': list(seeds)}


def format_cv_table(results: dict[str, dict[str, Any]]) -> str:
    """Markdown table: model | out-of-fold RMSE Fx / Fy / Fz mean ± std [N] | fit [s]."""
    lines = ['| model | group-CV RMSE Fx [N] | Fy [N] | Fz [N] | fit [s] |', '|---|---|---|---|---|']
    if not results:
        return '\n'.join(lines)
    means = np.array([r['mean'] for r in results.values()])
    best = means.min(axis=0)
    for name, r in results.items():
        cells = []
        for a in range(3):
            cell = f'{r["mean"][a]:.4f} ± {r["std"][a]:.4f}'
            cells.append(f'**{cell}**' if r['mean'][a] <= best[a] else cell)
        lines.append(f'| {name} | {" | ".join(cells)} | {r["fit_s"]:.2f} |')
    return '\n'.join(lines)
