"""Speed against error of the ANFIS force model on the shipped dataset (see haptic_anfis.report.model_bench),
and the compiled single query of the general ANFIS estimator for every MF family.

Run: ``make bench`` or ``.venv/bin/python bench/bench_model.py [--structures 3-3-3-2 ...]``.
"""
import sys

import numpy as np

from haptic_anfis.anfis import ANFIS
from haptic_anfis.anfis.timing import percentiles_us, throughput, time_calls
from haptic_anfis.cli import main
from haptic_anfis.tissue.dataset import load_dataset
from harness import run_with_page  # noqa: E402  (bench/ is sys.path[0])

#: Single-query timings per family.
REPEATS = 20000


def families() -> None:
    """``ANFIS`` (2 MFs per input, 16 rules) on the shipped dataset's (x, y, z, depth) -> Fz, one
    model per MF family: ``predict_one`` (compiled) and ``predict`` on one row (numpy), p50 / p99,
    and the compiled batch throughput."""
    ds = load_dataset()
    X, y = np.asarray(ds.X, float), np.asarray(ds.Y, float)[:, 2]
    rng = np.random.default_rng(0)
    Q = X.min(0) + (X.max(0) - X.min(0)) * rng.random((1000, 4))
    print('\nANFIS estimator (x, y, z, depth) -> Fz, 2 MFs per input (16 rules), 30 epochs, '
          'ridge 0; single-query times in µs')
    print('| family | train RMSE N | compiled p50 | compiled p99 | numpy p50 | numpy p99 | '
          'compiled eval/s |')
    print('|---|---|---|---|---|---|---|')
    for mf in ('triangular', 'trapezoidal', 'gbell', 'gaussian'):
        m = ANFIS(n_mfs=2, mf=mf, epochs=30, ridge=0.0).fit(X, y)
        rms = float(np.sqrt(np.mean((m.predict(X) - y) ** 2)))
        one = [(q,) for q in Q]
        c50, c99 = percentiles_us(time_calls(m.predict_one, one, REPEATS))
        rows = [(q[None, :],) for q in Q]
        n50, n99 = percentiles_us(time_calls(m.predict, rows, REPEATS // 10))
        rate = throughput(m.predict_compiled, Q)
        print(f'| {mf} | {rms:.4f} | {c50:.2f} | {c99:.2f} | {n50:.1f} | {n99:.1f} | {rate:.3g} |')


def run() -> int:
    rc = main(['bench', 'model', *sys.argv[1:]])
    if not rc:
        families()
    return rc


if __name__ == '__main__':
    sys.exit(run_with_page(run, __file__, __doc__))
