"""Pure-core tests of haptic_anfis.device (no ROS): safety layer, mapping, script, sim Falcon."""
from __future__ import annotations

import math
import time

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from haptic_anfis.device import (HandParams, PalpationScript, SimulatedFalcon, WorkspaceMapping,
                                 dome_height)
from haptic_anfis.device.safety import OK, REJECTED_FRAME, REJECTED_NONFINITE
from haptic_anfis.resources import config_file
from tick_oracle import SafetyLayer, ServoLoop

DT = 0.001


def norm(f):
    return math.sqrt(sum(c * c for c in f))


def run(safety, t0, t1, cmd=None, frame='tissue'):
    """Step the layer at 1 kHz from t0 to t1, commanding ``cmd`` every tick if given."""
    out = []
    n = int(round((t1 - t0) / DT))
    for i in range(n):
        t = t0 + i * DT
        if cmd is not None:
            safety.command(cmd, t, frame)
        out.append(safety.output(t))
    return out


# -- safety layer ---------------------------------------------------------------------------------
def test_zero_before_start_and_after_stop():
    s = SafetyLayer()
    assert s.command((1.0, 0, 0), 0.0, 'tissue') != OK
    assert s.output(0.0) == (0.0, 0.0, 0.0)
    s.start(0.0)
    out = run(s, 0.0, 0.1, (3.0, 0.0, 0.0))
    assert out[-1] == pytest.approx((3.0, 0.0, 0.0))
    s.stop()
    assert s.output(0.2) == (0.0, 0.0, 0.0)
    assert s.command((3.0, 0, 0), 0.2, 'tissue') != OK


def test_clamp_keeps_direction():
    s = SafetyLayer(max_force=10.0)
    s.start(0.0)
    out = run(s, 0.0, 0.2, (30.0, 40.0, 0.0))
    assert norm(out[-1]) == pytest.approx(10.0)
    assert out[-1][0] / out[-1][1] == pytest.approx(0.75)
    assert max(norm(f) for f in out) <= 10.0 + 1e-12
    assert s.stats.clamped > 0


def test_rate_limit():
    s = SafetyLayer(max_force_rate=1000.0)
    s.start(0.0)
    out = run(s, 0.0, 0.02, (8.0, 0.0, 0.0))
    steps = np.diff([0.0] + [f[0] for f in out])
    assert steps.max() <= 1000.0 * DT + 1e-9
    assert out[-1][0] == pytest.approx(8.0)


def test_watchdog_ramps_to_zero():
    s = SafetyLayer(watchdog_timeout=0.010, max_force_rate=1000.0)
    s.start(0.0)
    run(s, 0.0, 0.05, (5.0, 0.0, 0.0))
    assert s.output(0.05)[0] == pytest.approx(5.0)
    out = run(s, 0.051, 0.1)  # commands stop
    xs = [f[0] for f in out]
    # holds until the timeout, then ramps (never jumps) down to zero
    assert xs[0] == pytest.approx(5.0)
    assert np.all(np.diff(xs) <= 1e-12) and np.all(np.diff(xs) >= -1000.0 * DT - 1e-9)
    assert xs[-1] == 0.0 and s.watchdog_tripped and s.stats.watchdog_trips == 1
    assert run(s, 0.1, 0.12, (2.0, 0.0, 0.0))[-1][0] == pytest.approx(2.0)  # re-armed


@pytest.mark.parametrize('bad', [(math.nan, 0.0, 0.0), (0.0, math.inf, 0.0), (0.0, 0.0, -math.inf),
                                 (1.0, 2.0), None, 'abc'])
def test_nonfinite_command_zeroes_force_at_once(bad):
    s = SafetyLayer()
    s.start(0.0)
    run(s, 0.0, 0.05, (4.0, 1.0, 0.0))
    assert s.command(bad, 0.05, 'tissue') == REJECTED_NONFINITE
    assert s.output(0.05) == (0.0, 0.0, 0.0)
    assert s.output(0.06) == (0.0, 0.0, 0.0)  # stays zero until a valid command


def test_wrong_frame_rejected():
    s = SafetyLayer(frame_id='tissue')
    s.start(0.0)
    run(s, 0.0, 0.05, (4.0, 0.0, 0.0))
    assert s.command((4.0, 0.0, 0.0), 0.05, 'world') == REJECTED_FRAME
    assert s.output(0.05) == (0.0, 0.0, 0.0)
    assert s.stats.rejected_frame == 1


@pytest.mark.parametrize('kw', [dict(max_force=0.0), dict(max_force=-1.0),
                                dict(max_force_rate=math.nan), dict(watchdog_timeout=math.inf)])
