"""The compiled servo tick (device/native_tick.py, device/servo_native.py), driven tick by tick at
chosen times (no thread, no timing asserts): safety, local model, passivity bound, counters, and
the ripple / dropout figures (device/force_error.py)."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from haptic_anfis.device import HandParams, WorkspaceMapping
from haptic_anfis.device import native_tick as nt
from haptic_anfis.device.force_error import ripple_and_dropouts
from haptic_anfis.device.force_input import ForceInput
from haptic_anfis.device.local_model import (EXPIRED, EXTRAPOLATED, FREE, FRESH, LocalModel,
                                             tissue_stiffness_limit)
from haptic_anfis.device.palpation import PalpationScript
from haptic_anfis.device.servo_native import NativeServoLoop
from haptic_anfis.device.start_gate import HeldScript
from haptic_anfis.device.stats import LoopStats
from haptic_anfis.device.tick_views import seq_write, spectral_norm_sym
from haptic_anfis.interfaces import LM_P0, LOCAL_MODEL
from tick_oracle import ClutchMark, LocalModelRenderer, SafetyLayer

MAP = WorkspaceMapping(1.5, (0.03, 0.0, 0.0), 1.0)


def still_script(point=(0.06, 0.0, 0.0), moved=(0.06, 0.01, 0.0)):
    """A hand that waits 1 s at ``point`` then moves to ``moved`` within 1 s (tissue frame)."""
    return PalpationScript(np.array([0.0, 1.0, 2.0]), np.array([point, point, moved]),
                           np.array([False, False]), loop=False)


def loop(mode='zoh', **kw) -> NativeServoLoop:
    kw.setdefault('max_force', 8.9)
    return NativeServoLoop(kw.pop('script', still_script()), MAP, HandParams(), mode=mode, **kw)


def pin(lp: NativeServoLoop, x_dev, now: float):
    """Put the handle at ``x_dev`` (device frame) at rest, without dynamics up to ``now``."""
    S = nt.S
    lp.st[S.x0:S.x0 + 3] = x_dev
    lp.st[S.v0:S.v0 + 3] = 0.0
    lp.st[S.t_dev] = now


def test_command_is_rate_limited_then_clamped():
    lp = loop(max_force_rate=1000.0)
    lp.safety.start()
    assert lp.safety.command((20.0, 0.0, 0.0), 0.0, 'tissue') == 'ok'
    f = lp.tick(0.0)
    assert f == (0.0, 0.0, 0.0)  # the first tick has no time to ramp
    f = lp.tick(0.001)
    assert f[0] == pytest.approx(1.0)  # 1000 N/s for 1 ms
    t = 0.001
    for _ in range(8):
        t += 0.001
        lp.safety.command((20.0, 0.0, 0.0), t, 'tissue')
        f = lp.tick(t)
    assert f[0] == pytest.approx(8.9)
    assert lp.safety.stats.clamped > 0


def test_watchdog_ramps_down_and_a_stall_zeroes_at_once():
    lp = loop(max_force_rate=1e6, watchdog_timeout=0.010)
    lp.safety.start()
    lp.safety.command((3.0, 0.0, 0.0), 0.0, 'tissue')
    lp.tick(0.0)
    assert lp.tick(0.001)[0] == pytest.approx(3.0)
    # no new command: after the watchdog time the force goes to zero and a trip is counted
    f = lp.tick(0.0115)  # a gap of 10.5 ms > the watchdog: zero at once
    assert f == (0.0, 0.0, 0.0)
    assert lp.safety.stats.watchdog_trips == 1
    assert lp.safety.stats.watchdog_trips_in_contact == 1


def test_non_finite_inputs_zero_the_force_at_once():
    lp = loop(max_force_rate=1e6)
    lp.safety.start()
    lp.safety.command((2.0, 0.0, 0.0), 0.0, 'tissue')
    lp.tick(0.0)
    assert lp.tick(0.001)[0] == pytest.approx(2.0)
    assert lp.safety.command((math.nan, 0.0, 0.0), 0.001, 'tissue').startswith('rejected')
    assert lp.tick(0.002) == (0.0, 0.0, 0.0)
    # a NaN that bypassed the Python checks (written straight into the buffer): still zero
    lp.safety.command((2.0, 0.0, 0.0), 0.003, 'tissue')
    lp.tick(0.003)
    assert lp.tick(0.004)[0] == pytest.approx(2.0)
    s = lp.cmd[0]
    lp.cmd[:] = (s + 2.0, math.inf, 0.0, 0.0, 0.005)
    assert lp.tick(0.005) == (0.0, 0.0, 0.0)
    assert lp.safety.stats.rejected_nonfinite == 2


def test_wrong_frame_and_disabled_layer_give_zero():
    lp = loop(max_force_rate=1e6)
    assert lp.safety.command((1.0, 0.0, 0.0), 0.0, 'tissue') == 'ignored: disabled'
    assert lp.tick(0.0) == (0.0, 0.0, 0.0)
    lp.safety.start()
    assert lp.safety.command((1.0, 0.0, 0.0), 0.0, 'world') == 'rejected: wrong frame'
    lp.tick(0.001)
    assert lp.tick(0.002) == (0.0, 0.0, 0.0)


def test_a_torn_command_is_not_taken():
    """An odd sequence number (a write in progress) is never read."""
    lp = loop(max_force_rate=1e6)
    lp.safety.start()
    lp.cmd[:] = (1.0, 5.0, 0.0, 0.0, 0.0)  # odd: being written
    lp.tick(0.0)
    assert lp.tick(0.001) == (0.0, 0.0, 0.0)
    lp.cmd[0] = 2.0  # the write finished
    assert lp.tick(0.002)[0] == pytest.approx(5.0)


def model_values(rng, approach=False):
    """A contact model 4 mm in, or (``approach``) the plane ahead of a free probe (depth 0,
    F0 = 0, p0 the surface point)."""
    n = np.array([1.0, 0.0, 0.0])
    d = -n
    c0 = np.array([0.055, 0.0, 0.0])
    depth0 = 0.0 if approach else 0.004
    p0 = c0 + depth0 * d
    A = rng.normal(size=(3, 3))
    K = -(A @ A.T) / np.linalg.norm(A @ A.T) * 800.0 + (A - A.T) * 50.0  # with a skew part
    F0 = np.zeros(3) if approach else -K @ (p0 - c0) * 0.5 + rng.normal(size=3) * 0.1
    return LocalModel(tuple(F0), tuple(p0), K, tuple(c0), tuple(n), tuple(d), depth0, True,
                      0.0).values()


@pytest.mark.parametrize('approach', [False, True])
@pytest.mark.parametrize('spread', [0.001, 0.004])  # 0.004: many probes beyond the radius
@pytest.mark.parametrize('seed', range(3))
def test_local_model_renders_as_the_python_renderer(seed, spread, approach):
    """The compiled tick renders what LocalModelRenderer does, tick by tick: contact models and
    approach planes (free past their own radius along the plane, 6 mm here), inside and beyond
    the validity radius (5 mm)."""
    rng = np.random.default_rng(seed)
    v = model_values(rng, approach)
    lp = loop('local_model', max_force_rate=1e6, validity_time=1.0, approach_radius=0.006)
    ref = LocalModelRenderer(tissue_stiffness_limit(3000.0, 1.0, 1.5), 1.0, 0.005, 0.0015,
                             approach_radius=0.006)
    lp.safety.start()
    lp.renderer.offer_values(v, 0.0)
    ref.offer_values(v, 0.0)
    p0 = np.array(v[LM_P0])
    t = 0.0
    away = 0   # probes past an approach plane, further along it than the radius
    for _ in range(20):
        q = p0 + rng.normal(size=3) * spread
        away += approach and q[0] < p0[0] and np.hypot(q[1] - p0[1], q[2] - p0[2]) > 0.006
        pin(lp, MAP.to_device(tuple(q)), t)
        lp.tick(t)
        want, status = ref.render(tuple(q), t)
        S = nt.S
        if want is None:
            assert int(lp.st[nt.S.status]) in (EXPIRED, 0)
        else:
            got = lp.st[S.target0:S.target0 + 3]
            np.testing.assert_allclose(got, want, atol=1e-9)
        t += 0.001
    assert lp.renderer.stats.ticks_fresh + lp.renderer.stats.ticks_extrapolated + \
        lp.renderer.stats.ticks_free > 0
    assert lp.cnt[nt.CNT.beyond] == ref.stats.ticks_beyond
    assert lp.cnt[nt.CNT.free] == ref.stats.ticks_free
    if not approach:
        assert (ref.stats.ticks_beyond > 0) == (spread > 0.002)
    assert (away > 0) == (approach and spread > 0.002), away


@pytest.mark.parametrize('approach_radius, across, free', [
    (0.006, 0.0055, False),   # past the validity radius (5 mm), inside its own: held, rendered
    (0.006, 0.007, True),
    (0.002, 0.003, True)])    # its own radius below the validity radius applies as well
def test_the_tick_frees_an_approach_plane_past_its_own_radius(approach_radius, across, free):
    """The compiled tick reads approach_radius (not the validity radius): a probe 1 mm past an
    approach plane, ``across`` along it from its point, renders as the Python renderer does."""
    v = model_values(np.random.default_rng(0), approach=True)
    lp = loop('local_model', max_force_rate=1e6, validity_time=1.0,
              approach_radius=approach_radius)
    ref = LocalModelRenderer(tissue_stiffness_limit(3000.0, 1.0, 1.5), 1.0, 0.005, 0.0015,
                             approach_radius=approach_radius)
    lp.safety.start()
    lp.renderer.offer_values(v, 0.0)
    ref.offer_values(v, 0.0)
    q = np.array(v[LM_P0]) + np.array([-0.001, across, 0.0])   # n = +x: 1 mm in, across along y
    pin(lp, MAP.to_device(tuple(q)), 0.0)
    lp.tick(0.0)
    want, status = ref.render(tuple(q), 0.0)
    assert status == (FREE if free else FRESH) == int(lp.st[nt.S.status])
    np.testing.assert_allclose(lp.st[nt.S.target0:nt.S.target0 + 3], want, atol=1e-9)
    assert (np.linalg.norm(want) > 0.1) != free, want
    assert lp.cnt[nt.CNT.beyond] == ref.stats.ticks_beyond == (0 if free else 1)


def test_the_tick_kernels_are_rebuilt_when_a_function_they_inline_changes():
    """numba's cache keys the tick on native_tick.py alone: INLINED_SOURCE_HASH, kept in that
    file, must be the hash of the functions it compiles in from other modules."""
    got = nt.inlined_source_hash()
    assert nt.INLINED_SOURCE_HASH == got, (
        f'a function compiled into the tick changed: set native_tick.INLINED_SOURCE_HASH = {got!r}')


def test_a_model_offered_is_written_to_the_model_buffer_by_field_name():
    """The renderer fills the compiled tick's model buffer by the fields of
    native_tick.MODEL_SLOT, and the tick takes it into the state's m_* members in that order."""
    lp = loop('local_model', max_force_rate=1e6)
    lp.safety.start()
    v = model_values(np.random.default_rng(1))
    lm = np.asarray(v).view(LOCAL_MODEL)[0]
    lp.renderer.offer_values(v, 0.25)
    m = lp.model.view(nt.MODEL_SLOT)[0]
    assert m['seq'] == 2.0 and m['valid'] == 1.0 and m['t0'] == 0.25
    np.testing.assert_array_equal(m['f'], lm['f0'])
    np.testing.assert_array_equal(m['p'], lm['p0'])
    np.testing.assert_array_equal(m['d'], lm['direction'])
    assert m['depth0'] == lm['depth'] and m['contact'] == 1.0 and m['knorm'] > 0.0
    K = lm['k'].reshape(3, 3)
    np.testing.assert_allclose(m['k'].reshape(3, 3), (K + K.T) / 2, atol=1e-9)  # 800 N/m: no clamp
    lp.tick(0.0)
    for i, name in enumerate(nt.MODEL_SLOT.names[1:]):
        at = nt.S[f'm_{name}' if not m[name].shape else f'm_{name}0']
        want = np.atleast_1d(m[name])
        np.testing.assert_array_equal(lp.st[at:at + len(want)], want, err_msg=name)


