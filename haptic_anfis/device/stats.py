"""Servo-loop timing statistics (no ROS): tick rate, deadline misses, latency percentiles.

Everything here runs in constant memory, whatever the session length: the latencies go into a
fixed log-scale histogram (:class:`LatencyHistogram`), not a growing list (a list of
every command's latency grew the falcon driver by ~145 MB per hour).
"""
from __future__ import annotations

import math
import threading
from dataclasses import dataclass

import numpy as np


class LatencyHistogram:
    """Streaming histogram of positive durations [s] with bounded relative error, fixed memory.

    Bins are geometric: bin ``k >= 1`` holds ``[L, L*g)`` with ``L = lo * g**(k-1)`` and
    ``g = (1 + rel_error) / (1 - rel_error)``; its value ``2 L g / (g + 1)`` is within ``rel_error``
    (relative) of every value in the bin (the DDSketch construction: Masson, Rim & Lee, VLDB 2019). Values below ``lo`` (including 0 and negative ones, e.g. clock skew)
    share bin 0, values at or above ``hi`` the last bin (reported as the exact min / max); count,
    mean, min and max are exact.

    Quantiles: :meth:`quantile` returns, for ``q``, the centre of the bin holding the sample of
    rank ``ceil(q * n)`` (``numpy.quantile(..., method='inverted_cdf')``), hence within
    ``rel_error`` of that sample when it lies in ``[lo, hi)``; clamped to the exact [min, max].

    With the defaults (1 µs .. 100 s, 0.5 %) that is 1 845 bins: 15 KB of int64, whatever ``n``.
    Not locked: one writer thread; a reader sees a consistent copy via :meth:`snapshot`.
    """

    def __init__(self, lo: float = 1e-6, hi: float = 100.0, rel_error: float = 0.005):
        if not (0 < lo < hi and 0 < rel_error < 0.5):
            raise ValueError(f'LatencyHistogram: expected 0 < lo < hi and 0 < rel_error < 0.5, '
                             f'got lo={lo}, hi={hi}, rel_error={rel_error}')
        self.lo, self.hi, self.rel_error = float(lo), float(hi), float(rel_error)
        self.gamma = (1.0 + rel_error) / (1.0 - rel_error)
        self._inv_log_g = 1.0 / math.log(self.gamma)
        self.n_bins = int(math.ceil(math.log(hi / lo) * self._inv_log_g)) + 2
        self.counts = np.zeros(self.n_bins, dtype=np.int64)
        self.clear()

    def clear(self) -> None:
        self.counts[:] = 0
        self.n = 0
        self.total = 0.0
        self.min = math.inf
        self.max = -math.inf

    def bin_of(self, x: float) -> int:
        """Bin index of one value (0: below ``lo``; ``n_bins - 1``: at or above ``hi``)."""
        if not x >= self.lo:  # also NaN
            return 0
        if x >= self.hi:
            return self.n_bins - 1
        return min(int(math.log(x / self.lo) * self._inv_log_g) + 1, self.n_bins - 2)

    def add(self, x: float) -> None:
        """Record one duration [s]; NaN is ignored (not counted)."""
        if x != x:
            return
        self.counts[self.bin_of(x)] += 1
        self.n += 1
        self.total += x
        if x < self.min:
            self.min = x
        if x > self.max:
            self.max = x

    def centre(self, k: int) -> float:
        """The value reported for bin ``k`` [s] (see the class doc; edges for the outer bins)."""
        if k <= 0:
            return self.lo
        if k >= self.n_bins - 1:
            return self.hi
        g = self.gamma
        return self.lo * g ** (k - 1) * 2.0 * g / (g + 1.0)

    def quantile(self, q, counts: np.ndarray | None = None) -> np.ndarray:
        """Quantiles ``q`` (scalar or array in [0, 1]) [s]; NaN when empty (see the class doc)."""
        c = self.counts.copy() if counts is None else counts
        qs = np.atleast_1d(np.asarray(q, dtype=np.float64))
        n = int(c.sum())
        if n == 0:
            return np.full(qs.shape, np.nan)
        cum = np.cumsum(c)
        rank = np.clip(np.ceil(qs * n), 1, n)
        k = np.searchsorted(cum, rank, side='left')
        # the outer bins report the exact extremes (their values are unbounded)
        vals = np.array([self.min if i == 0 else self.max if i == self.n_bins - 1
                         else self.centre(int(i)) for i in k])
        return np.clip(vals, self.min, self.max)

    def snapshot(self) -> dict:
        """n, mean, min, max, p50, p99 [s] of what was recorded so far (NaN when empty)."""
        c = self.counts.copy()
        n = int(c.sum())
        p50, p99 = self.quantile([0.5, 0.99], c)
        return {'n': n, 'mean': self.total / self.n if self.n else math.nan,
                'min': self.min if n else math.nan, 'max': self.max if n else math.nan,
                'p50': float(p50), 'p99': float(p99)}

    def fraction_at_most(self, x: float) -> float:
        """Share of the recorded values <= ``x`` [s] (to the bins' 0.5 %); NaN when empty."""
        n = int(self.counts.sum())
        if n == 0:
            return math.nan
        return float(self.counts[:self.bin_of(x) + 1].sum()) / n

    @property
    def nbytes(self) -> int:
        return int(self.counts.nbytes)