def test_bad_settings_rejected(kw):
    with pytest.raises(ValueError, match=next(iter(kw))):
        SafetyLayer(**kw)


finite_or_not = st.floats(allow_nan=True, allow_infinity=True, width=64)
events = st.lists(st.tuples(st.floats(0.0, 0.02), st.booleans(),
                            st.tuples(finite_or_not, finite_or_not, finite_or_not),
                            st.sampled_from(['tissue', 'tissue', 'world'])), max_size=60)


@given(events, st.floats(0.1, 20.0), st.floats(1.0, 1e5))
def test_output_never_exceeds_clamp_never_nan(evs, max_force, rate):
    s = SafetyLayer(max_force=max_force, max_force_rate=rate)
    s.start(0.0)
    t = 0.0
    for dt, send, f, frame in evs:
        t += dt
        if send:
            s.command(f, t, frame)
        out = s.output(t)
        assert all(math.isfinite(c) for c in out)
        assert norm(out) <= max_force * (1 + 1e-12)
    s.stop()
    assert s.output(t + 1.0) == (0.0, 0.0, 0.0)


# -- mapping, script, simulated device ------------------------------------------------------------
def test_mapping_round_trip_and_checks():
    m = WorkspaceMapping(scale=2.0, offset=(0.01, -0.02, 0.03), force_scale=0.5)
    p = (0.01, 0.02, -0.03)
    assert m.to_device(m.to_tissue(p)) == pytest.approx(p)
    assert m.force_to_device((2.0, 0.0, -4.0)) == (1.0, 0.0, -2.0)
    for bad in (dict(scale=0.0), dict(offset=(0.0, math.nan, 0.0)), dict(force_scale=-1.0)):
        with pytest.raises(ValueError):
            WorkspaceMapping(**bad)


def test_shipped_script_presses_into_the_tissue():
    s = PalpationScript.from_yaml(config_file('palpation.yaml'))
    ts = np.arange(0.0, s.duration, 0.005)
    P = np.array([s.target(t) for t in ts])
    h = np.array([dome_height(y, z) for _, y, z in P])
    below = P[:, 0] < h
    assert below.any() and (~below).any()  # presses and lifts
    assert np.all(np.abs(np.diff(P, axis=0)).max(axis=1) < 0.002)  # continuous at 5 ms sampling
    assert s.target(0.0) == pytest.approx(s.target(s.duration))  # loops back to its start
    assert any(s.is_pressing(t) for t in ts) and not all(s.is_pressing(t) for t in ts)


@pytest.mark.parametrize('doc, match', [
    ({}, 'pattern'), ({'pattern': [{'poke': {}}]}, 'unknown move'),
    ({'pattern': [{'press': {'points': [[0.0]]}}]}, 'points'),
    ({'pattern': [{'press': {'points': [[0.0, 0.0]], 'depth': -1}}]}, 'depth'),
    ({'pattern': [{'pause': {}}], 'press_speed': 0}, 'press_speed')])
def test_bad_script_rejected(doc, match):
    with pytest.raises(ValueError, match=match):
        PalpationScript.from_dict(doc)


def one_press(depth=0.012, hold=1.0, loop=False):
    return PalpationScript.from_dict({'loop': loop, 'start_delay': 0.1, 'pattern': [
        {'press': {'points': [[0.0, 0.0]], 'depth': depth, 'hold': hold}}]})


def test_handle_follows_hand_and_force_pushes_back():
    mp = WorkspaceMapping()
    script = PalpationScript.from_dict({'start_delay': 0.0, 'pattern': [{'pause': {'duration': 5}}]})
    free, pushed = SimulatedFalcon(script, mp), SimulatedFalcon(script, mp)
    for dev in (free, pushed):
        dev.open(0.0)
    pushed.write((5.0, 0.0, 0.0))
    for i in range(1, 2001):
        a, b = free.read(i * DT), pushed.read(i * DT)
    target = free.hand_target(2.0)
    assert a.position == pytest.approx(target, abs=1e-6)
    # static deflection F / k along +x (device frame)
    assert b.position[0] - a.position[0] == pytest.approx(5.0 / HandParams().stiffness, rel=1e-3)


def test_device_clamps_and_ignores_nan_and_stays_in_workspace():
    dev = SimulatedFalcon(one_press(), WorkspaceMapping(), max_force=10.0)
    dev.open(0.0)
    dev.write((math.nan, 0.0, 0.0))
    assert dev._force == (0.0, 0.0, 0.0)
    dev.write((100.0, 0.0, 0.0))
    assert norm(dev._force) == pytest.approx(10.0)
    for i in range(1, 3000):
        st_ = dev.read(i * DT)
    assert all(abs(c) <= 0.05 for c in st_.position)


