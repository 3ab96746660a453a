"""The loop-check benchmark's replay: a trace's ticks read every period as the driver does (no
session: synthetic tick times)."""
import sys
from pathlib import Path

import numpy as np

BENCH = Path(__file__).resolve().parents[1] / 'bench'
sys.path.insert(0, str(BENCH))
from bench_loop_health import replay, session_settings  # noqa: E402


def test_a_steady_loop_is_never_behind_and_a_starved_stretch_is():
    """60 s of 1 ms ticks: silent; with 20-40 s ticking every 2 ms (half the periods lost)
    and a 17 ms gap at its end: the two windows over that stretch are behind (the second for
    both), the others not."""
    t = np.arange(60001) * 1e-3
    health, stats, said = replay(t, 10.0, 0.01, 1e-3)
    assert (health.windows, health.behind, said) == (6, 0, [])
    slow = np.r_[np.arange(0, 20000) * 1e-3, 20.0 + np.arange(0, 10000) * 2e-3,
                 40.015 + np.arange(0, 20000) * 1e-3]
    health, stats, said = replay(slow, 10.0, 0.01, 1e-3)
    assert stats.summary()['gaps_past_watchdog'] == 1
    assert health.windows == 6 and health.behind == 2
    assert all(m.startswith('servo loop fell behind over the last') for m in said)
    assert 'periods lost' in said[0] and 'watchdog' not in said[0]
    assert 'periods lost' in said[1] and '1 gap between ticks longer than the 10 ms' in said[1]


def test_the_watchdog_comes_from_the_sessions_parameter_file(tmp_path):
    trace = tmp_path / 'trace_bag_launch_50_1.npz'
    assert session_settings(trace) == ('bag_launch_50_1', 0.01)   # the default
    (tmp_path / 'driver_50_auto_default.yaml').write_text(
        'falcon_driver:\n  ros__parameters:\n    watchdog_timeout: 0.02\n')
    assert session_settings(trace) == ('bag_launch_50_1', 0.02)
