"""The passivity-window benchmark: its energy account of a zero-order hold, and its replay with
a late tick (no session: a short synthetic press)."""
import sys
from pathlib import Path

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parents[1] / 'bench'
sys.path.insert(0, str(BENCH))
from bench_model_age import models_along  # noqa: E402
from bench_model_blend import arrivals  # noqa: E402
from bench_passivity_window import hold_energy, replay_window  # noqa: E402
from test_bench_model_age import press_and_stroke  # noqa: E402

K = 3000.0   # N/m


def spring_path(period: float, n: int = 50) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(times, positions, forces) of a probe pressed 0.1 mm per tick into a spring K and back."""
    x = np.r_[np.arange(n), np.arange(n)[::-1]] * 1e-4
    p = np.zeros((2 * n, 3))
    p[:, 0] = x
    return np.arange(2 * n) * period, p, -K * p


def test_a_held_spring_leaks_k_dx2_over_2_per_period_whichever_way_it_moves():
    """No damping: each period lets out K dx^2 / 2 (in and out alike), so the running sum only
    rises: excess = net = (periods moved) K dx^2 / 2."""
    t, p, f = spring_path(0.001)
    moved = np.count_nonzero(np.linalg.norm(np.diff(p, axis=0), axis=1))
    excess, net = hold_energy(t, p, f, 0.0)
    assert net == pytest.approx(moved * K * 1e-8 / 2)
    assert excess == pytest.approx(net)


def test_at_the_bound_the_damping_takes_back_what_the_hold_lets_out():
    """K = 2 b / T (Colgate & Schenkel's bound with equality): the balance is zero; at a
    longer period the hold wins, at a shorter one the damping."""
    b = K * 0.001 / 2
    excess, net = hold_energy(*spring_path(0.001), b)
    assert abs(net) < 1e-15 and excess < 1e-15
    assert hold_energy(*spring_path(0.002), b)[1] > 0.0
    excess, net = hold_energy(*spring_path(0.0005), b)
    assert net < 0.0 and excess == pytest.approx(0.0, abs=1e-15)


def test_a_repeated_time_is_neither_leak_nor_damping():
    t, p, f = spring_path(0.001)
    t[10] = t[9]
    p[10] = p[9]
    assert np.isfinite(hold_energy(t, p, f, 1.5)).all()


def test_a_shorter_window_limits_more_ticks_after_a_late_one():
    """The press with one 8 ms gap in its ticks: the 20 ms window scales more ticks than the
    100 ms one, and without a gap neither scales any (the models stiffness is the bound's at
    the nominal period at most)."""
    times, positions = press_and_stroke()
    models, _, _ = models_along(positions)
    newest = arrivals(times, 0.001, 10.0, 0.0)
    assert replay_window(models, times, positions, newest, 0.02)[1] == 0
    late = times + np.where(np.arange(len(times)) >= 80, 0.007, 0.0)   # tick 80 is 8 ms late
    short = replay_window(models, late, positions, newest, 0.02)[1]
    long_ = replay_window(models, late, positions, newest, 0.1)[1]
    assert short > long_
