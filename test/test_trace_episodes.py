"""bench/trace_episodes.py's arithmetic: the runs of expired-model ticks and the servo gaps of a
trace, longest first then in time order, and what a topic did around one."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'bench'))
from trace_episodes import around, episodes, ripple_causes  # noqa: E402

from haptic_anfis.device.force_error import dropout_ticks, phantom_ticks, ripple_windows, \
    runs_of  # noqa: E402
from haptic_anfis.device.local_model import EXPIRED, EXTRAPOLATED, FREE, FRESH  # noqa: E402


def test_runs_of_true_at_the_edges_and_inside():
    m = np.array([1, 1, 0, 0, 1, 0, 1, 1, 1], bool)
    assert [tuple(map(int, r)) for r in zip(*runs_of(m))] == [(0, 2), (4, 5), (6, 9)]
    assert len(runs_of(np.zeros(4, bool))[0]) == 0


def test_dropout_and_phantom_ticks_at_their_edges():
    """A dropout: in contact, exactly 0 N applied, the ideal above 1 N (1 N itself is not);
    a phantom: not in contact, above 0.1 N applied (0.1 N itself is not)."""
    applied = np.array([0.0, 0.0, 1e-9, 0.0, 0.1, 0.1001, 0.0])
    ideal = np.array([1.0001, 1.0, 5.0, 5.0, 0.0, 0.0, 0.0])
    contact = np.array([1, 1, 1, 0, 0, 0, 0], bool)
    assert dropout_ticks(applied, ideal, contact).tolist() == [1, 0, 0, 0, 0, 0, 0]
    assert phantom_ticks(applied, contact).tolist() == [0, 0, 0, 0, 0, 1, 0]


def trace(t, status):
    rows = np.zeros((len(t), 8))
    rows[:, 0], rows[:, 7] = t, status
    return rows


def test_the_longest_expired_runs_and_gaps_in_time_order():
    t = np.arange(2000) * 1e-3
    t[1000:] += 0.030                         # a 31 ms gap between ticks 999 and 1000
    t[1500:] += 0.005                         # a 6 ms one: under the threshold
    status = np.full(2000, FRESH)
    status[100:150] = EXPIRED                 # 50 ms, until tick 150's fresh model
    status[300:305] = EXPIRED                 # 5 ms
    status[1990:] = EXPIRED                   # to the trace's end: 9 ms
    status[500:510] = FREE
    eps = episodes(trace(t, status), gap_s=0.010, top=2)
    kinds = [(k, round(t0, 3), round(d, 3)) for k, t0, d in eps]
    assert kinds == [('expired model', 0.1, 0.05), ('servo gap', 0.999, 0.031),
                     ('expired model', 2.025, 0.009)], kinds


def test_around_names_the_messages_either_side_and_counts_those_inside():
    recv = np.array([1.0, 1.1, 1.5, 2.0])
    stamp = recv - 0.002
    s = around((recv, stamp), 1.2, 1.9)
    assert '100.0 ms before (age    2.0)' in s and '    1 during' in s and '100.0 ms after' in s
    assert 'none before' in around((recv, stamp), 0.5, 0.6)
    assert 'none after' in around((recv, stamp), 2.5, 2.6)


def test_the_bag_is_lined_up_by_a_moving_hands_ticks_not_a_still_one(tmp_path):
    """Poses carry each tick's wall-clock stamp; a still hand's ticks lie nanometres apart, so
    they are left out of the match (they lined a real trace up 8.9 s off)."""
    from haptic_anfis.bag import typestore
    from haptic_anfis.bag.writer import BagWriter
    from trace_episodes import clock_offset
    ts = typestore()
    T, H = ts.types['builtin_interfaces/msg/Time'], ts.types['std_msgs/msg/Header']
    P, Q = ts.types['geometry_msgs/msg/Point'], ts.types['geometry_msgs/msg/Quaternion']
    Pose, PoseS = ts.types['geometry_msgs/msg/Pose'], ts.types['geometry_msgs/msg/PoseStamped']
    rng = np.random.default_rng(3)
    n, wall = 3000, 1_700_000_000.25            # wall clock - monotonic [s]
    t = 50.0 + np.arange(n) * 1e-3
    p = np.zeros((n, 3))
    p[:, 0] = 0.01 + rng.normal(0, 1e-9, n)     # held still: nanometre noise
    p[2000:, 1] = np.arange(1000) * 3e-5        # then a stroke at 30 mm/s
    rows = trace(t, FRESH)
    rows[:, 1:4] = p
    # the bag starts with the hand held 3 s before the trace does (its rows begin at the
    # first force command), at the same place
    before = 47.0 + np.arange(3000) * 1e-3
    pub = [(tb, (0.01 + rng.normal(0, 1e-9), 0.0, 0.0)) for tb in before[::2]] + \
        [(t[i], p[i]) for i in range(0, n, 2)]  # the bridge publishes every other tick
    with BagWriter(tmp_path / 'bag') as w:
        w.add_topic('/falcon/measured_cp', PoseS.__msgtype__)
        for tt, q in pub:
            st = tt + wall
            msg = PoseS(H(T(int(st), int(round(st % 1 * 1e9))), 'tissue'),
                        # published through another mapping's rounding: nanometres off
                        Pose(P(q[0] + 2e-9, q[1], q[2]), Q(0.0, 0.0, 0.0, 1.0)))
            w.write('/falcon/measured_cp', ts.serialize_cdr(msg, PoseS.__msgtype__),
                    int(st * 1e9) + 500_000)
    assert abs(clock_offset(rows, {}, tmp_path / 'bag') - wall) < 1e-6
    assert clock_offset(rows, {'realtime_minus_monotonic_s': 5.0}, tmp_path / 'bag') == 5.0


def test_around_gives_no_age_for_a_topic_without_a_header():
    recv = np.array([1.0, 2.0])
    s = around((recv, np.full(2, np.nan)), 1.2, 1.9)
    assert 'age' not in s and '200.0 ms before' in s and '100.0 ms after' in s


def test_a_longer_hold_leaves_the_ticks_past_it():
    """A run of expired ticks begins when the held model is ``hold`` old: under a hold 30 ms
    longer its first 30 ms would have rendered the model."""
    from trace_episodes import longer_holds
    t = np.arange(1000) * 1e-3
    status = np.full(1000, FRESH)
    status[100:150] = EXPIRED                 # 50 ms (the model 0.5-0.55 s old)
    status[400:420] = EXPIRED                 # 20 ms
    status[990:] = EXPIRED                    # to the end: 10 ticks
    got = longer_holds(trace(t, status), 0.5, [0.5, 0.53, 0.6])
    assert [(h, r, n) for h, r, n, _ in got] == [(0.5, 3, 80), (0.53, 1, 20), (0.6, 0, 0)], got
    assert round(got[0][3], 3) == 0.05 and round(got[1][3], 3) == 0.02


@pytest.mark.parametrize('text', ['0.75,x', '', '1,-1', 'nan'])
def test_longer_holds_that_are_no_times_get_one_line(text):
    """--longer-holds 0.75,x: argparse's one line naming the option and what was expected, no
    traceback (the list type the bench scripts share)."""
    import argparse

    from _args import positive_numbers
    with pytest.raises(argparse.ArgumentTypeError, match='expected comma-separated numbers > 0'):
        positive_numbers(text)
    assert positive_numbers('0.75, 1,1.5') == [0.75, 1.0, 1.5]


def test_dropout_runs_are_zero_force_in_contact_named_by_status():
    """A dropout tick: in contact, ideal > 1 N, 0 N applied; runs with their ticks' statuses."""
    from trace_episodes import dropout_runs
    t = np.arange(10) * 1e-3
    status = np.array([FRESH, FREE, FREE, FRESH, EXPIRED, EXPIRED, FRESH, FREE, FREE, FRESH])
    rows = trace(t, status)
    rows[:, 4] = 2.0
    rows[[1, 2, 4, 5, 7, 8], 4] = 0.0          # 0 N applied there
    ideal = np.zeros((10, 3))
    ideal[:, 0] = 3.0
    ideal[8, 0] = 0.5                           # the ideal below 1 N: no dropout
    contact = np.ones(10, dtype=bool)
    contact[2] = False                          # not in contact: no dropout
    got = dropout_runs(rows, ideal, contact)
    assert [(n, kinds) for _, n, _, kinds in got] == [
        (1, {'free': 1}), (2, {'expired': 2}), (1, {'free': 1})], got
    assert got[1][0] == pytest.approx(0.004) and got[1][2] == pytest.approx(0.001)


