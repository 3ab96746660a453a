"""The local force model (device/local_model.py), the stamp book (device/stamps.py) and the
driver's force input (device/force_input.py): exactness, guards, and issue 22's stall-and-kill."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as hst

from haptic_anfis.device import DeviceState, WorkspaceMapping
from haptic_anfis.device.force_input import ForceInput
from haptic_anfis.device.local_model import (EXPIRED, EXTRAPOLATED, FREE, FRESH, NONE,
                                             across_beyond, hold_offset,
                                             LocalModel, condition_stiffness,
                                             condition_stiffness_values, contact_jacobian,
                                             rotating_mode,
                                             depth_gradient)
from haptic_anfis.device.stamps import FUTURE, OK, STALE, UNKNOWN, StampBook
from haptic_anfis.device.trace import TickTrace, load_trace, save_trace
from tick_oracle import LocalModelRenderer, SafetyLayer, ServoLoop, render


def unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def spd_neg(rng, scale=500.0):
    A = rng.normal(size=(3, 3))
    return -(A @ A.T) / np.linalg.norm(A @ A.T) * scale  # symmetric negative-semidefinite


def make(f0, p0, K, c0, n, d, depth0, zero=False, t=0.0):
    return LocalModel(tuple(f0), tuple(p0), np.asarray(K), tuple(c0), tuple(n), tuple(d),
                      float(depth0), zero, t)


def geometry(rng):
    """A contact: surface point c0, outward normal n, direction d into the tissue, depth0, p0."""
    n = unit(rng.normal(size=3))
    d = unit(-n + 0.4 * rng.normal(size=3))
    if n @ d > -0.5:
        d = -n
    c0 = rng.normal(size=3) * 0.02
    depth0 = 0.004
    return c0, n, d, depth0, c0 + depth0 * d


@pytest.mark.parametrize('seed', range(5))
def test_exact_for_a_linear_field(seed):
    rng = np.random.default_rng(seed)
    c0, n, d, depth0, p0 = geometry(rng)
    K = spd_neg(rng)
    F0 = rng.normal(size=3)
    r = LocalModelRenderer(max_stiffness=1e4, validity_time=1.0, validity_radius=0.01)
    r.offer(make(F0, p0, K, c0, n, d, depth0))
    g = depth_gradient(n, d)
    for _ in range(50):
        p = p0 + rng.normal(size=3) * 0.002
        f, st = r.render(tuple(p), 0.0)
        if depth0 + g @ (p - p0) <= 0:
            assert st == FREE and f == (0.0, 0.0, 0.0)
        else:
            assert st == FRESH
            np.testing.assert_allclose(f, F0 + K @ (p - p0), rtol=0, atol=1e-12)


@pytest.mark.parametrize('seed', range(5))
def test_exact_for_a_linear_field_zero_on_the_surface(seed):
    """A field zero on the tangent plane (F = a * depth, K = a g^T symmetric when a || g):
    the onset correction changes nothing."""
    rng = np.random.default_rng(seed)
    c0, n, _, depth0, _ = geometry(rng)
    d = -n  # normal mode: K = -k n n^T is symmetric negative-semidefinite
    p0 = c0 + depth0 * d
    k = 800.0
    field = lambda p: k * (-(p - c0) @ n) * n  # noqa: E731
    K = -k * np.outer(n, n)
    r = LocalModelRenderer(max_stiffness=1e4, validity_time=1.0, validity_radius=0.01)
    r.offer(make(field(p0), p0, K, c0, n, d, depth0, zero=True))
    for _ in range(50):
        p = p0 + rng.normal(size=3) * 0.003
        f, st = r.render(tuple(p), 0.0)
        if -(p - c0) @ n > 0:
            np.testing.assert_allclose(f, field(p), rtol=0, atol=1e-12)


def test_no_step_at_contact_onset():
    """Force ~ depth^1.5 (zero at the surface, stiffening): the tangent model alone gives a pull
    at depth 0; with the onset correction the force goes continuously to zero and keeps the
    tangent stiffness at depth0."""
    n = np.array([1.0, 0.0, 0.0])
    d = -n
    c0 = np.zeros(3)
    a = 2e3
    F = lambda dep: a * dep ** 1.5 * n  # noqa: E731
    depth0 = 0.005
    p0 = c0 + depth0 * d
    K = -1.5 * a * depth0 ** 0.5 * np.outer(n, n)
    r = LocalModelRenderer(max_stiffness=1e5, validity_time=1.0, validity_radius=0.02)
    r.offer(make(F(depth0), p0, K, c0, n, d, depth0, zero=True))
    plain = F(depth0) + K @ (c0 - p0)
    assert plain[0] < -0.1  # the uncorrected model would pull at the surface
    forces = [r.render(tuple(c0 + dep * d + [0, 0.001, 0]), 0.0)[0][0]
              for dep in np.linspace(1e-6, depth0, 200)]
    assert abs(forces[0]) < 1e-3 and min(forces) >= -1e-9
    assert np.all(np.diff(forces) > 0)  # monotonic: no step, no pull
    # tangent kept at depth0: one-sided slope matches K
    h = 1e-7
    f1 = r.render(tuple(p0 - h * d), 0.0)[0][0]
    f2 = r.render(tuple(p0), 0.0)[0][0]
    assert (f2 - f1) / h == pytest.approx(1.5 * a * depth0 ** 0.5, rel=1e-3)
    assert r.render(tuple(c0 - 1e-6 * d), 0.0) == ((0.0, 0.0, 0.0), FREE)


def test_stiffness_guard():
    rng = np.random.default_rng(0)
    A = rng.normal(size=(3, 3)) * 5e3  # asymmetric, indefinite, too stiff
    K = condition_stiffness(A, 3000.0)
    w = np.linalg.eigvalsh(0.5 * (K + K.T))
    assert w.min() >= -3000.0 - 1e-6 and w.max() <= 1e-9
    # the skew part is A's, its |w| (A e = w x e) bounded to 3000 N/m
    skew = 0.5 * (A - A.T)
    np.testing.assert_allclose(0.5 * (K - K.T), skew, atol=1e-9)  # |w| 2290 N/m: kept
    K2 = condition_stiffness(2 * A, 3000.0)
    np.testing.assert_allclose(0.5 * (K2 - K2.T), skew * 3000.0 / skew_norm(skew), atol=1e-9)
    # a conforming symmetric part with a skew part within the bound passes unchanged
    S = spd_neg(rng, 1000.0)
    W = 0.1 * skew
    out, changed = condition_stiffness_values((S + W).ravel().tolist(), 3000.0)
    np.testing.assert_allclose(np.reshape(out, (3, 3)), S + W, atol=1e-9)
    assert not changed
    # a conforming K passes unchanged
    S = spd_neg(rng, 1000.0)
    np.testing.assert_allclose(condition_stiffness(S, 3000.0), S, atol=1e-9)
    # positive (pulling) stiffness becomes 0
    np.testing.assert_allclose(condition_stiffness(np.eye(3) * 100.0, 3000.0), 0.0, atol=1e-12)
    for bad in (np.full((3, 3), np.nan), np.diag([np.inf, 1.0, 1.0]), np.eye(2)):
        with pytest.raises(ValueError, match='stiffness K'):
            condition_stiffness(bad, 3000.0)
    r = LocalModelRenderer(max_stiffness=2000.0)
    n = np.array([1.0, 0, 0])
    r.offer(make((1, 0, 0), (-0.001, 0, 0), -1e5 * np.eye(3), (0, 0, 0), n, -n, 0.001))
    assert r.stats.stiffness_clamped == 1
    f, _ = r.render((-0.002, 0, 0), 0.0)
    assert f[0] == pytest.approx(1.0 + 2000.0 * 0.001)


def skew_norm(A) -> float:
    """|w| of the skew-symmetric A (A e = w x e): its spectral norm."""
    return float(np.linalg.norm([A[2, 1], A[0, 2], A[1, 0]]))


def eigh_reference(K, kmax):
    """The guard by numpy's eigh: symmetrise, clip the eigenvalues to [-kmax, 0], rebuild; add
    the skew part back, scaled to a spectral norm of at most kmax."""
    S = 0.5 * (K + K.T)
    w, V = np.linalg.eigh(S)
    A = 0.5 * (K - K.T)
    a = skew_norm(A)
    return (V * np.clip(w, -kmax, 0.0)) @ V.T + (A * min(1.0, kmax / a) if a > 0 else A)


def rotation(rng):
    Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return Q


def hard_stiffnesses(seed):
    """Random and degenerate K [N/m]: indefinite, too stiff, repeated / zero eigenvalues,
    diagonal, isotropic, rank one, nearly equal eigenvalues, tiny and huge scales."""
    rng = np.random.default_rng(seed)
    Q = rotation(rng)
    s = 10.0 ** rng.uniform(-3, 6)
    a, b, c = rng.uniform(-2, 1, 3) * s
    yield rng.normal(size=(3, 3)) * s                      # asymmetric, indefinite
    yield Q @ np.diag([a, a, b]) @ Q.T                      # a double eigenvalue
    yield Q @ np.diag([a, b, b]) @ Q.T
    yield Q @ np.diag([a, a, a]) @ Q.T                      # isotropic, rotated (rounding)
    yield np.diag([a, b, c])                                # diagonal: no off-diagonal terms
    yield a * np.eye(3)
    yield np.zeros((3, 3))
    v = rng.normal(size=3)
    yield a * np.outer(v, v)                                # rank one
    yield Q @ np.diag([a, a * (1 + 1e-9), a * (1 - 1e-9)]) @ Q.T  # nearly equal
    yield Q @ np.diag([a, b, c]) @ Q.T + 1e-12 * s * rng.normal(size=(3, 3))
    yield -np.outer([1.0, 0, 0], [1.0, 0, 0]) * 1e5         # one axis far too stiff


@pytest.mark.parametrize('seed', range(40))
def test_closed_form_guard_matches_eigh(seed):
    """The driver's closed-form guard (no numpy) gives numpy eigh's answer on random and
    degenerate stiffnesses, and says when it changed K."""
    kmax = 3000.0
    for K in hard_stiffnesses(seed):
        ref = eigh_reference(K, kmax)
        out, changed = condition_stiffness_values(K.ravel().tolist(), kmax)
        got = np.array(out).reshape(3, 3)
        scale = max(1.0, np.abs(K).max())
        np.testing.assert_allclose(got, ref, atol=1e-9 * scale, rtol=0)
        w = np.linalg.eigvalsh(0.5 * (got + got.T))
        assert w.max() <= 1e-9 * scale and w.min() >= -kmax - 1e-9 * scale
        e = np.random.default_rng(seed).normal(size=(20, 3))  # no displacement gains force along it
        assert np.all(np.einsum('ij,jk,ik->i', e, got, e) <= 1e-9 * scale * np.sum(e * e, 1))
        diff = np.abs(ref - K).max()
        if abs(diff - 1e-6) > 1e-8 * scale:  # not on the counting threshold itself
            assert changed == (diff > 1e-6)


def test_closed_form_guard_leaves_a_conforming_k_exactly():
    rng = np.random.default_rng(7)
    for _ in range(100):
        S = spd_neg(rng, rng.uniform(10.0, 2900.0))
        S = 0.5 * (S + S.T)
        if np.linalg.eigvalsh(S).max() > -1e-3:  # too close to the boundary for "exactly"
            continue
        out, changed = condition_stiffness_values(S.ravel().tolist(), 3000.0)
        assert out == tuple(S.ravel().tolist()) and not changed


@pytest.mark.parametrize('field', ['f0', 'p0', 'k', 'normal'])
def test_non_finite_model_rejected(field):
    n = np.array([1.0, 0, 0])
    kw = dict(f0=(1, 0, 0), p0=(-0.001, 0, 0), k=-np.eye(3), contact=(0, 0, 0), normal=tuple(n),
              direction=tuple(-n), depth0=0.001, zero_at_surface=False, time=0.0)
    kw[field] = np.full((3, 3), np.nan) if field == 'k' else (np.nan, 0.0, 0.0)
    r = LocalModelRenderer()
    with pytest.raises(ValueError, match='local model'):
        r.offer(LocalModel(**kw))
    assert r.stats.rejected == 1 and r.render((0, 0, 0), 0.0) == (None, NONE)


def test_expiry_by_time_beyond_the_radius_and_leaving_contact():
    n = np.array([1.0, 0, 0])
    r = LocalModelRenderer(validity_time=0.05, validity_radius=0.005, fresh_age=0.0015)
    K = np.diag([-500.0, -100.0, -100.0])
    r.offer(make((2, 0, 0), (-0.004, 0, 0), K, (0, 0, 0), n, -n, 0.004, t=1.0))
    assert r.render((-0.004, 0, 0), 1.001)[1] == FRESH
    assert r.render((-0.004, 0, 0), 1.02)[1] == EXTRAPOLATED
    assert r.render((-0.004, 0, 0), 1.0501) == (None, EXPIRED)
    # beyond the radius across the normal: rendered, the offset across held at 5 mm
    f, st = r.render((-0.004, 0.008, 0), 1.01)
    assert st == EXTRAPOLATED and f == pytest.approx((2.0, -0.5, 0.0))
    # beyond it along the normal (a deep press on a late model): the depth followed exactly
    f, st = r.render((-0.010, 0.001, 0), 1.01)
    assert st == EXTRAPOLATED and f == pytest.approx((2.0 + 500 * 0.006, -0.1, 0.0))
    # out along the normal: zero at once, even beyond the radius
    assert r.render((0.0001, 0, 0), 1.01) == ((0.0, 0.0, 0.0), FREE)
    assert r.render((0.02, 0, 0), 1.01) == ((0.0, 0.0, 0.0), FREE)
    s = r.stats
    assert (s.ticks_fresh, s.ticks_extrapolated, s.ticks_expired, s.ticks_free) == (1, 3, 1, 2)
    assert s.ticks_beyond == 2


@settings(max_examples=300, deadline=None)
@given(g=hst.tuples(*[hst.floats(-2, 2)] * 3), e=hst.tuples(*[hst.floats(-0.05, 0.05)] * 3),
       r=hst.floats(1e-4, 0.02))
def test_hold_offset_keeps_the_depth_and_holds_the_offset_across(g, e, r):
    """The depth g . e is kept; the part across g is at most r and points the same way; inside
    the radius nothing changes; a zero gradient (no direction) holds the whole offset."""
    h = np.array(hold_offset(*g, *e, r))
    g, e = np.array(g), np.array(e)
    assert np.all(np.isfinite(h))
    gg = g @ g
    if gg > 1e-12:
        assert h @ g == pytest.approx(e @ g, abs=1e-12)
        across = lambda v: v - (v @ g) / gg * g  # noqa: E731
    else:
        across = lambda v: v  # noqa: E731
    assert np.linalg.norm(across(h)) <= r * (1 + 1e-9)
    if np.linalg.norm(across(e)) <= r:
        assert np.allclose(h, e, atol=1e-15)
    else:
        assert across(h) @ across(e) >= 0.0


@pytest.mark.parametrize('seed', range(4))
@pytest.mark.parametrize('normal_mode', [False, True])
def test_contact_jacobian_through_the_geometry(seed, normal_mode):
    """K from J through a planar surface equals the finite-difference derivative of
    p -> F(c(p), depth(p)) computed geometrically (ray along d back to the plane)."""
    rng = np.random.default_rng(seed)
    c0, n, d, depth0, p0 = geometry(rng)
    if normal_mode:
        d = -n
        p0 = c0 + depth0 * d
    W = rng.normal(size=(3, 4))
    model = lambda x: np.tanh(W @ x) + 0.3 * (W @ x) ** 2  # noqa: E731  a nonlinear F(x, y, z, depth)

    def composed(p):
        t = ((p - c0) @ n) / (d @ n)  # distance along d from the plane (the depth)
        c = p - t * d
        return model(np.array([*c, t]))

    x0 = np.array([*c0, depth0])
    h = 1e-6
    J = np.stack([(model(x0 + h * e) - model(x0 - h * e)) / (2 * h) for e in np.eye(4)], axis=1)
    Kfd = np.stack([(composed(p0 + h * e) - composed(p0 - h * e)) / (2 * h) for e in np.eye(3)],
                   axis=1)
    np.testing.assert_allclose(contact_jacobian(J, n, d), Kfd, rtol=1e-5, atol=1e-6)


def test_stamp_book():
    b = StampBook(size=4)
    for i in range(6):
        b.record(1000 + i, 10.0 + i * 0.001)
    assert b.check(1005, 10.006, 0.01) == (OK, pytest.approx(10.005))
    assert b.check(1002, 10.006, 0.01)[0] == OK
    assert b.check(1001, 10.006, 0.01)[0] == UNKNOWN  # evicted
    assert b.check(1007, 10.006, 0.01)[0] == FUTURE
    assert b.check(1003, 10.02, 0.01)[0] == STALE
    assert b.check(7, 10.0, 0.01)[0] == UNKNOWN
    s = b.stats
    assert (s.rejected_unknown, s.rejected_future, s.rejected_stale) == (2, 1, 1)


class StillDevice:
    """A device held at one position (the hand pressing), recording what it is told."""
    max_force = 10.0

    def __init__(self, p):
        self.p, self.forces = tuple(p), []

    def open(self, now):
        pass

    def read(self, now):
        return DeviceState(self.p, (0.0, 0.0, 0.0), ())

    def write(self, f):
        self.forces.append(f)

    def close(self):
        pass


@pytest.mark.parametrize('mode', ['zoh', 'local_model'])
def test_stall_and_kill(mode):
    """Issue 22: the driver applies 9.5 N, is paused (no servo tick) for 1 s during which the
    force server sends commands answering its old poses and dies; on resume the queued commands
    arrive. No force above 0.05 N after the resume."""
    mapping = WorkspaceMapping(1.0, (0.0, 0.0, 0.0), 1.0)
    safety = SafetyLayer(10.0, 1000.0, 0.010, frame_id='tissue')
    fi = ForceInput(safety, mapping, LocalModelRenderer(3000.0, validity_time=0.05), mode=mode)
    p = np.array([-0.004, 0.0, 0.0])
    dev = StillDevice(p)
    clock = [0.0]
    stamps: list[int] = []

    def on_state(state, force, now):
        ns = int(round(now * 1e9)) + 1_000_000_000
        stamps.append(ns)
        fi.on_pose(ns, now)

    servo = ServoLoop(dev, safety, 1000.0, on_state=on_state, clock=lambda: clock[0],
                      render=lambda st, now: render(fi, st, now))
    servo.start()
    n = np.array([1.0, 0, 0])
    F0 = np.array([9.5, 0.0, 0.0])  # more than one max_dt ramp step (5 N) above zero
    lm = make(F0, p, -500 * np.outer(n, n), (0, 0, 0), n, -n, 0.004, zero=True)

    def answer(stamp, now):  # what the force server sends for the pose `stamp`
        assert fi.command(tuple(F0), stamp, 'tissue', now) == 'ok'
        if mode == 'local_model':
            assert fi.model(lm, stamp, 'tissue', now) == 'ok'

    for i in range(100):  # 0.1 s of normal running, 1 ms latency
        clock[0] = i * 0.001
        servo.tick(clock[0])
        answer(stamps[-1], clock[0] + 0.0005)
    assert np.linalg.norm(dev.forces[-1]) == pytest.approx(9.5, abs=0.01)
    late = stamps[-5:]  # poses answered while the driver was paused; the server then died
    clock[0] = 1.1  # resume: 1 s later
    for s in late:  # the queued commands arrive before the first tick ...
        if mode == 'zoh':
            assert fi.command(tuple(F0), s, 'tissue', clock[0]).startswith('rejected: stamp')
        else:
            assert fi.model(lm, s, 'tissue', clock[0]).startswith('rejected: stamp')
    after = []
    for i in range(30):
        clock[0] = 1.1 + i * 0.001
        servo.tick(clock[0])
        after.append(np.linalg.norm(dev.forces[-1]))
        if i == 3:  # ... or after the first ticks
            for s in late:
                fi.command(tuple(F0), s, 'tissue', clock[0])
                if mode == 'local_model':
                    assert fi.model(lm, s, 'tissue', clock[0]).startswith('rejected')
    assert max(after) <= 0.05, after
    assert fi.stamps.stats.rejected_stale >= 5
    assert safety.stats.watchdog_trips_in_contact == 1


@pytest.mark.parametrize('hold_time, taken', [(None, (True, False, False)),
                                               (0.0, (True, False, False)),
                                               (0.5, (True, True, False))])
def test_a_late_model_is_taken_while_it_could_still_be_held(hold_time, taken):
    """A model is refused at arrival only when it is older than the renderer in use may render
    it: past model_validity_time for the Python renderer (None) or the compiled tick without a
    hold, past model_hold_time with one. A model 0.2 s late is younger than the held one it would
    replace: refusing it let the held model expire beside a busy machine (issue 32). Past the
    hold it is refused (issue 22)."""
    mapping = WorkspaceMapping(1.0, (0.0, 0.0, 0.0), 1.0)
    safety = SafetyLayer(10.0, 1000.0, 0.010, frame_id='tissue')
    fi = ForceInput(safety, mapping, LocalModelRenderer(3000.0, validity_time=0.05), mode='local_model')
    if hold_time is not None:   # the driver's compiled tick: its renderer takes the models
        from haptic_anfis.device import HandParams
        from haptic_anfis.device.palpation import PalpationScript
        from haptic_anfis.device.servo_native import NativeServoLoop
        still = PalpationScript(np.array([0.0, 1.0]), np.zeros((2, 3)), np.array([False]))
        fi.renderer = NativeServoLoop(still, mapping, HandParams(), mode='local_model',
                                      validity_time=0.05, hold_time=hold_time).renderer
    n = np.array([1.0, 0, 0])
    p = (-0.004, 0.0, 0.0)
    lm = make((2.0, 0.0, 0.0), p, -500 * np.outer(n, n), (0, 0, 0), n, -n, 0.004)
    got = []
    for k, late in enumerate((0.02, 0.2, 0.6)):   # pose at t0, the model `late` s after it
        t0 = 10.0 * (k + 1)
        stamp = int(t0 * 1e9)
        fi.on_pose(stamp, t0)
        got.append(fi.model(lm, stamp, 'tissue', t0 + late) == 'ok')
    assert tuple(got) == taken
    assert fi.stamps.stats.rejected_stale == taken.count(False)


def test_local_model_rides_out_latency_zoh_does_not():
    """A press at 0.1 m/s with every answer 15 ms late (past the 10 ms watchdog): the zero-order
    hold refuses every stale command and its force stays at zero; the local model follows the
    ideal force within 2 % with no watchdog trip."""
    res = {}
    for mode in ('zoh', 'local_model'):
        mapping = WorkspaceMapping(1.0, (0.0, 0.0, 0.0), 1.0)
        safety = SafetyLayer(10.0, 1000.0, 0.010, frame_id='tissue')
        fi = ForceInput(safety, mapping, LocalModelRenderer(3000.0, validity_time=0.05), mode=mode)
        dev = StillDevice((0.0, 0.0, 0.0))
        n = np.array([1.0, 0, 0])
        k = 400.0
        ideal = lambda p: max(0.0, -p[0]) * k * n  # noqa: E731
        pend = []
        servo = ServoLoop(dev, safety, 1000.0,
                          on_state=lambda st, f, now: (fi.on_pose(int(now * 1e9) + 1, now),
                                                       pend.append((now + 0.015, st.position,
                                                                    int(now * 1e9) + 1))),
                          clock=lambda: 0.0, render=lambda st, now: render(fi, st, now))
        servo.start()
        errs, forces = [], []
        for i in range(400):
            now = i * 0.001
            dev.p = (0.0005 - 0.1 * now * (1 if now < 0.2 else 0) - (0.02 if now >= 0.2 else 0),
                     0.0, 0.0)
            while pend and pend[0][0] <= now:
                _, pos, st = pend.pop(0)
                f = ideal(pos)
                fi.command(tuple(f), st, 'tissue', now)
                depth = max(0.0, -pos[0])
                fi.model(make(f, pos, -k * np.outer(n, n), (0, pos[1], pos[2]), n, -n, depth,
                              zero=True), st, 'tissue', now)
            servo.tick(now)
            if 0.05 < now < 0.2:
                errs.append(np.linalg.norm(np.array(dev.forces[-1]) - ideal(dev.p)))
                forces.append(np.linalg.norm(ideal(dev.p)))
        res[mode] = (np.sqrt(np.mean(np.square(errs))) / np.sqrt(np.mean(np.square(forces))),
                     safety.stats.watchdog_trips_in_contact, max(np.linalg.norm(f)
                                                                  for f in dev.forces))
    assert res['local_model'][0] < 0.02 and res['local_model'][1] == 0
    assert res['zoh'][2] == 0.0  # every command refused as stale: never any force


def test_trace_roundtrip(tmp_path):
    t = TickTrace(chunk=3)
    for i in range(7):
        t.add(i * 1e-3, (i, 0, 0), (0, i, 0), i % 5)
    rows = t.arrays()
    assert rows.shape == (7, 8) and rows[6, 1] == 6 and rows[6, 5] == 6
    path = save_trace(tmp_path / 'x.npz', rows, mode='zoh')
    r2, meta = load_trace(path)
    np.testing.assert_array_equal(r2, rows)
    assert meta == {'mode': 'zoh'}
    (tmp_path / 'bad.npz').write_bytes(b'nope')
    with pytest.raises(ValueError, match='bad.npz'):
        load_trace(tmp_path / 'bad.npz')


def test_trace_keeps_the_newest_rows_within_its_bound():
    # an hour-long session must not grow the driver without bound (issue 21): a ring of chunks
    t = TickTrace(chunk=4, max_rows=10)
    for i in range(103):
        t.add(i * 1e-3, (i, 0, 0), (0, 0, 0), 0)
    rows = t.arrays()
    assert len(rows) <= 12 and len(t._chunks) <= 3  # max_rows rounded up to whole chunks
    np.testing.assert_array_equal(rows[:, 1], np.arange(103 - len(rows), 103))  # newest, in order
    assert t.dropped + t.rows == 103 and t.rows == len(rows)
    unbounded = TickTrace(chunk=4, max_rows=0)
    for i in range(103):
        unbounded.add(i, (i, 0, 0), (0, 0, 0), 0)
    assert len(unbounded.arrays()) == 103 and unbounded.dropped == 0


@pytest.fixture(scope='module')
def default_model():
    from haptic_anfis.pipeline.force import load_model
    return load_model({'model_path': ''})[1]


@pytest.mark.parametrize('seed', range(3))
def test_force_server_local_model_matches_finite_differences(default_model, seed):
    """The published K (analytic Jacobian through the geometry) equals central differences of
    the model through the same geometry; F0 is the model's force; p0 = contact + depth d."""
    from haptic_anfis.device.local_model import force_and_jacobian_fd
    from haptic_anfis import interfaces as ifc
    from haptic_anfis.pipeline.force import local_model_from_contact
    rng = np.random.default_rng(seed)
    c = np.array([0.035, *rng.uniform(-0.02, 0.02, 2)])
    n = unit([1.0, *rng.uniform(-0.4, 0.4, 2)])
    d = np.array([-1.0, 0.0, 0.0])
    depth = rng.uniform(0.003, 0.012)
    v = [*c, depth, *d, 1.0, 0.0, *n]
    F, lm, err = local_model_from_contact(default_model, v)
    assert err is None
    np.testing.assert_allclose(F, default_model.predict_one(*c, depth), atol=1e-12)
    np.testing.assert_allclose(lm[ifc.LM_P0], c + depth * d, atol=1e-15)
    _, Jfd = force_and_jacobian_fd(default_model, *c, depth)
    K = np.array(lm[ifc.LM_K]).reshape(3, 3)
    np.testing.assert_allclose(K, contact_jacobian(Jfd, n, d), rtol=1e-3, atol=0.5)
    m = LocalModel.from_values(lm)
    assert m.in_contact and m.depth0 == depth
    # the older 9-value contact: normal taken as -direction
    F9, lm9, err9 = local_model_from_contact(default_model, v[:9])
    assert err9 is None and lm9[ifc.LM_N] == [1.0, -0.0, -0.0]
    # saturated: the depth column does not count
    vs = list(v)
    vs[ifc.I_SATURATED] = 1.0
    Ks = np.array(local_model_from_contact(default_model, vs)[1][ifc.LM_K]).reshape(3, 3)
    J0 = Jfd.copy()
    J0[:, 3] = 0.0
    np.testing.assert_allclose(Ks, contact_jacobian(J0, n, d), rtol=1e-3, atol=0.5)