#: a latency up to this many periods counts as "taken at the next tick" (tick start jitter)
NEXT_TICK = 1.25


@dataclass
class LoopStats:
    """Counters one servo loop fills in; read with :meth:`summary`.

    A *deadline miss* is a tick that started more than one period late (at least one tick was
    skipped); the loop then re-synchronises instead of bursting to catch up. Latencies are pose
    stamp -> force command received [s], recorded by whoever receives the commands, into a
    :class:`LatencyHistogram` (percentiles within 0.5 %, max exact; constant memory).
    """
    period: float = 0.001
    ticks: int = 0
    deadline_misses: int = 0
    #: periods lost: a gap of k periods between two ticks lost k - 1 (a deadline miss can lose
    #: many: the miss count undercounted lost ticks ~5x)
    periods_lost: int = 0
    max_gap: float = 0.0  # the longest time between two ticks [s]
    #: the safety layer's watchdog time [s] (inf: no gap counted in ``long_gaps``)
    watchdog: float = math.inf
    #: gaps between two ticks longer than ``watchdog``: each one a stop the hand may feel
    long_gaps: int = 0
    #: windows started again by :meth:`reset` (never cleared: a reader of two summaries knows
    #: whether they belong to one window, ``device/loop_health.py``)
    resets: int = 0
    t_first: float | None = None
    t_last: float | None = None
    max_force: float = 0.0

    def __post_init__(self):
        self.latency_hist = LatencyHistogram()
        self._lock = threading.Lock()

    def reset(self) -> None:
        """Start a new measurement window (counters and latencies cleared)."""
        self.ticks = self.deadline_misses = self.periods_lost = self.long_gaps = 0
        self.resets += 1
        self.max_gap = 0.0
        self.t_first = self.t_last = None
        self.max_force = 0.0
        self.latency_hist.clear()

    def tick(self, now: float) -> None:
        if self.t_first is None:
            self.t_first = now
        elif self.t_last is not None:
            gap = now - self.t_last
            self.periods_lost += periods_lost_in(gap, self.period)
            if gap > self.max_gap:
                self.max_gap = gap
            if gap > self.watchdog:
                self.long_gaps += 1
        self.t_last = now
        self.ticks += 1

    def latency(self, seconds: float) -> None:
        """Record one pose -> command latency [s] (one writer thread: the command callback)."""
        self.latency_hist.add(seconds)

    def summary(self) -> dict:
        span = (self.t_last - self.t_first) if self.ticks > 1 else 0.0
        lat = self.latency_hist.snapshot()
        return {
            'ticks': self.ticks, 'seconds': span,
            'rate_hz': (self.ticks - 1) / span if span > 0 else 0.0,
            'deadline_misses': self.deadline_misses,
            'periods_lost': self.periods_lost, 'max_gap_ms': self.max_gap * 1e3,
            'gaps_past_watchdog': self.long_gaps, 'stats_resets': self.resets,
            'latency_n': lat['n'],
            'latency_p50_ms': lat['p50'] * 1e3, 'latency_p99_ms': lat['p99'] * 1e3,
            'latency_max_ms': lat['max'] * 1e3,
            # answers taken by the tick right after their pose's (the latency counts to the tick
            # that takes the answer, so one period is the least it can be)
            'latency_next_tick_pct': 100.0 * self.latency_hist.fraction_at_most(
                NEXT_TICK * self.period),
            'max_force_N': self.max_force,
        }


def periods_lost_in(gap: float, period: float) -> int:
    """The servo periods lost in a ``gap`` [s] between two ticks of a loop of ``period`` [s]: a
    gap of k periods (k rounded to the nearest whole number) lost k - 1. The one rule of
    :meth:`LoopStats.tick`, :func:`tick_gaps` and the compiled tick (``native_tick``, which
    compiles this function)."""
    return max(int(math.floor(gap / period + 0.5)) - 1, 0)


def tick_gaps(t: np.ndarray, period: float) -> tuple[int, float]:
    """(periods lost, longest gap [s]) of tick times ``t`` [s]: :func:`periods_lost_in` summed
    over the gaps, and the longest."""
    gaps = np.diff(np.asarray(t, dtype=np.float64))
    if gaps.size == 0:
        return 0, 0.0
    lost = np.floor(gaps / period + 0.5).astype(np.int64) - 1  # periods_lost_in, vectorised
    return int(lost[lost > 0].sum()), float(gaps.max())
