"""Penetration depth (fixed axis and normal), and the stateful ContactTracker (proxy)."""
from __future__ import annotations

import numpy as np
import pytest

from contact_reference import dome
from haptic_anfis.contact import ContactDetector, ContactTracker, MeshWarning
from haptic_anfis.tissue.synthetic import surface_x

RADII = (0.045, 0.070, 0.070)
X_AXIS = (-1.0, 0.0, 0.0)  # the paper's indentation axis: into the body


@pytest.fixture(scope='module')
def dome_mesh():
    return dome(n_theta=30, n_phi=120)


@pytest.fixture(scope='module')
def det_axis(dome_mesh):
    return ContactDetector(dome_mesh, direction=X_AXIS)


@pytest.fixture(scope='module')
def det_normal(dome_mesh):
    return ContactDetector(dome_mesh)


def test_fixed_axis_depth_is_distance_back_to_the_surface(det_axis):
    rng = np.random.default_rng(0)
    yz = rng.uniform(-0.045, 0.045, (200, 2))
    yz = yz[np.hypot(*yz.T) < 0.055]
    delta = rng.uniform(0.001, 0.016, len(yz))
    xs = surface_x(yz[:, 0], yz[:, 1], RADII)
    P = np.column_stack([xs - delta, yz])
    b = det_axis.query_many(P)
    assert b.in_contact.all()
    # The contact point is on the surface, straight "above" the probe along +x, depth apart.
    np.testing.assert_allclose(b.contact_point, P + b.depth[:, None] * [1.0, 0.0, 0.0], atol=1e-15)
    on = det_axis.query_many(b.contact_point)
    assert np.abs(on.signed_distance).max() < 1e-15
    np.testing.assert_array_equal(b.direction, np.tile(X_AXIS, (len(P), 1)))
    # The facetted dome is within a sagitta (~0.1 mm here) of the analytic one.
    np.testing.assert_allclose(b.depth, delta, atol=2e-4)
    # Above the surface: no contact, zero depth.
    out = det_axis.query_many(P + [0.02, 0.0, 0.0])
    assert not out.in_contact.any() and (out.depth == 0).all() and (out.signed_distance > 0).all()


def test_normal_depth_is_minus_signed_distance(det_normal):
    rng = np.random.default_rng(1)
    P = rng.uniform([-0.01, -0.08, -0.08], [0.06, 0.08, 0.08], (300, 3))
    b = det_normal.query_many(P)
    np.testing.assert_array_equal(b.depth, np.maximum(0.0, -b.signed_distance))
    np.testing.assert_array_equal(b.in_contact, b.signed_distance < 0)
    np.testing.assert_array_equal(b.direction, -b.normal)
    np.testing.assert_array_equal(b.contact_point, b.point)


def test_behind_the_chest_wall_is_not_contact(det_axis):
    r = det_axis.query([-0.005, 0.01, 0.0])
    assert r.signed_distance == pytest.approx(0.005) and not r.in_contact and r.depth == 0.0


def test_open_dome_from_below_is_rejected_by_the_tracker():
    # Without the chest-wall disc the dome is a shell: a point under it is "inside" (behind the
    # nearest face) and walking back along +x crosses the dome's front face, so the stateless query
    # reports a depth. The tracker sees the probe arrive from below without crossing the skin.
    with pytest.warns(MeshWarning, match='not watertight'):
        det = ContactDetector(dome(n_theta=10, n_phi=40, closed=False), direction=X_AXIS)
    assert det.query([-0.01, 0.0, 0.0]).in_contact
    tr = ContactTracker(det)
    for x in np.linspace(-0.03, 0.02, 30):  # coming up from behind the chest wall
        assert not tr.update([x, 0.0, 0.0]).in_contact
    assert tr.state == 'rejected'


def _slide(tracker, path):
    return [tracker.update(p) for p in path]


def test_tracker_enter_press_release(det_axis):
    tr = ContactTracker(det_axis)
    down = [[x, 0.01, 0.005] for x in np.linspace(0.06, 0.03, 31)]
    res = _slide(tr, down)
    xs = surface_x(np.array(0.01), np.array(0.005), RADII)
    for p, r in zip(down, res):
        inside = p[0] < xs - 2e-4
        assert r.in_contact == (r.state == 'contact')
        if inside:
            assert r.in_contact and r.depth == pytest.approx(xs - p[0], abs=2e-4)
        if p[0] > xs + 2e-4:
            assert not r.in_contact and r.state == 'free'
    up = _slide(tr, down[::-1])
    assert up[-1].state == 'free' and not up[-1].in_contact


def test_tracker_rejects_entry_from_behind_and_recovers(det_axis):
    tr = ContactTracker(det_axis)
    path = [[x, 0.0, 0.01] for x in np.linspace(-0.02, 0.06, 81)]  # through the chest wall
    res = _slide(tr, path)
    assert not any(r.in_contact for r in res)
    assert {r.state for r in res} == {'free', 'rejected'}
    assert res[-1].state == 'free'
    # The same probe coming down from outside the skin is a contact.
    res = _slide(tr, path[::-1])
    assert any(r.in_contact for r in res)


def test_first_sample_inside_is_rejected(det_axis):
    tr = ContactTracker(det_axis)
    assert tr.update([0.03, 0.0, 0.0]).state == 'rejected'
    assert tr.update([0.031, 0.0, 0.0]).state == 'rejected'
    assert tr.update([0.05, 0.0, 0.0]).state == 'free'
    assert tr.update([0.04, 0.0, 0.0]).in_contact


