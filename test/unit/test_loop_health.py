"""The driver's live check of its servo loop (issue 32): a window that lost more than 0.5 % of
its periods, or had a gap past the watchdog, is named in one line; a good window, the first
reading and a reset of the loop's statistics are not."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from haptic_anfis.device.loop_health import LoopHealth, behind_text
from haptic_anfis.device.stats import LoopStats


def reading(ticks, lost, long_gaps=0, seconds=None, resets=0, gap_ms=1.0):
    return {'ticks': ticks, 'periods_lost': lost, 'gaps_past_watchdog': long_gaps,
            'seconds': (ticks + lost) * 1e-3 if seconds is None else seconds,
            'stats_resets': resets, 'max_gap_ms': gap_ms}


def test_the_first_reading_only_starts_the_window():
    h = LoopHealth(0.01)
    assert h.check(reading(5000, 500, 3, gap_ms=40.0)) is None and h.windows == h.behind == 0


def test_a_window_that_lost_too_many_periods_is_named_with_its_length():
    h = LoopHealth(0.01)
    h.check(reading(0, 0))
    msg = h.check(reading(9940, 60, seconds=10.2))   # 0.60 % of 10 000 periods
    assert msg == ('servo loop fell behind over the last 10.2 s: 0.60 % of its periods lost '
                   '(60 of 10000; at most 0.5 %)')
    assert (h.windows, h.behind) == (1, 1)
    assert h.check(reading(19900, 100)) is None   # 40 of 10 000 next: within the target
    assert (h.windows, h.behind) == (2, 1)


def test_the_rate_target_is_the_boundary():
    """995 Hz at 1 kHz: 0.5 % lost is within, one period more is not."""
    h = LoopHealth(0.01)
    h.check(reading(0, 0))
    assert h.check(reading(9950, 50)) is None
    assert h.check(reading(19899, 101)) is not None


def test_a_gap_past_the_watchdog_is_named_with_the_longest():
    h = LoopHealth(0.01)
    h.check(reading(0, 0))
    msg = h.check(reading(9990, 10, long_gaps=1, gap_ms=11.0))
    assert '1 gap between ticks longer than the 10 ms watchdog' in msg
    assert 'the longest since the statistics began 11.0 ms' in msg and 'periods lost' not in msg
    msg = h.check(reading(19970, 30, long_gaps=3, gap_ms=11.0))
    assert '2 gaps between ticks' in msg


def test_a_reset_of_the_statistics_starts_a_new_window():
    """The driver resets its loop statistics at the first command: the readings on either side
    are not one window, even when no counter went back (a check before the reset, the next
    one more than a check period of ticks after it)."""
    h = LoopHealth(0.01)
    h.check(reading(9500, 0, seconds=9.5))
    assert h.check(reading(9700, 2, seconds=9.7, resets=1)) is None   # 2 of 9 702: no verdict
    assert h.windows == 0
    assert h.check(reading(19600, 102, seconds=19.7, resets=1)) is not None   # 100 of 10 000
    h.check(reading(3000, 300, 2, resets=2))
    assert h.check(reading(100, 0, resets=2)) is None   # counters went back: a new window too


def test_no_ticks_no_verdict():
    h = LoopHealth(0.01)
    h.check(reading(10, 0))
    assert h.check(reading(10, 0)) is None and h.windows == 0


@pytest.mark.parametrize('kw, match', [
    ({'watchdog': 0.0}, 'watchdog: expected a finite number > 0 s'),
    ({'watchdog': math.nan}, 'watchdog: expected'),
    ({'watchdog': 0.01, 'max_lost_pct': -1.0}, r'max_lost_pct: expected a number >= 0 and < 100'),
    ({'watchdog': 0.01, 'max_lost_pct': math.inf}, 'max_lost_pct: expected')])
def test_bad_settings_are_refused(kw, match):
    with pytest.raises(ValueError, match=match):
        LoopHealth(**kw)


@settings(max_examples=100, deadline=None)
@given(st.lists(st.floats(0.0002, 0.03), min_size=2, max_size=200))
def test_it_warns_exactly_when_the_ticks_miss_the_rate_or_stop_past_the_watchdog(gaps):
    """A LoopStats that ticked with ``gaps``: the check warns exactly when the window's periods
    lost, counted from the tick times here, are above 0.5 % of its periods, or a gap between
    ticks was longer than the 10 ms watchdog."""
    s = LoopStats(period=0.001, watchdog=0.01)
    h = LoopHealth(0.01)
    t = np.concatenate(([0.0], np.cumsum(gaps)))
    s.tick(float(t[0]))
    h.check(s.summary())
    for x in t[1:]:
        s.tick(float(x))
    d = np.diff(t)   # the gaps as the counters see them (the cumulative sum rounds)
    lost = int(np.sum(np.maximum(np.floor(d / 0.001 + 0.5) - 1, 0)))
    expected = 100.0 * lost / (len(d) + lost) > 0.5 or bool(np.any(d > 0.01))
    assert (h.check(s.summary()) is not None) == expected
    assert s.summary()['gaps_past_watchdog'] == int(np.sum(d > 0.01))


def test_the_pages_line_says_nothing_until_a_window_fell_behind():
    assert behind_text(12, 0, 'anything') == ''
    t = behind_text(12, 3, 'real-time priority keeps the period')
    assert t.startswith('the force came late in 3 of 12 check windows so far')
    assert t.endswith('; real-time priority keeps the period')