def test_non_finite_model_is_never_rendered():
    lp = loop('local_model', max_force_rate=1e6)
    lp.safety.start()
    lm = np.asarray(model_values(np.random.default_rng(0))).view(LOCAL_MODEL)[0]
    slot = np.zeros(1, nt.MODEL_SLOT)
    m = slot[0]
    m['f'], m['p'], m['k'], m['depth0'] = lm['f0'], lm['p0'], lm['k'], lm['depth']
    m['zero'] = m['contact'] = m['valid'] = m['knorm'] = m['hold_skew'] = 1.0
    m['f'][0] = math.nan
    seq_write(lp.model, slot.view(np.float64)[1:])
    pin(lp, MAP.to_device(tuple(lm['p0'])), 0.0)
    assert lp.tick(0.0) == (0.0, 0.0, 0.0)
    assert int(lp.st[nt.S.status]) == 0  # no model
    assert lp.safety.stats.rejected_nonfinite == 1


def wall_loop(**kw):
    """A loop with a 1500 N/m wall (device frame 1.5 x 1500 = 2250 N/m), the probe 1 mm in
    (``kw``: more of the loop's arguments)."""
    lp = loop('local_model', max_force_rate=1e6, validity_time=10.0, hold_time=20.0,
              damping=1.5, **kw)
    lp.safety.start()
    n = (1.0, 0.0, 0.0)
    K = np.diag([-1500.0, 0.0, 0.0])
    v = LocalModel((1.0, 0.0, 0.0), (0.05, 0.0, 0.0), K, (0.055, 0.0, 0.0), n, (-1.0, 0.0, 0.0),
                   0.005, False, 0.0).values()
    lp.renderer.offer_values(v, 0.0)
    return lp, MAP.to_device((0.049, 0.0, 0.0))


def test_stiffness_is_limited_by_the_measured_period():
    """Colgate & Schenkel: K <= 2 b / T, T the energy-weighted mean period of the last
    ``passivity_window`` (sum T^2 / sum T). A loop ticking every 5 ms with b = 1.5 N s/m gets
    600 N/m; one late tick among nominal ones is limited far less than by its own gap."""
    S = nt.S
    lp, q = wall_loop()
    pin(lp, q, 0.0)
    lp.tick(0.0)  # first tick: the nominal period
    assert lp.st[S.target0] == pytest.approx(1.0 + 1.5)  # 1 N + 1500 N/m x 1 mm, not limited
    assert lp.cnt[nt.CNT.passivity_limited] == 0
    for t in np.arange(1, 200) * 0.005:  # a loop that keeps ticking every 5 ms
        pin(lp, q, t)
        lp.tick(t)
    s = (2 * 1.5 / 0.005) / (1500.0 * 1.5)
    assert lp.st[S.target0] == pytest.approx(1.0 + s * 1.5, rel=1e-6)
    assert lp.cnt[nt.CNT.passivity_limited] > 190
    # nominal ticks, then one 5 ms gap
    lp, q = wall_loop()
    t = 0.0
    for t in np.arange(0, 100) * 0.001:
        pin(lp, q, t)
        lp.tick(t)
    assert lp.st[S.pt2] / lp.st[S.pt1] == pytest.approx(0.001)
    lam = np.exp(-0.005 / lp.cfg[nt.CFG.passivity_window])
    t_eff = (lam * lp.st[S.pt2] + 0.005 ** 2) / (lam * lp.st[S.pt1] + 0.005)
    t += 0.005
    pin(lp, q, t)
    lp.tick(t)
    s = (2 * 1.5 / t_eff) / (1500.0 * 1.5)
    assert 0.6 < s < 1.0  # the old rule (T = this gap alone): 0.27
    assert lp.st[S.target0] == pytest.approx(1.0 + s * 1.5, rel=1e-6)
    for t in t + np.arange(1, 200) * 0.001:  # back to nominal: the bound recovers
        pin(lp, q, t)
        lp.tick(t)
    assert lp.st[S.target0] == pytest.approx(1.0 + 1.5)


