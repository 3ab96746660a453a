"""Loop statistics in constant memory (issue 21 item 1): the latency histogram's quantiles are
within the stated relative error of the exact order statistics, and a long session's worth of
latencies allocates nothing that grows."""
from __future__ import annotations

import functools
import math
import tracemalloc

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from haptic_anfis.device.stats import LatencyHistogram, LoopStats


def _exact(samples, q):
    return np.quantile(np.asarray(samples), q, method='inverted_cdf')


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(1e-6, 99.0, allow_nan=False), min_size=1, max_size=400),
       st.floats(0.0, 1.0))
def test_quantile_within_stated_relative_error(samples, q):
    h = LatencyHistogram()
    for x in samples:
        h.add(x)
    got = float(h.quantile(q)[0])
    want = float(_exact(samples, q))
    assert abs(got - want) <= h.rel_error * want * (1 + 1e-9)
    assert h.n == len(samples) and h.max == max(samples) and h.min == min(samples)


def test_quantiles_of_a_lognormal_session():
    rng = np.random.default_rng(21)
    lat = rng.lognormal(math.log(0.4e-3), 0.6, 200_000)
    s = LoopStats()
    for x in lat:
        s.latency(float(x))
    out = s.summary()
    assert out['latency_n'] == len(lat)
    for key, q in (('latency_p50_ms', 0.5), ('latency_p99_ms', 0.99)):
        want = _exact(lat, q) * 1e3
        assert out[key] == pytest.approx(want, rel=0.005)
    assert out['latency_max_ms'] == lat.max() * 1e3  # exact


def test_out_of_range_and_bad_values():
    h = LatencyHistogram(lo=1e-6, hi=1.0)
    for x in (-1e-3, 0.0, 5.0, float('nan'), float('inf')):
        h.add(x)
    assert h.n == 4  # NaN is not counted
    assert h.counts[0] == 2 and h.counts[-1] == 2
    assert h.min == -1e-3 and h.max == math.inf
    assert h.quantile(0.0)[0] == -1e-3      # clamped to the exact min
    empty = LatencyHistogram().snapshot()
    assert empty['n'] == 0 and math.isnan(empty['p50']) and math.isnan(empty['max'])
    with pytest.raises(ValueError, match='rel_error'):
        LatencyHistogram(rel_error=0.0)


def test_reset_starts_a_new_window():
    s = LoopStats()
    for x in (1e-3, 2e-3):
        s.latency(x)
    s.reset()
    s.latency(5e-3)
    out = s.summary()
    assert out['latency_n'] == 1 and out['latency_max_ms'] == pytest.approx(5.0)


@pytest.mark.slow  # > 5 s: out of the developer loop (docs/tests.md)
def test_a_long_session_allocates_no_growing_memory():
    """One hour of 1 kHz commands is 3.6 M latencies; 200 k here (tracemalloc is slow). The list
    the loop kept before grew 8.4 MB per million (pointers alone, measured); the histogram's
    allocations stay flat."""
    s = LoopStats()
    rng = np.random.default_rng(0)
    values = rng.lognormal(math.log(0.5e-3), 0.5, 200_000).tolist()
    for x in values[:1000]:  # warm-up
        s.latency(x)
    tracemalloc.start()
    try:
        before = tracemalloc.take_snapshot()
        for x in values[1000:]:
            s.latency(x)
        s.summary()
        after = tracemalloc.take_snapshot()
    finally:
        tracemalloc.stop()
    grown = sum(st.size_diff for st in after.compare_to(before, 'filename'))
    assert grown < 64 * 1024, f'{grown} bytes allocated and kept over 200 k latencies'
    assert s.summary()['latency_n'] == len(values)


def test_share_of_answers_taken_at_the_next_tick():
    """fraction_at_most counts what lies at or below a bound (to a bin); the summary's
    latency_next_tick_pct is that share at 1.25 periods; NaN when nothing was recorded."""
    h = LatencyHistogram()
    assert math.isnan(h.fraction_at_most(0.001))
    for x in [0.00099, 0.00101, 0.00105, 0.00198, 0.00202]:
        h.add(x)
    assert h.fraction_at_most(0.00125) == pytest.approx(0.6)
    assert h.fraction_at_most(1.0) == 1.0 and h.fraction_at_most(1e-7) == 0.0
    st = LoopStats(period=0.001)
    for x in [0.001] * 97 + [0.002] * 3:
        st.latency(x)
    assert st.summary()['latency_next_tick_pct'] == pytest.approx(97.0)


@functools.cache
def compiled_periods_lost_in():
    """periods_lost_in as the compiled tick calls it (native_tick registers it for numba)."""
    import numba

    from haptic_anfis.device import native_tick  # noqa: F401  (registers it)
    from haptic_anfis.device.stats import periods_lost_in
    return numba.njit(lambda gap, period: periods_lost_in(gap, period))


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(0.0, 0.05), min_size=1, max_size=60),
       st.sampled_from([0.001, 0.002, 0.0005]))
def test_the_three_counts_of_lost_periods_agree(gaps, period):
    """LoopStats.tick, tick_gaps and the compiled tick's rule count the same periods lost."""
    from haptic_anfis.device.stats import periods_lost_in, tick_gaps
    compiled = compiled_periods_lost_in()
    t = np.concatenate(([0.0], np.cumsum(gaps)))
    s = LoopStats(period=period)
    for x in t:
        s.tick(float(x))
    lost, longest = tick_gaps(t, period)
    d = np.diff(t)  # the gaps as the counters see them (the cumulative sum rounds)
    assert s.periods_lost == lost == sum(periods_lost_in(float(g), period) for g in d) \
        == sum(compiled(float(g), period) for g in d)
    assert longest == pytest.approx(float(d.max()))


def test_a_gap_of_k_periods_loses_k_minus_one():
    from haptic_anfis.device.stats import periods_lost_in
    assert [periods_lost_in(g * 1e-3, 1e-3) for g in (0.0, 0.4, 1.0, 1.49, 1.51, 3.0, 10.2)] \
        == [0, 0, 0, 0, 1, 2, 9]