def test_force_server_local_model_without_contact_or_bad(default_model):
    from haptic_anfis import interfaces as ifc
    from haptic_anfis.pipeline.force import local_model_from_contact
    free = [0.05, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    F, lm, err = local_model_from_contact(default_model, free)
    assert F == (0.0, 0.0, 0.0) and err is None and lm[ifc.LM_DEPTH] == 0.0
    assert not LocalModel.from_values(lm).in_contact
    bad = [math.nan, 0.0, 0.0, 0.005, -1.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0]
    F, lm, err = local_model_from_contact(default_model, bad)
    assert F == (0.0, 0.0, 0.0) and 'non-finite' in err and lm[ifc.LM_DEPTH] == 0.0
    F, lm, err = local_model_from_contact(default_model, [1.0] * 5)
    assert F == (0.0, 0.0, 0.0) and 'expected 12' in err
    with pytest.raises(ValueError, match='expected 26'):
        LocalModel.from_values([0.0] * 3)


def test_force_error_and_its_phases():
    """Two contacts of 100 ticks at 1 kHz (the second runs to the trace's end); the applied force
    is the ideal one except 3 ticks late at each onset (zero there) and one 0.1 N error in the
    middle of the first: the squared error splits accordingly."""
    from haptic_anfis.device.force_error import error_by_phase, force_error
    t = np.arange(300) * 1e-3
    contact = np.zeros(300, dtype=bool)
    contact[50:150] = True
    contact[200:300] = True
    ideal = np.zeros((300, 3))
    ideal[contact, 0] = 2.0
    applied = ideal.copy()
    applied[[50, 51, 52, 200, 201, 202], 0] = 0.0  # onset: one latency of zero force
    applied[100, 0] = 2.1  # steady
    applied[10, 0] = 5.0  # free: not counted
    e = force_error(applied, ideal, contact)
    assert e['contact_ticks'] == 200
    assert e['force_error_rms_n'] == pytest.approx(math.sqrt((6 * 4 + 0.01) / 200))
    assert e['force_error_rms_pct'] == pytest.approx(100 * e['force_error_rms_n'] / 2.0)
    ph = error_by_phase(applied, ideal, contact, t, window=0.0195)  # 20 ticks each
    assert ph['contacts'] == 2
    assert (ph['onset']['ticks'], ph['offset']['ticks'], ph['steady']['ticks']) == (40, 20, 140)
    assert ph['onset']['share_pct'] == pytest.approx(100 * 24 / 24.01)
    assert ph['steady']['share_pct'] == pytest.approx(100 * 0.01 / 24.01)
    assert ph['offset']['share_pct'] == 0.0
    # the ideal force is clamped to the device limit before comparing
    assert force_error(ideal * 10, ideal * 10, contact, max_force=5.0)['force_error_rms_n'] \
        == pytest.approx(15.0)
    with pytest.raises(ValueError, match='error_by_phase'):
        error_by_phase(applied, ideal, contact, t[:5])


def test_approach_model_renders_from_the_plane_on():
    """A model made while free, with the plane ahead (depth 0, unit normal): zero outside the
    plane, K (p - s) past it at once, counted as approach ticks; a non-unit normal is refused."""
    n = unit([1.0, 0.2, 0.0])
    d = np.array([-1.0, 0.0, 0.0])
    s = np.array([0.03, 0.001, 0.0])
    g = depth_gradient(n, d)
    kd = np.array([300.0, 20.0, 0.0])  # dF/d depth at 0+ [N/m]
    K = np.outer(kd, g)  # the force grows with the depth past the plane
    r = LocalModelRenderer(max_stiffness=1e5, validity_time=1.0, validity_radius=0.01)
    m = make((0, 0, 0), s, K, s, n, d, 0.0, zero=True)
    assert m.approach and not m.in_contact
    r.offer(m)
    assert r.render(tuple(s - 0.002 * d), 0.0) == ((0.0, 0.0, 0.0), FREE)  # still outside
    p = s + 0.0005 * d + np.array([0.0, 0.0005, 0.0003])
    f, st = r.render(tuple(p), 0.0)
    assert st == FRESH and r.stats.ticks_approach == 1
    depth = g @ (p - s)
    assert depth > 0
    np.testing.assert_allclose(f, condition_stiffness(K, 1e5) @ (p - s), atol=1e-12)
    # the all-zero free model still renders nothing, and counts no approach tick
    r.offer(make((0, 0, 0), (0, 0, 0), np.zeros((3, 3)), (0, 0, 0), (0, 0, 0), (0, 0, 0), 0.0))
    assert r.render(tuple(p), 0.0) == ((0.0, 0.0, 0.0), FREE) and r.stats.ticks_approach == 1
    with pytest.raises(ValueError, match='normal'):
        r.offer(make((0, 0, 0), s, K, s, 2 * n, d, 0.0))


def test_an_approach_plane_renders_nothing_away_from_its_point():
    """An approach model is the tangent plane at one point: followed past ``approach_radius``
    ACROSS the direction (a stale plane under a sideways stroke) it renders zero, where the
    surface lies under the plane; inside it (past the validity radius: the offset across held),
    straight in past both radii, and a contact model any way past them, it still renders."""
    n = unit([1.0, 0.2, 0.0])
    d = np.array([-1.0, 0.0, 0.0])
    s = np.array([0.03, 0.001, 0.0])
    g = depth_gradient(n, d)
    K = np.outer([300.0, 20.0, 0.0], g)
    r = LocalModelRenderer(max_stiffness=1e5, validity_time=1.0, validity_radius=0.005,
                           approach_radius=0.008)
    r.offer(make((0, 0, 0), s, K, s, n, d, 0.0, zero=True))
    side = np.array([0.0, 0.0, 1.0])   # across d and in the plane's tangent direction
    for deep, across, kind in ((0.009, 0.0, FRESH), (0.001, 0.004, FRESH),
                               (0.001, 0.007, FRESH), (0.001, 0.009, FREE)):
        f, st = r.render(tuple(s + deep * d + across * side), 0.0)
        assert st == kind, (deep, across, st)
        assert (np.linalg.norm(f) > 0.1) == (kind == FRESH), (deep, across, f)
    assert r.stats.ticks_beyond == 2 and r.stats.ticks_free == 1
    assert not across_beyond(*g, *(0.009 * d), 0.008) and across_beyond(*g, *(0.009 * side), 0.008)
    # a radius below the validity radius applies as well (it is its own test, not the hold's)
    r2 = LocalModelRenderer(max_stiffness=1e5, validity_time=1.0, validity_radius=0.005,
                            approach_radius=0.002)
    r2.offer(make((0, 0, 0), s, K, s, n, d, 0.0, zero=True))
    assert r2.render(tuple(s + 0.001 * d + 0.003 * side), 0.0) == ((0.0, 0.0, 0.0), FREE)
    assert r2.stats.ticks_free == 1 and r2.stats.ticks_beyond == 0
    c = s + 0.002 * d   # a contact model 2 mm in: 9 mm across is held at the radius, not dropped
    r.offer(make((1.0, 0.0, 0.0), c, K, s, n, d, 0.002))
    f, st = r.render(tuple(c + 0.009 * side), 0.0)
    assert st == FRESH and f[0] > 0.5 and r.stats.ticks_beyond == 3


@pytest.mark.parametrize('radius', [0.0, -0.01, math.nan, math.inf, '0.01'])
def test_an_approach_radius_that_is_no_length_is_refused(radius):
    """approach_radius 0, negative, NaN, infinite or not a number: one ValueError naming it."""
    with pytest.raises(ValueError, match='approach_radius: expected a finite number > 0'):
        LocalModelRenderer(approach_radius=radius)


def test_surface_ahead_of_a_free_probe():
    """Fixed direction: the ray's first front-face crossing within the distance; normal mode:
    the closest point; nothing beyond the distance or behind the probe."""
    from haptic_anfis.contact import ContactDetector, ellipsoid_dome
    from haptic_anfis.contact.approach import surface_ahead
    mesh = ellipsoid_dome((0.045, 0.07, 0.07))
    det = ContactDetector(mesh, direction=(-1.0, 0.0, 0.0))
    top = np.array([0.045, 0.0, 0.0])
    s, n, t = surface_ahead(det, top + [0.003, 0.001, 0.0], det.direction, 0.005)
    assert t == pytest.approx(0.003, abs=2e-4) and s[0] == pytest.approx(0.045, abs=2e-4)
    assert n[0] > 0.95 and np.linalg.norm(n) == pytest.approx(1.0)
    assert surface_ahead(det, top + [0.006, 0.0, 0.0], det.direction, 0.005) is None
    assert surface_ahead(det, top + [0.003, 0.0, 0.0], det.direction, 0.0) is None
    assert surface_ahead(det, top + [0.003, 0.0, 0.0], (1.0, 0.0, 0.0), 0.005) is None  # away
    free = ContactDetector(mesh, direction=None)
    s, n, t = surface_ahead(free, top + [0.002, 0.0, 0.0], None, 0.005)
    assert t == pytest.approx(0.002, abs=2e-4) and n[0] > 0.95


def test_force_server_approach_model(default_model):
    """Free probe with the approach fields: F0 = 0 at the surface point ahead, K = dF/dp at depth
    0+; past the plane the rendered force follows the model's at small depths. Without the
    fields, or with bad ones: the all-zero model."""
    from haptic_anfis.pipeline.force import local_model_from_contact
    c = np.array([0.035, 0.004, -0.003])
    n = unit([1.0, 0.1, -0.05])
    d = np.array([-1.0, 0.0, 0.0])
    free = [*(c - 0.002 * d), 0.0, *d, 0.0, 0.0, 0.0, 0.0, 0.0]
    F, lm, err = local_model_from_contact(default_model, free, approach=[*c, *n])
    assert F == (0.0, 0.0, 0.0) and err is None
    m = LocalModel.from_values(lm)
    assert m.approach and m.zero_at_surface and m.f0 == (0.0, 0.0, 0.0)
    np.testing.assert_allclose(m.p0, c)
    r = LocalModelRenderer(max_stiffness=1e6, validity_time=1.0, validity_radius=0.01)
    r.offer(m)
    for depth in (1e-5, 1e-4, 3e-4):
        f, st = r.render(tuple(c + depth * d), 0.0)
        assert st == FRESH
        ref = np.array(default_model.predict_one(*c, depth))
        # the normal force to 1 %; the tangential part is what the symmetric guard leaves of the
        # rank-one K = J_depth g^T (measured 2-12 % of |F| on the shipped surface's slopes)
        assert abs(f[0] - ref[0]) <= 0.01 * np.linalg.norm(ref), (depth, f, ref)
        assert np.linalg.norm(f - ref) <= 0.15 * np.linalg.norm(ref), (depth, f, ref)
    assert local_model_from_contact(default_model, free)[1] == [0.0] * len(lm)
    for bad in ([math.nan, 0, 0, *n], [*c, 0.0, 0.0, 0.0], [*c, *n][:5]):
        assert local_model_from_contact(default_model, free, approach=bad)[1] == [0.0] * len(lm)


@pytest.mark.parametrize('seed', range(10))
def test_rotating_mode_is_a_complex_pair_of_eigenvalues(seed):
    """rotating_mode agrees with numpy's eigenvalues on random, symmetric (never rotating, also
    with repeated eigenvalues) and guarded stiffnesses."""
    for K in hard_stiffnesses(seed):
        for M in (K, 0.5 * (K + K.T), condition_stiffness(K, 3000.0)):
            w = np.linalg.eigvals(M)
            scale = max(np.abs(M).max(), 1e-300)
            complex_pair = np.abs(w.imag).max() > 1e-4 * scale
            real = np.abs(w.imag).max() < 1e-7 * scale
            if complex_pair or real:  # not on the edge between them
                assert rotating_mode(M.ravel().tolist()) == complex_pair, M
    # the tissue's kind (the depth coupled with the surface) and a turned surface plane
    assert not rotating_mode([-1000, 0, 0, 200, -500, 0, 0, 0, 0])
    assert rotating_mode([-1000, 0, 0, 0, 0, -100, 0, 100, 0])