def limited_after_one_gap(window: float, gap: float) -> tuple[np.ndarray, float]:
    """(the stiffness scale (extrapolated force / unlimited) at each tick from the gap on, the
    period the bound would use at the gap by the window's formula [s]) of a wall loop with
    ``passivity_window`` = ``window`` [s]: 100 nominal ticks, one ``gap`` [s], 300 nominal."""
    S = nt.S
    lp, q = wall_loop(passivity_window=window)
    times = np.r_[np.arange(100) * 0.001, 0.099 + gap + np.arange(300) * 0.001]
    scale, t_eff = [], 0.0
    for i, t in enumerate(times):
        if i == 100:   # sum(T^2) / sum(T), the sums decayed over the gap, then the gap added
            lam = np.exp(-gap / window)
            t_eff = (lam * lp.st[S.pt2] + gap ** 2) / (lam * lp.st[S.pt1] + gap)
        pin(lp, q, t)
        lp.tick(t)
        scale.append((lp.st[S.target0] - 1.0) / 1.5)
    return np.array(scale[100:]), t_eff


def test_the_passivity_window_sets_how_deep_one_late_tick_limits():
    """A longer window: a 7.5 ms gap lowers the stiffness less; the bound comes back to
    nominal either way. The scale right after the gap is the window's formula."""
    (short, t_short), (long_, t_long) = (limited_after_one_gap(0.02, 0.0075),
                                         limited_after_one_gap(0.1, 0.0075))
    assert short[0] < long_[0] < 1.0
    for s, t_eff in ((short[0], t_short), (long_[0], t_long)):
        assert s == pytest.approx(2 * 1.5 / t_eff / 2250.0, rel=1e-9)   # K <= 2 b / T
    assert short[-1] == long_[-1] == pytest.approx(1.0)


@pytest.mark.parametrize('window', [0.0, -0.02, float('nan'), float('inf'), True, '0.05'])
def test_a_bad_passivity_window_is_refused(window):
    with pytest.raises(ValueError, match='passivity_window: expected a finite number > 0 s'):
        wall_loop(passivity_window=window)


@given(st.lists(st.floats(0.0002, 0.05), min_size=1, max_size=300))
def test_passivity_period_is_the_energy_weighted_mean_of_the_recent_periods(gaps):
    """sum(T^2) / sum(T) of the capped periods, exponentially weighted from a nominal history:
    never below the shortest (or nominal) period nor above the longest (capped) one, and the
    bound it gives holds at every tick."""
    lp = loop('local_model')
    cfg, state = lp.cfg, nt.new_state()
    cap, nominal = cfg[nt.CFG.watchdog], cfg[nt.CFG.period]
    w = cfg[nt.CFG.passivity_window]
    a, b = w, w * nominal
    for i, gap in enumerate(gaps):
        t = min(gap, cap)
        lam = math.exp(-t / w)
        a, b = lam * a + t, lam * b + t * t
        got = nt._passivity_period(cfg, state, gap)
        assert got == pytest.approx(b / a, rel=1e-9)
        capped = [min(g, cap) for g in gaps[:i + 1]] + [nominal]
        assert min(capped) * (1 - 1e-9) <= got <= max(capped) * (1 + 1e-9)


def test_lost_periods_are_counted():
    lp = loop()
    for t in (0.0, 0.001, 0.002, 0.007, 0.008):
        lp.tick(t)
    assert lp.cnt[nt.CNT.periods_lost] == 4
    assert lp.cnt[nt.CNT.ticks] == 5
    s = LoopStats(period=0.001)
    for t in (0.0, 0.001, 0.002, 0.007, 0.008):
        s.tick(t)
    assert s.summary()['periods_lost'] == 4
    assert s.summary()['max_gap_ms'] == pytest.approx(5.0)


def test_held_script_waits_for_release():
    lp = loop(script=HeldScript(still_script(), held=True))
    x = lp.st[nt.S.x0:nt.S.x0 + 3].copy()
    for i in range(1500):
        lp.tick(i * 0.001)
    np.testing.assert_allclose(lp.st[nt.S.x0:nt.S.x0 + 3], x, atol=1e-9)
    lp.release()
    for i in range(1500, 4000):
        lp.tick(i * 0.001)
    assert lp.st[nt.S.x1] > 0.005 / 1.5 * 0.9  # the hand moved 1 cm (tissue) in y


def test_stop_leaves_zero_force_and_trace_rows():
    from haptic_anfis.device.trace import TickTrace
    lp = loop(max_force_rate=1e6, trace=TickTrace())
    lp.safety.start()
    lp.safety.command((2.0, 0.0, 0.0), 0.0, 'tissue')
    lp.tick(0.0)
    assert lp.tick(0.001)[0] == pytest.approx(2.0)
    lp.ctl[nt.CTL.stop] = 1
    nt.run(lp.cfg, lp.st, lp.cnt, lp.hand_script, lp.buffers, lp._scratch,
           np.zeros(2, dtype=np.int64), lp._lock)
    assert tuple(lp.st[nt.S.f0:nt.S.f0 + 3]) == (0.0, 0.0, 0.0)
    lp._drain()
    rows = lp.trace.arrays()
    assert rows.shape == (2, 8)
    assert rows[1, 4] == pytest.approx(2.0)


def test_ripple_and_dropouts_on_known_signals():
    t = np.arange(0, 2.0, 0.001)
    n = len(t)
    steady = np.tile([5.0, 0.0, 0.0], (n, 1))
    contact = np.ones(n, bool)
    r = ripple_and_dropouts(t, steady, steady, contact)
    assert r['ripple_windows_pct'] == 0.0 and r['zero_force_ticks'] == 0
    buzz = steady.copy()
    buzz[:, 0] += 0.5 * np.sin(2 * np.pi * 25 * t)  # a 25 Hz buzz of +-0.5 N
    r = ripple_and_dropouts(t, buzz, steady, contact)
    assert r['ripple_windows_pct'] == 100.0
    assert r['ripple_windows_ideal_pct'] == 0.0
    drop = steady.copy()
    drop[500:520] = 0.0
    r = ripple_and_dropouts(t, drop, steady, contact)
    assert r['zero_force_ticks'] == 20
    assert r['longest_dropout_ms'] == pytest.approx(20.0)
    r = ripple_and_dropouts(t, drop, steady * 0.1, contact)  # ideal 0.5 N: not a dropout
    assert r['zero_force_ticks'] == 0


def test_spectral_norm_matches_numpy():
    rng = np.random.default_rng(3)
    for _ in range(20):
        A = rng.normal(size=(3, 3))
        K = -(A @ A.T) * 100.0
        assert spectral_norm_sym(K.ravel().tolist()) == pytest.approx(
            np.abs(np.linalg.eigvalsh(K)).max(), rel=1e-9)


