"""Speed against error for the ANFIS force model (``haptic-anfis bench model``, ``make bench``).

For each structure: test RMSE per output, single-query latency percentiles of the compiled path
(``predict_one``), of its Jacobian (``jacobian_one``) and of the
estimators' numpy path (:func:`~haptic_anfis.anfis.force_model.numpy_forces` on one row), and
batch throughput of both.
Timings are printed, never asserted: the machines are shared and noisy.
"""
from __future__ import annotations

import time
from typing import Any, Sequence

import numpy as np

from ..anfis import ForceModel, rmse
from ..anfis.force_model import numpy_forces
from ..tissue.dataset import ForceDataset, split_indices
from ..anfis.timing import percentiles_us, throughput, time_calls


def time_single(fn, queries: np.ndarray, repeats: int) -> np.ndarray:
    """Per-call wall times [s] of ``fn(x, y, z, depth)`` over ``repeats`` calls cycling ``queries``."""
    return time_calls(fn, [tuple(float(v) for v in q) for q in queries], repeats)


def bench_structures(ds: ForceDataset, structures: Sequence[Any], seed: int = 0,
                     repeats: int = 20000, batch: int = 100_000,
                     params: dict[str, Any] | None = None) -> list[dict]:
    """Train one ForceModel per structure and measure it.

    Args:
        structures: per entry ``None`` (structure search), one tuple for all outputs, or three
            tuples (Fx, Fy, Fz).
        params: further ForceModel keyword arguments (e.g. config/force_model.yaml's section
            without its ``structure``, ``seed`` and ``test_fraction``).
    """
    params = dict(params or {})
    tr_idx, te_idx = split_indices(ds, 0.2, seed)
    tr, te = ds.subset(tr_idx), ds.subset(te_idx)
    rng = np.random.default_rng(seed)
    lo, hi = tr.X.min(0), tr.X.max(0)
    Xb = lo + (hi - lo) * rng.random((batch, 4))
    rows = []
    for st in structures:
        t0 = time.perf_counter()
        model = ForceModel(**{**params, 'structure': st, 'seed': seed}).fit(tr.X, tr.Y,
                                                                          groups=tr.point)
        fit_s = time.perf_counter() - t0
        numpy_one = lambda x, y, z, d: numpy_forces(model, np.array([[x, y, z, d]]))  # noqa: E731
        c50, c99 = percentiles_us(time_single(model.predict_one, te.X, repeats))
        n50, n99 = percentiles_us(time_single(numpy_one, te.X, max(repeats // 10, 200)))
        j50, j99 = percentiles_us(time_single(model.jacobian_one, te.X, repeats))
        structs = ['-'.join(map(str, s)) for s in model.structures_]
        rows.append({
            'label': 'search' if st is None else ('/'.join(structs) if len(set(structs)) > 1
                                                  else structs[0]),
            'structures': structs,
            'rules': [e.n_rules_ for e in model.estimators_],
            'test_rmse': rmse(model.predict(te.X), te.Y),
            'fit_s': fit_s,
            'compiled_p50_us': c50, 'compiled_p99_us': c99,
            'numpy_p50_us': n50, 'numpy_p99_us': n99,
            'jacobian_p50_us': j50, 'jacobian_p99_us': j99,
            'compiled_batch_per_s': throughput(model.predict, Xb),
            'numpy_batch_per_s': throughput(lambda X: numpy_forces(model, X), Xb[:20000]),
        })
    return rows


def format_table(rows: list[dict]) -> str:
    head = (f'{"model":<20} {"structures (Fx/Fy/Fz)":<24} {"RMSE Fx":>8} {"Fy":>8} {"Fz":>8} '
            f'{"fit s":>6} {"jit p50":>8} {"p99 µs":>7} {"jac p50":>7} {"p99 µs":>7} '
            f'{"np p50":>7} {"p99 µs":>7} '
            f'{"jit eval/s":>11} {"np eval/s":>10}')
    lines = [head, '-' * len(head)]
    for r in rows:
        e = r['test_rmse']
        lines.append(
            f'{r["label"]:<20} {"/".join(r["structures"]):<24} {e[0]:>8.4f} {e[1]:>8.4f} {e[2]:>8.4f} '
            f'{r["fit_s"]:>6.1f} {r["compiled_p50_us"]:>8.2f} {r["compiled_p99_us"]:>7.2f} '
            f'{r["jacobian_p50_us"]:>7.2f} {r["jacobian_p99_us"]:>7.2f} '
            f'{r["numpy_p50_us"]:>7.1f} {r["numpy_p99_us"]:>7.1f} '
            f'{r["compiled_batch_per_s"]:>11.3g} {r["numpy_batch_per_s"]:>10.3g}')
    lines.append('paper (MATLAB, its own data): RMSE 0.0791 / 0.0063 / 0.0181 N, ~1e5 evaluations/s; '
                 'haptic budget: 1000 µs per loop at 1 kHz')
    return '\n'.join(lines)
