"""The display dent model: footprint exact, far field untouched, fitted fields reproduced."""
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from haptic_anfis.tissue.deformation import R_MAX, DeformationModel, fe_samples, holdout_errors

from deformation_fixture import A, FP, synthetic as _synthetic  # noqa: E402


@pytest.fixture(scope='module')
def model():
    return DeformationModel().fit(_synthetic())


def _disc(c, direction, radius, n=400, seed=0):
    """Points spread over a disc of ``radius`` around the axis through c along direction."""
    from haptic_anfis.tissue.displacement import probe_frame

    f = probe_frame(direction)
    rng = np.random.default_rng(seed)
    r = radius * np.sqrt(rng.random(n))
    t = 2 * np.pi * rng.random(n)
    return c + (r * np.cos(t))[:, None] * f[1] + (r * np.sin(t))[:, None] * f[2], r


@settings(max_examples=30, deadline=None)
@given(y=st.floats(-0.04, 0.04), z=st.floats(-0.04, 0.04), depth=st.floats(1e-4, 0.02),
       tilt=st.floats(-0.5, 0.5))
def test_footprint_exactly_at_depth_and_far_field_unchanged(model, y, z, depth, tilt):
    c = np.array([0.04, y, z])
    d = np.array([-1.0, tilt, 0.0])
    d /= np.linalg.norm(d)
    inside, _ = _disc(c, d, A * (1 - 1e-9))
    new = model.displace(inside, c, d, depth)
    np.testing.assert_allclose(new - inside, np.broadcast_to(depth * d, inside.shape), atol=1e-12)
    far, r = _disc(c, d, 0.2)
    far = far[r > R_MAX * A * 1.0001]
    np.testing.assert_array_equal(model.displace(far, c, d, depth), far)


def test_no_dent_without_depth_and_chest_wall_fixed(model):
    pts, _ = _disc(np.array([0.045, 0, 0]), [-1, 0, 0], 0.05)
    for depth in (0.0, -0.003):
        np.testing.assert_array_equal(model.displace(pts, pts[0], [-1, 0, 0], depth), pts)
    wall = pts.copy()
    wall[:, 0] = 0.0
    np.testing.assert_array_equal(model.displace(wall, [0.045, 0, 0], [-1, 0, 0], 0.01), wall)


def test_dent_is_continuous_at_the_probe_edge(model):
    c = np.array([0.045, 0.0, 0.0])
    r = A * np.array([1 - 1e-6, 1 + 1e-6, 1.5])
    pts = c + np.column_stack([np.zeros(3), r, np.zeros(3)])
    u = model.displacement(pts, c, [-1, 0, 0], 0.016)
    assert np.abs(u[1] - u[0]).max() < 1e-6 * 0.016 * 10
    assert 0.0 < -u[2, 0] < 0.016


def test_fitted_fields_are_reproduced_at_loading_points(model):
    data = _synthetic()
    rho = data.rho
    out = rho >= 2 * A  # beyond the footprint stretch the model reads the FE field as is
    for i in (0, 7, len(data.point) // 2):
        for j, d in enumerate(data.depths):
            got = model.field_samples(data.surface_point[i], d)
            want = fe_samples(data, i, j)
            fade = rho <= 8 * A
            np.testing.assert_allclose(got[out & fade], want[out & fade], atol=1e-9)


def test_depth_interpolation_is_linear_in_the_field_over_depth(model):
    c = np.array([0.045, 0.0, 0.0])
    u_lo = model.coefficients(c, 0.005) / 0.005
    u_hi = model.coefficients(c, 0.008) / 0.008
    mid = model.coefficients(c, 0.0065) / 0.0065
    np.testing.assert_allclose(mid, 0.5 * (u_lo + u_hi), atol=1e-12)
    np.testing.assert_allclose(model.coefficients(c, 0.03) / 0.03,
                               model.coefficients(c, 0.016) / 0.016, atol=1e-12)


def test_contact_outside_the_sampled_disc_saturates(model):
    edge = model.coefficients([0.03, 0.0, 0.03], 0.01)
    beyond = model.coefficients([0.02, 0.0, 0.06], 0.01)
    assert np.all(np.isfinite(beyond))
    assert np.abs(beyond - edge).max() < 0.01 * 0.2  # close to the hull's field


@pytest.mark.parametrize('bad, match', [
    (dict(vertices=np.zeros((3, 2))), 'vertices'),
    (dict(contact_point=[np.nan, 0, 0]), 'contact_point'),
    (dict(direction=[0, 0, 0]), 'direction'),
    (dict(depth=np.inf), 'depth'),
])
def test_bad_input_named(model, bad, match):
    args = dict(vertices=np.zeros((3, 3)), contact_point=[0.045, 0, 0], direction=[-1, 0, 0],
                depth=0.01)
    args.update(bad)
    with pytest.raises(ValueError, match=match):
        model.displace(**args)


def test_holdout_error_small_on_a_smooth_field():
    err = holdout_errors(_synthetic(), folds=4)
    assert err['footprint_max_dev_m'] == 0.0
    assert err['annulus_rms_over_depth'] < 0.05
    radial = holdout_errors(_synthetic(), form='radial', folds=4)
    assert radial['annulus_rms_over_depth'] > err['annulus_rms_over_depth']  # misses harmonic 1