def test_an_old_model_is_held_then_expires():
    lp = loop('local_model', max_force_rate=1e6, validity_time=0.05, hold_time=0.3)
    lp.safety.start()
    K = np.diag([-1000.0, 0.0, 0.0])
    v = LocalModel((2.0, 0.0, 0.0), (0.05, 0.0, 0.0), K, (0.055, 0.0, 0.0), (1.0, 0.0, 0.0),
                   (-1.0, 0.0, 0.0), 0.005, False, 0.0).values()
    lp.renderer.offer_values(v, 0.0)
    q = MAP.to_device((0.05, 0.0, 0.0))
    for t in (0.0, 0.001, 0.1, 0.101):  # 100 ms old: past its validity, inside the hold
        pin(lp, q, t)
        f = lp.tick(t)
    assert f[0] == pytest.approx(2.0)
    assert lp.cnt[nt.CNT.held] == 2
    pin(lp, MAP.to_device((0.05, 0.006, 0.0)), 0.102)  # 6 mm away across: beyond the radius
    f = lp.tick(0.102)
    assert int(lp.st[nt.S.status]) != EXPIRED and f[0] == pytest.approx(2.0)
    assert lp.cnt[nt.CNT.beyond] == 1
    for t in np.arange(0.103, 0.32, 0.001):  # past the hold time: expired, watchdog -> 0 N
        pin(lp, q, t)
        f = lp.tick(t)
    assert int(lp.st[nt.S.status]) == EXPIRED
    assert f == (0.0, 0.0, 0.0)


def test_a_held_model_expires_with_the_probe_past_the_hold_radius():
    """Held (past its validity, inside the hold time) only within hold_radius of p0: a probe
    that far away has left the place the model describes. A valid model is rendered there."""
    lp = loop('local_model', max_force_rate=1e6, validity_time=0.05, hold_time=0.3,
              hold_radius=0.02)
    lp.safety.start()
    K = np.diag([-1000.0, 0.0, 0.0])
    v = LocalModel((2.0, 0.0, 0.0), (0.05, 0.0, 0.0), K, (0.055, 0.0, 0.0), (1.0, 0.0, 0.0),
                   (-1.0, 0.0, 0.0), 0.005, False, 0.0).values()
    lp.renderer.offer_values(v, 0.0)
    far = MAP.to_device((0.05, 0.025, 0.0))  # 25 mm across: beyond the 5 mm validity radius too
    for t in (0.0, 0.001, 0.04):  # valid: rendered with the offset across held at 5 mm
        pin(lp, far, t)
        f = lp.tick(t)
    assert int(lp.st[nt.S.status]) != EXPIRED and f[0] == pytest.approx(2.0)
    pin(lp, MAP.to_device((0.05, 0.019, 0.0)), 0.06)  # held, 19 mm: inside the hold radius
    assert lp.tick(0.06)[0] == pytest.approx(2.0) and lp.cnt[nt.CNT.held] == 1
    expired = lp.cnt[nt.CNT.expired]
    pin(lp, far, 0.061)  # held, 25 mm: past it
    lp.tick(0.061)
    assert int(lp.st[nt.S.status]) == EXPIRED and lp.cnt[nt.CNT.expired] == expired + 1
    later = np.arange(0.062, 0.0795, 0.001)
    for t in later:  # the watchdog ramps the held force to zero
        pin(lp, far, t)
        f = lp.tick(t)
    assert f == (0.0, 0.0, 0.0)
    pin(lp, MAP.to_device((0.06, 0.025, 0.0)), 0.08)  # out of the tissue there: free
    assert lp.tick(0.08) == (0.0, 0.0, 0.0) and int(lp.st[nt.S.status]) == FREE
    assert lp.cnt[nt.CNT.expired] == expired + 1 + len(later)  # not counted as expired
    for t in (0.081, 0.082):  # back inside the radius, inside the hold time: rendered again
        pin(lp, MAP.to_device((0.05, 0.0199, 0.0)), t)
        f = lp.tick(t)
    assert int(lp.st[nt.S.status]) == EXTRAPOLATED and f[0] == pytest.approx(2.0)


@pytest.mark.parametrize('damping', [0.0, -1.5, float('nan'), float('inf'), '1.5', True])
def test_a_damping_that_is_not_a_damping_is_refused(damping):
    with pytest.raises(ValueError, match='damping: expected a finite number > 0 N s/m'):
        loop('local_model', damping=damping)


@pytest.mark.parametrize('radius', [0.0, -0.01, float('nan'), float('inf'), '0.03', True])
def test_a_hold_radius_that_is_not_a_distance_is_refused(radius):
    with pytest.raises(ValueError, match='hold_radius: expected a finite number > 0 m'):
        loop('local_model', hold_radius=radius)


@pytest.mark.parametrize('rotating', [False, True])
def test_a_held_model_keeps_the_skew_part_unless_it_rotates(rotating):
    """The skew part of K (the tissue force turning with the probe) is rendered while the model
    is valid; a held one (no newer model for longer than its validity) keeps it only where K has
    no rotating mode, else renders F0 + S e, a passive spring."""
    lp = loop('local_model', max_force_rate=1e6, validity_time=0.05, hold_time=0.3)
    lp.safety.start()
    if rotating:  # w along x, where y and z have no stiffness: the surface plane turned
        K = np.array([[-1000.0, 0.0, 0.0], [0.0, 0.0, -100.0], [0.0, 100.0, 0.0]])
        e = (-0.001, 0.001, 0.0)
        full, sym = (3.0, 0.0, 0.1), (3.0, 0.0, 0.0)
    else:  # Fy grows with the depth: real modes
        K = np.array([[-1000.0, 0.0, 0.0], [200.0, -500.0, 0.0], [0.0, 0.0, 0.0]])
        e = (-0.001, 0.0, 0.0)
        full = sym = (3.0, -0.2, 0.0)
    v = LocalModel((2.0, 0.0, 0.0), (0.05, 0.0, 0.0), K, (0.055, 0.0, 0.0), (1.0, 0.0, 0.0),
                   (-1.0, 0.0, 0.0), 0.005, False, 0.0).values()
    lp.renderer.offer_values(v, 0.0)
    q = MAP.to_device(tuple(np.add((0.05, 0.0, 0.0), e)))
    pin(lp, q, 0.0)
    lp.tick(0.0)
    S = nt.S
    np.testing.assert_allclose(lp.st[S.target0:S.target0 + 3], full, atol=1e-9)
    for t in np.arange(1, 121) * 0.001:  # held after 50 ms
        pin(lp, q, t)
        lp.tick(t)
    assert lp.cnt[nt.CNT.held] == 70
    np.testing.assert_allclose(lp.st[S.target0:S.target0 + 3], sym, atol=1e-9)


def test_passivity_observer_takes_back_energy_the_port_put_out():
    """Hannaford & Ryu: a force pushing along the handle's motion puts energy out; the observer's
    damping takes it back (here all of it: alpha = -E / (T v^2) cancels the 2 N)."""
    for observer, want in ((False, 2.0), (True, 0.0)):
        lp = loop(max_force_rate=1e6, observer=observer)
        lp.safety.start()
        t = 0.0
        for _ in range(3):
            lp.safety.command((2.0, 0.0, 0.0), t, 'tissue')
            pin(lp, (0.0, 0.0, 0.0), t)
            lp.st[nt.S.v0] = 0.1  # moving along +x at 0.1 m/s, as the force pushes
            f = lp.tick(t)
            t += 0.001
        assert f[0] == pytest.approx(want, abs=1e-9)
        assert (lp.cnt[nt.CNT.observer_active] > 0) == observer


