"""Wall-clock measurement helpers shared by the benchmarks and the report (printed, never asserted).

Only numpy and the standard library: cheap to import anywhere.
"""
from __future__ import annotations

import time
from typing import Any, Callable, Sequence

import numpy as np


def time_calls(fn: Callable[..., Any], args: Sequence[tuple], repeats: int) -> np.ndarray:
    """Per-call wall times [s] of ``fn(*args[k % len(args)])`` for k in range(repeats)."""
    out = np.empty(repeats)
    clock = time.perf_counter
    n = len(args)
    for k in range(repeats):
        a = args[k % n]
        t0 = clock()
        fn(*a)
        out[k] = clock() - t0
    return out


def throughput(fn: Callable[[np.ndarray], Any], X: np.ndarray, min_seconds: float = 0.3) -> float:
    """Evaluations per second of the batch call ``fn(X)``, timed over at least ``min_seconds``."""
    fn(X[:10])  # warm: compilation and caches out of the measurement
    n_calls, t0 = 0, time.perf_counter()
    while True:
        fn(X)
        n_calls += 1
        dt = time.perf_counter() - t0
        if dt >= min_seconds:
            return n_calls * len(X) / dt


def percentiles_us(samples: np.ndarray) -> tuple[float, float]:
    """(p50, p99) of per-call times [s], in microseconds."""
    return float(np.percentile(samples, 50) * 1e6), float(np.percentile(samples, 99) * 1e6)
