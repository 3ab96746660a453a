"""The clutch / mark rules (their Python oracle, which the compiled tick is held to in
test_servo_native) and the palpation scripts that press the buttons (no ROS)."""
import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from haptic_anfis.device import PalpationScript, SimulatedFalcon, WorkspaceMapping
from tick_oracle import ClutchMark


def test_clutch_freezes_the_probe_and_keeps_the_offset():
    cm = ClutchMark()
    p, ev = cm.update((0, 0), (0.01, 0.0, 0.0), 0.0)
    assert p == (0.01, 0.0, 0.0) and not ev.clutch_pressed
    p, ev = cm.update((1, 0), (0.01, 0.0, 0.0), 0.001)
    assert ev.clutch_pressed and cm.held
    p, _ = cm.update((1, 0), (0.03, 0.02, -0.01), 0.002)   # the hand re-centres
    assert p == pytest.approx((0.01, 0.0, 0.0))             # the probe stays
    p, ev = cm.update((0, 0), (0.03, 0.02, -0.01), 0.003)
    assert ev.clutch_released and p == pytest.approx((0.01, 0.0, 0.0))   # no jump
    p, _ = cm.update((0, 0), (0.04, 0.02, -0.01), 0.004)
    assert p == pytest.approx((0.02, 0.0, 0.0))             # follows the hand from there


def test_force_zero_while_held_and_until_the_probe_left_the_tissue():
    cm = ClutchMark(ramp_s=0.004)
    cm.update((0, 0), (0, 0, 0), 0.0)
    assert cm.gain((5.0, 0, 0), 0.0) == 1.0
    cm.update((1, 0), (0, 0, 0), 0.001)
    assert cm.gain((5.0, 0, 0), 0.001) == 0.0
    cm.update((0, 0), (0, 0, 0), 0.002)                    # released inside the tissue
    assert cm.gain((5.0, 0, 0), 0.003) == 0.0
    assert cm.gain((6.0, 0, 0), 0.010) == 0.0              # still inside: no force
    assert cm.gain((0.0, 0, 0), 0.011) == 0.0              # left the tissue: the gate opens
    g = [cm.gain((3.0, 0, 0), 0.011 + k * 0.001) for k in range(6)]
    assert g[0] == 0.0 and g[2] == pytest.approx(0.5) and g[-1] == 1.0
    assert all(b >= a for a, b in zip(g, g[1:]))           # a ramp, no jump


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 1), st.integers(0, 1),
                          st.floats(-0.05, 0.05), st.floats(0, 10)), min_size=1, max_size=60))
def test_gain_bounded_and_marks_are_rising_edges_outside_the_clutch(seq):
    cm = ClutchMark()
    prev_mark, marks = 0, 0
    for k, (b0, b1, x, f) in enumerate(seq):
        p, ev = cm.update((b0, b1), (x, 0.0, 0.0), k * 1e-3)
        assert all(math.isfinite(c) for c in p)
        g = cm.gain((f, 0.0, 0.0), k * 1e-3)
        assert 0.0 <= g <= 1.0
        if b0:
            assert g == 0.0 and not ev.mark
        if ev.mark:
            marks += 1
            assert b1 and not prev_mark and not b0
        prev_mark = b1
    assert marks == cm.marks


def test_script_mark_and_clutch_moves_press_the_buttons():
    doc = {'loop': False, 'start_delay': 0.1, 'pattern': [
        {'mark': {'points': [[0.0, 0.0]], 'depth': 0.01, 'hold': 0.4, 'click': 0.1}},
        {'clutch': {'shift': [0.0, 0.02, 0.0]}},
        {'press': {'points': [[0.01, 0.0]], 'depth': 0.01, 'hold': 0.2}}]}
    s = PalpationScript.from_dict(doc)
    ts = np.linspace(0, s.duration, 4000)
    b = np.array([s.buttons(t) for t in ts])
    assert b[:, 1].any() and b[:, 0].any() and not (b[:, 0] & b[:, 1]).any()
    # the mark is pressed while the hand is in the tissue
    assert all(s.is_pressing(t) for t, m in zip(ts, b[:, 1]) if m)
    # after the clutch the hand target is shifted by +20 mm in y, so the probe (hand - shift)
    # presses at y = 10 mm as the script says
    t_press = [t for t in ts if s.is_pressing(t)][-1]
    assert s.target(t_press)[1] == pytest.approx(0.03, abs=1e-9)


def test_simulated_falcon_reports_the_script_buttons():
    doc = {'loop': False, 'start_delay': 0.0, 'pattern': [
        {'mark': {'points': [[0.0, 0.0]], 'depth': 0.01, 'hold': 0.4}}]}
    s = PalpationScript.from_dict(doc)
    dev = SimulatedFalcon(s, WorkspaceMapping())
    seen = set()
    for k in range(int(s.duration * 1000)):
        seen.add(dev.read(k * 1e-3).buttons[:2])
    assert seen == {(0, 0), (0, 1)}


@pytest.mark.parametrize('move, msg', [({'clutch': {'shift': [0.0, 0.1]}}, 'shift'),
                                       ({'strip': {'y': [0.0], 'z': [0, 0.01], 'depths': [-1]}},
                                        'depths')])
def test_bad_button_moves_are_named(move, msg):
    with pytest.raises(ValueError, match=msg):
        PalpationScript.from_dict({'pattern': [move]})