@pytest.mark.parametrize('process', [False, True])
def test_loop_runs_on_its_thread_or_process_and_stops_at_zero_force(process):
    """Started for real (thread, or a forked servo process on shared memory): it ticks, takes a
    command, and leaves zero force when stopped. No timing asserted: only that ticks happened."""
    import time
    states = []
    lp = loop(max_force_rate=1e6, process=process, on_state=lambda s, f, t: states.append(f))
    lp.start()
    try:
        end = time.monotonic() + 20.0
        while lp.cnt[nt.CNT.ticks] < 5 and time.monotonic() < end:
            time.sleep(0.01)
        lp.safety.command((1.0, 0.0, 0.0), time.monotonic(), 'tissue')
        t0 = int(lp.cnt[nt.CNT.ticks])
        while lp.cnt[nt.CNT.ticks] < t0 + 3 and time.monotonic() < end:
            time.sleep(0.005)
    finally:
        lp.stop()
    assert lp.cnt[nt.CNT.ticks] >= 5
    assert tuple(lp.st[nt.S.f0:nt.S.f0 + 3]) == (0.0, 0.0, 0.0)
    assert not lp.running
    assert states  # the bridge published ticks


@pytest.mark.parametrize('process', [False, True])
def test_a_refused_priority_is_said_with_rtkits_reason_on_thread_and_process(monkeypatch, process):
    """SCHED_FIFO refused and rtkit refusing too: the loop's scheduling words are the servo
    thread's own, with both reasons and the short-slice fallback, whether the thread is the
    node's or the servo process's (which reports them through shared memory: the parent cannot
    know rtkit's answer). The refusals are faked before the fork, so the child inherits them."""
    import os

    from haptic_anfis.realtime import rtkit
    from haptic_anfis.realtime.rtkit import RealtimeKitError

    def refuse(*_a):
        raise PermissionError(1, 'Operation not permitted')

    def kit_refuses(_priority):
        raise RealtimeKitError('rtkit: refused by polkit (test)')

    monkeypatch.setattr(os, 'sched_setscheduler', refuse)
    monkeypatch.setattr(rtkit, 'make_thread_realtime', kit_refuses)
    lp = loop(process=process, priority=50, workers=1)
    lp.start()
    try:
        words = lp.scheduling
    finally:
        lp.stop()
    assert ('servo process' in words) == process
    assert 'SCHED_FIFO 50 refused (Operation not permitted; rtkit: refused by polkit (test))' \
        in words
    assert 'ulimit -r 50' in words


@pytest.mark.parametrize('process', [False, True])
def test_two_workers_serve_one_schedule_each_on_its_core(process):
    """Two tick workers (threads of the node, or of the servo process) on distinct cores share
    one schedule: every tick is traced once, in time order, and no period is served twice
    (ticks <= span / period + 1, whoever woke first). Counts and order only, no timing."""
    import os
    import time

    from haptic_anfis.realtime.scheduling import worker_cpus
    from haptic_anfis.device.trace import TickTrace
    lp = loop(process=process, trace=TickTrace(), workers=2)
    cpus = worker_cpus(2)
    lp.start()
    try:
        end = time.monotonic() + 20.0
        while lp.cnt[nt.CNT.ticks] < 300 and time.monotonic() < end:
            time.sleep(0.01)
        if process:
            threads = os.listdir(f'/proc/{lp._pid}/task')
            assert len(threads) == len(cpus)  # the workers and nothing else
            tids = [f'/proc/{lp._pid}/task/{t}' for t in threads]
        else:
            assert sorted(min(os.sched_getaffinity(th.native_id)) for th in lp._tick_threads
                          ) == sorted(c for c in cpus if c is not None) or cpus == [None]
            tids = [f'/proc/self/task/{th.native_id}' for th in lp._tick_threads]
        # named for top -H, ps -L and scheduler traces
        assert sorted(Path(t, 'comm').read_text().strip() for t in tids) == [
            f'servo-tick{w}' for w in range(len(cpus))]
    finally:
        lp.stop()
    lp._drain()
    t = lp.trace.arrays()[:, 0]
    ticks = int(lp.cnt[nt.CNT.ticks])
    assert ticks >= 300 and len(t) == ticks
    assert np.all(np.diff(t) > 0)
    assert ticks <= (t[-1] - t[0]) / lp.period + 1 + 1e-9
    assert lp.cnt[nt.CNT.running] == 0 and lp.cnt[nt.CNT.deadline_ns] == 0
    assert tuple(lp.st[nt.S.f0:nt.S.f0 + 3]) == (0.0, 0.0, 0.0)


def worker_arrays(lp) -> list[np.ndarray]:
    """One worker's own copies, as ``run`` gives each: state, counters, the counters at its
    claim, scratch."""
    return [np.empty_like(lp.st), np.empty_like(lp.cnt), np.empty_like(lp.cnt),
            np.empty_like(lp._scratch)]


