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


def test_a_repeated_tick_is_neither_leak_nor_damping():
    """A tick repeated (same time, place and force) changes nothing: the account is the
    path's without it."""
    t, p, f = spring_path(0.001)
    twice = lambda a: np.insert(a, 10, a[10], axis=0)  # noqa: E731
    assert hold_energy(twice(t), twice(p), twice(f), 1.5) == \
        pytest.approx(hold_energy(t, p, f, 1.5), rel=1e-12)


def test_a_shorter_window_cuts_the_force_deeper_after_a_late_tick():
    """The press and stroke with no tick for 8 ms in the stroke (the hand moves on: poses
    80-86 have no tick): at the tick after the gap the 20 ms window's force is further from
    what a window too long to notice one gap (10 s) renders than the 100 ms window's, and it
    limits more ticks; the same poses ticked on time are not limited at all."""
    times, positions = press_and_stroke()
    keep = np.r_[0:80, 87:len(times)]
    t, p = times[keep], positions[keep]
    models, _, _ = models_along(p)
    newest = arrivals(t, 0.001, 10.0, 0.0)
    (short, n_short), (long_, n_long), (none, _) = (
        replay_window(models, t, p, newest, w) for w in (0.02, 0.1, 10.0))
    cut = {k: np.linalg.norm(f[80] - none[80]) for k, f in (('short', short), ('long', long_))}
    # the press's models are well below the stiffness guard, so the cut is small (the depth
    # at the guard is test_servo_native's): the window reaches the loop, and orders the cut
    assert cut['short'] > cut['long'] + 1e-3 and n_short > n_long
    on_time, _, _ = models_along(positions)
    assert replay_window(on_time, times, positions, arrivals(times, 0.001, 10.0, 0.0),
                         0.02)[1] == 0
