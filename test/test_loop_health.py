"""The driver's live check of its servo loop (issue 32): a window that lost more than 0.5 % of
its periods, or had a gap past the watchdog, is named in one line; a good window, the first
reading and a reset of the counters are not."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from haptic_anfis.device.loop_health import MAX_LOST_PCT, LoopHealth
from haptic_anfis.device.stats import LoopStats


def reading(ticks, lost, long_gaps=0, gap_ms=1.0):
    return {'ticks': ticks, 'periods_lost': lost, 'gaps_past_watchdog': long_gaps,
            'max_gap_ms': gap_ms}


def test_the_first_reading_only_starts_the_window():
    h = LoopHealth(0.01)
    assert h.check(reading(5000, 500, 3, 40.0), 10.0) is None and h.windows == h.behind == 0


def test_a_window_that_lost_too_many_periods_is_named():
    h = LoopHealth(0.01)
    h.check(reading(0, 0), 0.0)
    msg = h.check(reading(9940, 60), 10.0)   # 0.60 % of 10 000 periods
    assert msg == ('servo loop fell behind over the last 10 s: 0.60 % of its periods lost '
                   '(60 of 10000; at most 0.5 %)')
    assert (h.windows, h.behind) == (1, 1)
    assert h.check(reading(19900, 100), 10.0) is None   # 40 of 10 000 next: within the target
    assert (h.windows, h.behind) == (2, 1)


def test_the_rate_target_is_the_boundary():
    """995 Hz at 1 kHz: 0.5 % lost is within, one period more is not."""
    h = LoopHealth(0.01)
    h.check(reading(0, 0), 0.0)
    assert h.check(reading(9950, 50), 10.0) is None
    assert h.check(reading(19899, 101), 10.0) is not None


def test_a_gap_past_the_watchdog_is_named_with_the_sessions_longest():
    h = LoopHealth(0.01)
    h.check(reading(0, 0), 0.0)
    msg = h.check(reading(9990, 10, long_gaps=1, gap_ms=11.0), 10.0)
    assert '1 gap between ticks longer than the 10 ms watchdog' in msg
    assert 'the longest of the session 11.0 ms' in msg and 'periods lost' not in msg
    msg = h.check(reading(19970, 30, long_gaps=3, gap_ms=11.0), 10.0)
    assert '2 gaps between ticks' in msg


def test_a_reset_of_the_counters_starts_a_new_window():
    """The driver resets its loop statistics at the first command (run_duration): counters that
    went back start the window again instead of giving negative counts."""
    h = LoopHealth(0.01)
    h.check(reading(3000, 300, 2), 3.0)
    assert h.check(reading(100, 0), 10.0) is None
    assert h.check(reading(10100, 100), 10.0) is not None   # 100 of 10 100 lost since the reset


def test_no_ticks_no_verdict():
    h = LoopHealth(0.01)
    h.check(reading(10, 0), 0.0)
    assert h.check(reading(10, 0), 10.0) is None


@pytest.mark.parametrize('kw, match', [
    ({'watchdog': 0.0}, 'watchdog: expected a finite number > 0 s'),
    ({'watchdog': math.nan}, 'watchdog: expected'),
    ({'watchdog': 0.01, 'max_lost_pct': -1.0}, 'max_lost_pct: expected a number from 0 to 100'),
    ({'watchdog': 0.01, 'max_lost_pct': math.inf}, 'max_lost_pct: expected')])
def test_bad_settings_are_refused(kw, match):
    with pytest.raises(ValueError, match=match):
        LoopHealth(**kw)


@settings(max_examples=100, deadline=None)
@given(st.lists(st.floats(0.0002, 0.03), min_size=2, max_size=200))
def test_it_agrees_with_the_loops_own_counters(gaps):
    """Fed a LoopStats that ticked with ``gaps``, the check warns exactly when the periods lost
    exceed the target share or a gap passed the watchdog."""
    s = LoopStats(period=0.001, watchdog=0.01)
    h = LoopHealth(0.01)
    t = np.concatenate(([0.0], np.cumsum(gaps)))
    s.tick(float(t[0]))
    h.check(s.summary(), 0.0)
    for x in t[1:]:
        s.tick(float(x))
    sm = s.summary()
    lost, ticks = sm['periods_lost'], len(gaps)
    expected = (100.0 * lost / (ticks + lost) > MAX_LOST_PCT) or sm['gaps_past_watchdog'] > 0
    assert (h.check(sm, float(t[-1])) is not None) == expected
    # the gaps as the counters see them (the cumulative sum rounds)
    assert sm['gaps_past_watchdog'] == int(np.sum(np.diff(t) > 0.01))