def test_a_worker_stalled_in_its_tick_is_taken_over_and_its_result_dropped():
    """Two workers' claims and commits played by hand at chosen times (the protocol ``run``
    follows, no threads): worker A claims the tick and stalls before its commit; B, waking within
    the period, leaves it; a period later B takes it over from the committed state and commits;
    A's late commit is dropped. One tick counted, one trace row, the state B's."""
    from haptic_anfis.device.trace import TickTrace
    lp = loop(max_force_rate=1e6, trace=TickTrace())
    lp.safety.start()
    lp.safety.command((2.0, 0.0, 0.0), 0.0, 'tissue')
    C, S = nt.CNT, nt.S
    period = int(lp.period * 1e9 + 0.5)
    t0 = 10 ** 9
    lp.cnt[C.deadline_ns] = t0
    lp.cnt[C.max_gap_ns] = 7_000_000  # a statistics window's maximum, reset below mid-tick
    a, b = worker_arrays(lp), worker_arrays(lp)

    def compute(w, now):
        return nt._compute(now * 1e-9, lp.cfg, w[0], w[1], lp.hand_script, lp.buffers, w[3])

    ok, da, ga = nt._claim(t0, period, lp.ctl, lp.st, lp.cnt, a[0], a[1], a[2])
    assert ok and da == t0
    compute(a, t0)  # ... and A is preempted here
    ok, again, _ = nt._claim(t0 + period // 2, period, lp.ctl, lp.st, lp.cnt, b[0], b[1], b[2])
    assert not ok and again == t0 + period  # being run: B looks again a period on
    lp.cnt[C.max_gap_ns] = 0  # the driver's statistics window restarts meanwhile
    late = t0 + period + 1000
    ok, db, gb = nt._claim(late, period, lp.ctl, lp.st, lp.cnt, b[0], b[1], b[2])
    assert ok and db == late and gb == ga  # taken over, the schedule re-synchronised
    assert lp.cnt[C.taken_over] == 1 and lp.cnt[C.deadline_misses] == 1
    _, *q = compute(b, late)
    assert nt._commit(gb, db, period, lp.st, lp.cnt, b[0], b[1], b[2])
    nt._publish(late * 1e-9, lp.st, lp.cnt, lp.buffers, b[3], 0, *q)
    assert not nt._commit(ga, da, period, lp.st, lp.cnt, a[0], a[1], a[2])  # dropped
    assert lp.st[S.t_prev] == pytest.approx(late * 1e-9)
    assert lp.cnt[C.ticks] == 1 and lp.cnt[C.trace_w] == 1 and lp.cnt[C.gen] == 1
    assert lp.cnt[C.max_gap_ns] == 0  # the window's reset kept
    assert lp.cnt[C.deadline_ns] == late + period and lp.cnt[C.claim_ns] == 0
    assert lp.cnt[C.t_last_ns] == late
    lp._drain()
    assert lp.trace.arrays()[:, 0] == pytest.approx([late * 1e-9])
    # the next period is B's (or A's) as usual
    ok, d, g = nt._claim(late + period, period, lp.ctl, lp.st, lp.cnt, a[0], a[1], a[2])
    assert ok and d == late + period and g == 1 and lp.cnt[C.taken_over] == 1


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 1), st.integers(0, 3000)), min_size=2, max_size=80))
def test_any_order_of_claims_and_commits_keeps_one_tick_per_generation(events):
    """Two workers' steps in any order: each event is a worker's next step (wake and claim, or,
    with a claim pending, commit) and the time to the next event [us] (> 1000: a worker
    preempted mid-tick, its claim taken over). Whatever the order: one tick per commit, the
    committed ticks in time order and traced once each, the state the last commit's, the gaps
    past the watchdog (2 ms here) those between committed ticks."""
    from haptic_anfis.device.trace import TickTrace
    lp = loop(trace=TickTrace(), watchdog_timeout=0.002)
    lp.safety.start()
    C, S = nt.CNT, nt.S
    period = int(lp.period * 1e9 + 0.5)
    work = [worker_arrays(lp) for _ in range(2)]
    pending: list = [None, None]
    committed = []
    t = 10 ** 9
    for who, step_us in events:
        w = work[who]
        if pending[who] is None:
            ok, d, g = nt._claim(t, period, lp.ctl, lp.st, lp.cnt, w[0], w[1], w[2])
            if ok:
                q = nt._compute(t * 1e-9, lp.cfg, w[0], w[1], lp.hand_script, lp.buffers,
                                w[3])[1:]
                pending[who] = (g, d, t, q)
            else:
                assert d > t or lp.cnt[C.claim_ns] == lp.cnt[C.deadline_ns]
        else:
            g, d, t0, q = pending[who]
            pending[who] = None
            if nt._commit(g, d, period, lp.st, lp.cnt, w[0], w[1], w[2]):
                nt._publish(t0 * 1e-9, lp.st, lp.cnt, lp.buffers, w[3], 0, *q)
                committed.append(t0)
        t += step_us * 1000
    n = len(committed)
    assert lp.cnt[C.ticks] == lp.cnt[C.gen] == lp.cnt[C.trace_w] == n
    assert all(b > a for a, b in zip(committed, committed[1:]))
    if n:
        assert lp.st[S.t_prev] == pytest.approx(committed[-1] * 1e-9)
        assert lp.cnt[C.t_last_ns] == committed[-1]
    assert lp.cnt[C.long_gaps] == int(np.sum(np.diff(np.array(committed) * 1e-9) > 0.002))
    lp._drain()
    assert lp.trace.arrays()[:, 0] == pytest.approx(np.array(committed) * 1e-9)


def test_the_first_tick_is_claimed_once():
    """The schedule starts with the first claim: a second worker waking a moment later finds
    that tick claimed, not a new schedule of its own."""
    lp = loop()
    period = int(lp.period * 1e9 + 0.5)
    w = worker_arrays(lp)[:3]
    t0 = 5 * 10 ** 9
    ok, d, _ = nt._claim(t0, period, lp.ctl, lp.st, lp.cnt, *w)
    assert ok and d == t0 and lp.cnt[nt.CNT.deadline_ns] == t0
    ok, again, _ = nt._claim(t0 + 2000, period, lp.ctl, lp.st, lp.cnt, *w)
    assert not ok and again == t0 + period


def test_worker_cores_are_distinct_and_never_more_than_allowed(monkeypatch):
    import os

    from haptic_anfis.realtime.scheduling import worker_cpus
    monkeypatch.setattr(os, 'sched_getaffinity', lambda pid: {0, 1, 2, 3})
    assert worker_cpus(2) == [0, 3]
    assert worker_cpus(4) == [0, 3, 1, 2]
    assert worker_cpus(8) == [0, 3, 1, 2]
    assert worker_cpus(1) == [None]
    monkeypatch.setattr(os, 'sched_getaffinity', lambda pid: {5})
    assert worker_cpus(2) == [None]  # one core: one unpinned worker
    with pytest.raises(ValueError, match='workers: expected an integer from 1 to 8, got 0'):
        loop(workers=0)


def test_an_external_script_is_played_through_the_hand_buffer():
    """exam run swaps in a script only Python can play: the bridge feeds its target (plain float
    times: a numpy time once leaked into the exam report as a numpy bool) and the tick follows."""
    seen = []

    class Script:
        def target(self, t):
            seen.append(type(t))
            return (0.06, 0.02, 0.0)

        def buttons(self, t):
            return (0, 1)

    lp = loop()
    lp.tick(0.0)
    lp.script = Script()
    lp._feed_hand()
    assert seen and all(t is float for t in seen)
    assert lp.ctl[nt.CTL.external] == 1
    t_feed = lp.hand[1]
    for i in range(1, 2000):
        lp.tick(t_feed + i * 0.001)
    # the hand pulled the handle to the target (y = 0.02 m tissue = 0.0133 m device)
    assert lp.st[nt.S.x1] == pytest.approx(0.02 / 1.5, abs=2e-3)
    assert lp.last_out is not None and lp.cnt[nt.CNT.marks] == 1  # button 1 pressed once


def test_auto_servo_loop_is_the_servo_process_for_both_backends():
    from haptic_anfis.nodes.falcon_params import resolve_servo_loop
    from haptic_anfis.nodes.parameters import ParameterError
    assert resolve_servo_loop('auto') == 'native_process'
    assert resolve_servo_loop('auto', 'falcon') == 'native_process'
    for choice in ('native', 'native_process'):
        assert resolve_servo_loop(choice) == choice
    with pytest.raises(ParameterError, match="servo_loop: got 'native' with backend 'falcon'"):
        resolve_servo_loop('native', 'falcon')


def test_ticks_with_the_safety_layer_off_are_traced_as_disabled():
    """Before start and at shutdown the device gets 0 N on purpose: the trace says so, so the
    force error and the dropout count leave those ticks out (a run stopped mid-press counted
    its last tick as a dropout)."""
    from haptic_anfis.device.trace import DISABLED, TickTrace
    lp = loop('local_model', max_force_rate=1e6, validity_time=1.0, trace=TickTrace())
    v = LocalModel((2.0, 0.0, 0.0), (0.05, 0.0, 0.0), np.diag([-1000.0, 0.0, 0.0]),
                   (0.055, 0.0, 0.0), (1.0, 0.0, 0.0), (-1.0, 0.0, 0.0), 0.005, False,
                   0.0).values()
    lp.renderer.offer_values(v, 0.0)
    q = MAP.to_device((0.05, 0.0, 0.0))
    forces = []
    for t, on in ((0.0, False), (0.001, True), (0.002, True), (0.003, False)):
        if on and not lp.safety.enabled:
            lp.safety.start()
        if not on and lp.safety.enabled:
            lp.safety.stop()
        pin(lp, q, t)
        forces.append(lp.tick(t)[0])
    lp._drain()
    rows = lp.trace.arrays()
    assert forces[0] == forces[3] == 0.0 and forces[2] == pytest.approx(2.0)
    assert list(rows[:, 7]) == [DISABLED, FRESH, EXTRAPOLATED, DISABLED]