def test_ripple_windows_find_each_windows_worst_tick():
    """A 0.4 N step at 0.55 s leaves its 50 ms mean by ~0.2 N: window 2 (0.4-0.6 s) is bad and
    its worst tick is the step's; the windows either side stay under 0.1 N, and the last,
    mostly out of contact, is not counted."""
    t = np.arange(0.0, 1.0, 0.001)
    f = np.zeros((len(t), 3))
    f[:, 0] = 3.0
    f[550:, 0] += 0.4
    contact = t < 0.85
    counted, bad, worst, dev = ripple_windows(t, f, contact)
    assert counted.tolist() == [True, True, True, True, False]
    assert bad.tolist() == [False, False, True, False, False]
    assert worst[2] in (549, 550) and dev[worst[2]] == pytest.approx(0.2, abs=0.01)
    assert dev[~contact].max() == 0.0


def test_ripple_causes_tell_a_servo_gap_from_a_step():
    """Two 0.4 N jumps of the applied force the ideal does not have: one after a 15 ms gap
    between ticks (a servo gap), one at a tick on time (a step); a ripple window the ideal
    force has too is not listed."""
    t = np.arange(0.0, 2.0, 0.001)
    t[500:] += 0.015
    ideal = np.zeros((len(t), 3))
    ideal[:, 0] = 3.0
    ideal[1500:, 0] += 0.5                  # the tissue's own step: not the loop's
    rows = trace(t, np.full(len(t), EXTRAPOLATED))
    rows[:, 4:7] = ideal
    rows[500:, 4] += 0.4
    rows[1100:, 4] += 0.4
    causes = ripple_causes(rows, ideal, np.ones(len(t), bool), gap_s=0.003)
    got = [(c['cause'], round(c['jump_n'], 2), round(c['jump_dt_s'] * 1e3)) for c in causes]
    assert got == [('servo gap', 0.4, 16), ('step', 0.4, 1)], got
    assert causes[1]['jump_status'] == 'extrapolated -> extrapolated'