def test_tracker_depth_saturates_beyond_the_chest_wall(det_axis):
    tr = ContactTracker(det_axis)
    path = [[x, 0.0, 0.0] for x in np.linspace(0.05, -0.03, 161)]  # through the whole breast
    res = _slide(tr, path)
    contact = [r for r in res if r.in_contact]
    assert res[-1].in_contact and res[-1].saturated
    thickness = 0.045  # the pole is exactly on the mesh
    assert max(r.depth for r in contact) == pytest.approx(thickness, abs=1e-12)
    assert np.all(np.diff([r.depth for r in contact]) >= -1e-15)  # never drops while pushing in
    np.testing.assert_allclose(res[-1].contact_point, [0.045, 0.0, 0.0], atol=1e-12)
    # An explicit cap (the deepest trained depth) saturates earlier.
    tr = ContactTracker(det_axis, max_depth=0.016)
    res = _slide(tr, path)
    assert max(r.depth for r in res) == 0.016 and res[-1].saturated


@pytest.mark.parametrize('direction', [X_AXIS, None])
def test_proxy_moves_smoothly_when_deep(dome_mesh, direction):
    """Slide 25 mm deep under the dome across its width: no jumps of the contact point."""
    det = ContactDetector(dome_mesh, direction=direction)
    tr = ContactTracker(det)
    step = 1e-4  # 0.1 mm per 1 ms sample = 0.1 m/s
    _slide(tr, [[x, 0.0, 0.0] for x in np.arange(0.06, 0.020, -step)])  # press in at the pole
    ys = np.arange(0.0, 0.05, step)
    path = np.column_stack([np.full(len(ys), 0.020), ys, 0.3 * ys])
    res = _slide(tr, path)
    assert all(r.in_contact for r in res)
    cp = np.array([r.contact_point for r in res])
    jumps = np.linalg.norm(np.diff(cp, axis=0), axis=1)
    # The proxy moves along the surface: lateral step times the slope factor (< 2 here).
    assert jumps.max() < 2 * step * np.hypot(1, 0.3), jumps.max()
    # ...whereas the stateless closest point jumps between distant faces (dome top <-> chest wall).
    stateless = ContactDetector(dome_mesh).query_many(path).point
    assert np.linalg.norm(np.diff(stateless, axis=0), axis=1).max() > 0.01


def test_tracker_nan_resets_and_raises(det_axis):
    tr = ContactTracker(det_axis)
    tr.update([0.06, 0.0, 0.0])
    assert tr.update([0.04, 0.0, 0.0]).in_contact
    with pytest.raises(ValueError, match='p: probe position must be finite'):
        tr.update([np.nan, 0.0, 0.0])
    assert tr.state == 'free'
    assert tr.update([0.04, 0.0, 0.0]).state == 'rejected'  # no history: must come from outside


@pytest.mark.parametrize('direction,max_depth', [(X_AXIS, None), (X_AXIS, 0.016), (None, None)])
def test_tracker_proxy_step_matches_two_separate_ray_casts(dome_mesh, direction, max_depth):
    # The tracker's one-kernel proxy step (ray back out, then the thickness ray stopped at the
    # probe) gives exactly what two full ray casts give, including saturation.
    det = ContactDetector(dome_mesh, direction=direction)
    tr = ContactTracker(det, max_depth=max_depth)
    s = np.linspace(0, 1, 600)
    path = np.column_stack([0.05 - 0.07 * np.abs(np.sin(5 * s)), 0.03 * np.sin(3 * s),
                            0.03 * np.cos(4 * s)])  # in, through the chest wall, out, again
    cap = np.inf if max_depth is None else max_depth
    n_contact = n_sat = 0
    for p in path:
        d = tr._dir
        r = tr.update(p)
        if not r.in_contact:
            continue
        n_contact += 1
        n_sat += r.saturated
        if d is None or r.direction is not d:  # contact started here: direction just set
            d = r.direction
        face, t = det._raycast(p, -d, -tr.max_step, np.inf, +1)
        proxy = p - t * d
        thick = det._raycast(proxy, d, det._tol, np.inf, 0)
        limit = min(thick[1] if thick is not None else np.inf, cap)
        assert r.triangle == face
        np.testing.assert_array_equal(r.contact_point, proxy)
        assert r.depth == min(t, limit) and r.saturated == (t > limit)
        np.testing.assert_array_equal(r.normal, det._tri[det._row_of[face], 9:12])
    assert n_contact > 100 and n_sat > 10


def test_a_press_compiles_nothing_after_the_detector_is_built():
    """Every kernel a contact uses — the entry's ray cast, the follow, the approach's ray cast and
    normal — is compiled (or loaded from numba's cache) when the detector is built, not at the
    first touch: with a cold cache a first-touch compile stopped the contact stream ~1.5 s and the
    servo loop rendered 0 N for 0.65 s (issue 32). A new signature of any kernel after the build
    would be such a compile."""
    from haptic_anfis.contact import ContactDetector, ContactTracker, bvh, load_mesh
    from haptic_anfis.pipeline.contact import DEFAULT_SURFACE, approach_values
    mesh = load_mesh(DEFAULT_SURFACE, unit='mm')
    mesh.merge_vertices()
    tracker = ContactTracker(ContactDetector(mesh, direction=(-1.0, 0.0, 0.0)))

    def signatures():
        return {k: len(v.signatures) for k, v in vars(bvh).items() if hasattr(v, 'signatures')}
    built = signatures()
    touched = 0
    for x in np.arange(0.09, 0.0, -0.001):  # the default surface, pressed along -x
        p = np.array([x, 0.005, 0.002])
        c = tracker.update(p)
        approach_values(tracker, c, (x, 0.005, 0.002), 0.02)
        touched += c.in_contact
        if touched > 5:
            break
    assert touched > 5  # the press did reach into the tissue
    tracker.update(np.array([0.09, 0.005, 0.002]))  # and out again
    assert signatures() == built