def press_model(f0: float, t0: float, contact: bool = True) -> list:
    """A model 5 mm into a wall along -x at x = 0.055 m: F0 = ``f0`` N along x, 1000 N/m (not
    ``contact``: a model that says the probe is free)."""
    if not contact:
        return LocalModel((0.0, 0.0, 0.0), (0.05, 0.0, 0.0), np.zeros((3, 3)), (0.0, 0.0, 0.0),
                          (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0, False, t0).values()
    return LocalModel((f0, 0.0, 0.0), (0.05, 0.0, 0.0), np.diag([-1000.0, 0.0, 0.0]),
                      (0.055, 0.0, 0.0), (1.0, 0.0, 0.0), (-1.0, 0.0, 0.0), 0.005, False,
                      t0).values()


def fade_run(blend_time: float, switch_at: float, later: float | None = None,
             until: float = 0.08) -> list:
    """The target force along x [N] at each tick of a probe held still: a 2 N model from t = 0,
    a 3 N one offered at ``switch_at`` (made then), and (``later``) a model of ``later`` N
    offered anew at every tick after it, each made at its tick (models on time)."""
    lp = loop('local_model', max_force_rate=1e6, blend_time=blend_time, hold_time=1.0)
    lp.safety.start()
    q = MAP.to_device((0.05, 0.0, 0.0))
    lp.renderer.offer_values(press_model(2.0, 0.0), 0.0)
    out = []
    for t in np.arange(0.0, until, 0.001):
        if abs(t - switch_at) < 1e-9:
            lp.renderer.offer_values(press_model(3.0, t), t)
        elif later is not None and t > switch_at:
            lp.renderer.offer_values(press_model(later, t), t)
        pin(lp, q, t)
        lp.tick(t)
        out.append(lp.st[nt.S.target0])
    return out


@pytest.mark.parametrize('blend_time, switch_at', [(0.0, 0.03), (0.01, 0.03), (0.05, 0.03),
                                                   (0.05, 0.001)])
def test_the_step_to_a_late_model_is_ramped_out_over_the_old_models_age(blend_time, switch_at):
    """A new model that disagrees with the old one at the probe (2 N -> 3 N): 0.05 N of the
    step is taken at once, the rest ramped out over tau, the old model's age at the switch, at
    most blend_time (0: all at once); a model a tick old is taken within a few ticks."""
    f = fade_run(blend_time, switch_at)
    tau = min(switch_at, blend_time)
    k = round(switch_at * 1e3)
    assert f[:k] == pytest.approx([2.0] * k)
    if not tau:
        assert f[k:] == pytest.approx([3.0] * (len(f) - k))
        return
    assert f[k] == pytest.approx(2.05)   # the deadband at once, the rest left to fade
    assert 3.0 - f[k + 1] == pytest.approx(0.95 * np.exp(-0.001 / tau))
    for i in range(k, len(f)):   # never past the new force; no slower than exp(-t / tau)
        assert 0.0 <= 3.0 - f[i] <= 0.95 * np.exp(-(i - k) * 1e-3 / tau) + 1e-12
    end = k + round(tau * 1e3) + 5   # a ramp over tau, and a tail of a few ticks
    assert f[end] == pytest.approx(3.0, abs=1e-3)
    if tau >= 0.01:   # a ramp, not a step: a third of the way in, most of it is still left
        assert 3.0 - f[k + round(tau * 1e3 / 3)] > 0.5


def test_a_model_on_time_after_a_late_one_does_not_cut_its_fade_short():
    """Models on time right after a late one (3.1 N: another step, 1 ms old) keep the late
    one's 30 ms ramp: the fade runs for the longer of the two times."""
    f = fade_run(0.05, 0.03, later=3.1)
    assert 3.1 - f[40] > 0.5   # 10 ms after the late switch, most of its 0.95 N still fading
    assert abs(3.1 - f[79]) < 0.05   # 50 ms after it: ramped out


def test_only_the_models_disagreement_is_faded_not_the_probes_motion():
    """The same model offered anew renders what it did: the probe's motion (the stiffness) is
    rendered at once, the fade holds nothing; two models that agree leave no offset."""
    lp = loop('local_model', max_force_rate=1e6, blend_time=0.02)
    lp.safety.start()
    for i, t in enumerate(np.arange(0.0, 0.02, 0.001)):
        lp.renderer.offer_values(press_model(2.0, t), t)   # a new model every tick
        x = 0.05 - 0.0001 * i   # 0.1 mm deeper every tick: 0.1 N more
        pin(lp, MAP.to_device((x, 0.0, 0.0)), t)
        lp.tick(t)
        assert lp.st[nt.S.target0] == pytest.approx(2.0 + 1000.0 * (0.05 - x), abs=1e-9)
    assert np.all(lp.st[nt.S.bl0:nt.S.bl0 + 3] == 0.0)


@pytest.mark.parametrize('release', ['free', 'expired', 'fault'])
def test_a_release_or_a_fault_drops_the_fade(release):
    """A new model that says free renders zero at once, an expired one leaves the force to the
    watchdog, and a fault zeroes it, as without the fade; the next press starts with no
    offset (the 2 N -> 4 N step before it was 30 ms late: a 20 ms fade)."""
    lp = loop('local_model', max_force_rate=1e6, blend_time=0.02, validity_time=0.01,
              hold_time=0.05)
    lp.safety.start()
    q = MAP.to_device((0.05, 0.0, 0.0))
    lp.renderer.offer_values(press_model(2.0, 0.0), 0.0)
    for t in np.arange(0.0, 0.03, 0.001):
        pin(lp, q, t)
        lp.tick(t)
    lp.renderer.offer_values(press_model(4.0, 0.03), 0.03)
    pin(lp, q, 0.03)
    lp.tick(0.03)
    assert lp.st[nt.S.target0] == pytest.approx(2.05)   # fading: 1.95 N left
    if release == 'free':
        lp.renderer.offer_values(press_model(4.0, 0.031, contact=False), 0.031)
        pin(lp, q, 0.031)
        lp.tick(0.031)
        assert lp.st[nt.S.target0] == 0.0 and int(lp.st[nt.S.status]) == FREE
        t_next = 0.032
    elif release == 'expired':
        for t in np.arange(0.031, 0.0815, 0.001):   # the 4 N model expires at 80 ms
            pin(lp, q, t)
            lp.tick(t)
        assert int(lp.st[nt.S.status]) == EXPIRED
        t_next = 0.082
    else:
        lp.safety.reject('a NaN pose')
        t_next = 0.031
    if release != 'fault':
        assert np.all(lp.st[nt.S.bl0:nt.S.bl_tau + 1] == 0.0)
    lp.renderer.offer_values(press_model(3.0, t_next), t_next)   # the fault: the same tick
    pin(lp, q, t_next)
    lp.tick(t_next)
    assert np.all(lp.st[nt.S.bl0:nt.S.bl_tau + 1] == 0.0)
    assert lp.st[nt.S.target0] == pytest.approx(3.0)   # no fade from before


@pytest.mark.parametrize('blend_time', [-0.01, float('nan'), float('inf'), '0.02', True])
def test_a_blend_time_that_is_not_a_time_is_refused(blend_time):
    with pytest.raises(ValueError, match='blend_time: expected a finite number >= 0 s'):
        loop('local_model', blend_time=blend_time)


def test_gaps_past_the_watchdog_are_counted_and_restart_with_the_window():
    """The compiled tick counts gaps between ticks longer than the watchdog time (the driver's
    live check, device/loop_health.py), as LoopStats does; a stats reset starts them again."""
    lp = loop(watchdog_timeout=0.01)
    lp.safety.start()
    t = 0.0
    for g in (0.001, 0.001, 0.015, 0.001, 0.0101, 0.001, 0.0099):
        lp.tick(t)
        t += g
    lp.tick(t)
    assert lp.stats.summary()['gaps_past_watchdog'] == 2
    assert int(lp.cnt[nt.CNT.long_gaps]) == 2
    lp.stats.reset()
    lp.tick(t + 0.02)
    assert lp.stats.summary()['gaps_past_watchdog'] == 1


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_the_ticks_clutch_and_mark_follow_the_python_rules(seed):
    """Grip buttons held for random spells, a wandering hand and forces on and off through the
    compiled tick's clutch and gain and through the Python rules (tick_oracle.ClutchMark): the
    same tissue position, gain, clutches and marks at every tick."""
    rng = np.random.default_rng(seed)
    ramp = 0.005
    cm = ClutchMark(ramp_s=ramp)
    cfg = np.zeros(nt.CFG_LEN)
    cfg[nt.CFG.ramp] = ramp
    st, cnt = nt.new_state(), np.zeros(nt.CNT_LEN, dtype=np.int64)
    buttons, pressing, mapped = [0, 0], False, np.zeros(3)
    gains = set()
    for i in range(4000):
        now = i * 0.001
        for b in range(2):
            if rng.random() < 0.02:
                buttons[b] ^= 1
        if rng.random() < 0.01:
            pressing = not pressing
        mapped = mapped + rng.normal(scale=2e-4, size=3)
        force = (1.5, 0.0, -0.5) if pressing else (0.0, 0.0, 0.0)
        q = nt._clutch(st, cnt, buttons[0], buttons[1], *mapped)
        want, _ = cm.update(tuple(buttons), tuple(mapped), now)
        assert q == pytest.approx(want, abs=1e-15), i
        g = nt._gain(cfg, st, pressing, now)
        assert g == cm.gain(force, now), i
        gains.add(round(g, 3))
    assert (cnt[nt.CNT.clutches], cnt[nt.CNT.marks]) == (cm.clutches, cm.marks)
    assert cm.clutches > 5 and cm.marks > 5 and {0.0, 1.0} < gains  # every branch was taken


def test_a_malformed_model_through_the_drivers_input_is_counted_and_zeroes_the_force():
    """The driver's force input over the compiled loop: a model the tick would press with, then
    one with a value missing: refused in one line, counted as a rejected model and a non-finite
    input, and the next tick applies no force."""
    lp, x = wall_loop()
    fi = ForceInput(lp.safety, MAP, lp.renderer)
    for t in (0.0, 0.001, 0.002):  # the first tick takes the enable: zero, then the wall's
        pin(lp, x, t)
        f = lp.tick(t)
    assert f[0] > 1.0
    why = fi.model_values([0.0] * 25, 1, 'tissue', 0.0025)
    assert why == 'rejected: local model: expected 26 values, got 25'
    assert fi.summary()['models_rejected'] == 1 and lp.safety.stats.rejected_nonfinite == 1
    pin(lp, x, 0.003)
    assert lp.tick(0.003) == (0.0, 0.0, 0.0)


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_the_ticks_safety_rules_follow_the_python_rules(seed):
    """Commands at random times (over the clamp, non-finite, in a wrong frame, out of order)
    and ticks with jitter and stalls past the watchdog, through the compiled tick (zoh) and the
    Python rules (tick_oracle.SafetyLayer): the same force at every tick."""
    rng = np.random.default_rng(seed)
    lp = loop('zoh', max_force=5.0, max_force_rate=1000.0, watchdog_timeout=0.01)
    ref = SafetyLayer(5.0, 1000.0, 0.01, frame_id='tissue')
    t = 1.0
    lp.safety.start()
    lp.tick(t)  # takes the enable: zero force, the watchdog counts from here
    ref.start(t)
    seen = set()
    for i in range(3000):
        gap = 0.001 * (1.0 + 0.2 * rng.random()) if rng.random() > 0.005 else 0.02
        if rng.random() < 0.5:  # one command between two ticks
            tc = t + rng.random() * gap
            f, frame, kind = tuple(rng.normal(scale=3.0, size=3)), 'tissue', 'ok'
            u = rng.random()
            if u < 0.01:
                f, kind = (math.nan, 0.0, 1.0), 'nan'
            elif u < 0.02:
                frame, kind = 'world', 'frame'
            elif u < 0.04:
                tc, kind = tc - 0.05, 'older'
            seen.add(kind)
            assert lp.safety.command(f, tc, frame) == ref.command(f, tc, frame) or kind == 'older'
        t += gap
        got, want = lp.tick(t), ref.output(t)
        assert got == pytest.approx(want, abs=1e-9), i
        seen.add('clamped' if math.hypot(*want) > 4.999 else 'zero' if want == (0, 0, 0) else '')
    assert seen >= {'ok', 'nan', 'frame', 'older', 'clamped', 'zero'}
    assert lp.safety.stats.watchdog_trips == ref.stats.watchdog_trips > 0


def _constant_model(f: float, at=(0.06, 0.0, 0.0)):
    """A local model pushing ``f`` [N] along +x at ``at`` (tissue frame), no stiffness: the same
    force wherever the probe is within the model's radius."""
    return LocalModel((f, 0.0, 0.0), at, np.zeros((3, 3)), (at[0] + 0.005, at[1], at[2]),
                      (1.0, 0.0, 0.0), (-1.0, 0.0, 0.0), 0.005, False, 0.0).values()


def test_a_force_scale_set_while_running_is_rendered_from_the_next_tick():
    """A case switched live brings its own force scale: the next tick renders the same tissue
    force times the new scale, and the stiffness bound follows it."""
    from haptic_anfis.device.local_model import FALCON_MAX_STIFFNESS
    lp = loop('local_model', max_force_rate=1e6, validity_time=10.0, hold_time=20.0)
    lp.safety.start()
    lp.renderer.offer_values(_constant_model(2.0), 0.0)
    pin(lp, MAP.to_device((0.06, 0.0, 0.0)), 0.0)
    lp.tick(0.0)
    assert lp.tick(0.001)[0] == pytest.approx(2.0)   # force_scale 1
    m = lp.set_force_scale(0.4, FALCON_MAX_STIFFNESS)
    assert m.force_scale == lp.mapping.force_scale == 0.4 and m.scale == MAP.scale
    assert lp.tick(0.002)[0] == pytest.approx(0.8)
    want = tissue_stiffness_limit(FALCON_MAX_STIFFNESS, 0.4, MAP.scale)
    assert lp.renderer.max_stiffness == pytest.approx(want)
    assert lp.cfg[nt.CFG.max_stiffness] == pytest.approx(want)
    with pytest.raises(ValueError, match='force_scale'):
        lp.set_force_scale(0.0, FALCON_MAX_STIFFNESS)
    assert lp.mapping.force_scale == 0.4


def test_a_force_scale_set_while_running_reaches_the_servo_process():
    """The servo process reads its configuration from memory it shares with the driver: a
    scale set in the driver's process is the one the forked tick renders."""
    import time
    from haptic_anfis.device.local_model import FALCON_MAX_STIFFNESS
    lp = loop('local_model', max_force_rate=1e6, validity_time=60.0, hold_time=60.0,
              process=True)
    lp.safety.start()
    lp.start()
    try:
        def rendered(f, timeout=20.0):
            end = time.monotonic() + timeout
            while time.monotonic() < end:
                lp.renderer.offer_values(_constant_model(2.0), time.monotonic())
                time.sleep(0.01)
                if lp.force[0] == pytest.approx(f, abs=1e-6):
                    return True
            return False
        assert rendered(2.0)
        lp.set_force_scale(0.25, FALCON_MAX_STIFFNESS)
        assert rendered(0.5)
    finally:
        lp.stop()