def test_closed_loop_force_appears_and_vanishes():
    """Hand presses the dome, tracker + ANFIS render the force, the handle is pushed back."""
    from haptic_anfis.anfis import ForceModel
    from haptic_anfis.contact import ContactDetector, ContactTracker, ellipsoid_dome
    from haptic_anfis.tissue.dataset import DATA_DIR
    model = ForceModel.load(DATA_DIR / 'default_model.json')
    tracker = ContactTracker(ContactDetector(ellipsoid_dome(), direction=(-1, 0, 0)))
    mp = WorkspaceMapping()
    script = one_press(depth=0.012, hold=0.5)
    dev, safety = SimulatedFalcon(script, mp), SafetyLayer()
    dev.open(0.0)
    safety.start(0.0)
    fx, depth, hand_depth = [], [], []
    for i in range(int((script.duration + 0.5) / DT)):
        t = i * DT
        p = mp.to_tissue(dev.read(t).position)
        c = tracker.update(p)
        f = model.predict_one(*c.contact_point, c.depth) if c.in_contact else (0.0, 0.0, 0.0)
        safety.command(mp.force_to_device(f), t, 'tissue')
        out = safety.output(t)
        dev.write(out)
        fx.append(out[0])
        depth.append(c.depth)
        hand_depth.append(dome_height(0, 0) - script.target(t)[0])
    fx, depth = np.array(fx), np.array(depth)
    assert fx.max() > 1.0 and fx[-1] == 0.0 and depth[-1] == 0.0
    assert np.all(np.abs(fx) <= 10.0)
    assert depth.max() < 0.8 * max(hand_depth)  # the tissue force held the handle back


def test_servo_loop_thread_runs_and_stops_at_zero_force():
    dev = SimulatedFalcon(one_press(loop=True), WorkspaceMapping())
    safety = SafetyLayer()
    calls = []

    def on_state(state, force, now):
        calls.append(now)
        if len(calls) == 5:
            raise RuntimeError('publisher hiccup')
        safety.command((2.0, 0.0, 0.0), now, 'tissue')

    loop = ServoLoop(dev, safety, rate=500.0, on_state=on_state)
    loop.start()
    time.sleep(0.3)
    assert loop.running
    loop.stop()
    assert not loop.running and loop.errors == 1
    assert len(calls) > 20 and loop.stats.ticks == len(calls)
    assert loop.stats.max_force == pytest.approx(2.0)
    assert dev._force == (0.0, 0.0, 0.0) and safety.output(time.monotonic()) == (0.0, 0.0, 0.0)


def test_servo_loop_survives_a_failing_device_read_at_zero_force():
    class Flaky(SimulatedFalcon):
        n = 0

        def read(self, now):
            Flaky.n += 1
            if Flaky.n == 10:
                raise OSError('USB read failed')
            return super().read(now)

    dev = Flaky(one_press(loop=True), WorkspaceMapping())
    safety = SafetyLayer()
    loop = ServoLoop(dev, safety, rate=500.0,
                     on_state=lambda state, force, now: safety.command((2.0, 0.0, 0.0), now,
                                                                       'tissue'))
    loop.start()
    time.sleep(0.3)
    assert loop.running and loop.errors == 1 and isinstance(loop.last_error, OSError)
    assert Flaky.n > 20  # the thread went on after the failure
    loop.stop()
    assert dev._force == (0.0, 0.0, 0.0)


def test_servo_thread_real_time_priority_or_a_clear_refusal(monkeypatch):
    """The servo thread asks for SCHED_FIFO: granted (it then runs FIFO), or refused with a
    message naming how to allow it; priority 0 leaves the scheduler alone; bad values refused."""
    import os
    import threading

    from haptic_anfis.realtime.scheduling import set_realtime
    assert set_realtime(0) == 'normal scheduler (priority 0)'
    got = {}

    def probe():
        got['said'] = set_realtime(10)
        got['policy'] = os.sched_getscheduler(0)
    t = threading.Thread(target=probe)
    t.start()
    t.join()
    if 'refused' in got['said']:
        assert 'ulimit -r 10' in got['said'] and got['policy'] == os.SCHED_OTHER
    else:
        assert got['said'] == 'SCHED_FIFO priority 10' and got['policy'] == os.SCHED_FIFO

    def refuse(*a):
        raise PermissionError(1, 'Operation not permitted')
    monkeypatch.setattr(os, 'sched_setscheduler', refuse)
    said = set_realtime(50)
    assert 'refused (Operation not permitted)' in said and 'ulimit -r 50' in said
    with pytest.raises(ValueError, match='priority'):
        ServoLoop(None, None, priority=100)
