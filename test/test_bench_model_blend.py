"""The model-blend benchmark: its stall schedule, and its replay with models on time (no
session: a short synthetic press)."""
import sys
from pathlib import Path

import numpy as np

BENCH = Path(__file__).resolve().parents[1] / 'bench'
sys.path.insert(0, str(BENCH))
from bench_model_age import models_along  # noqa: E402
from bench_model_blend import arrivals, replay  # noqa: E402
from test_bench_model_age import press_and_stroke  # noqa: E402


def test_a_stall_lets_no_model_through_then_the_newest_comes():
    """Models 1.5 ms late (between two ticks, so rounding cannot move them): pose i's model at
    tick i + 2. During a stall (0.1 s from every 1 s) the loop keeps what it had at the tick
    before the stall, then takes the newest."""
    t = np.arange(0.0, 3.0, 0.001)
    newest = arrivals(t, 0.0015, 1.0, 0.1)
    i = np.arange(len(t))
    assert np.array_equal(newest[:1000], np.maximum(i[:1000] - 2, -1))   # no stall yet
    assert np.all(newest[1000:1100] == 997)          # 1.0-1.1 s: what tick 999 had
    assert newest[1100] == 1098 and newest[1500] == 1498
    assert np.all(newest[2000:2100] == 1997)         # the next stall, from 2 s
    assert np.array_equal(arrivals(t, 0.0015, 1.0, 0.0), np.maximum(i - 2, -1))


def test_models_on_time_and_in_agreement_are_rendered_alike_with_or_without_the_fade():
    """One tick late, a press and a stroke: the fade changes the force by hundredths of a
    newton at most (the deadband takes small steps at once), and it renders in contact."""
    times, positions = press_and_stroke()
    models, F, contact = models_along(positions)
    newest = arrivals(times, 0.001, 10.0, 0.0)
    off = replay(models, times, positions, newest, 0.0)
    on = replay(models, times, positions, newest, 0.02)
    assert np.abs(off[contact]).max() > 0.5
    assert np.abs(on - off).max() < 0.05
