"""Zero force at contact and continuity from it: properties of the shipped force model over the
whole palpated surface (hypothesis), and of the depth-scaled form in general."""
import numpy as np
import pytest
from hypothesis import given, strategies as st

from haptic_anfis.anfis import ForceModel
from haptic_anfis.tissue.dataset import DATA_DIR, load_dataset
from haptic_anfis.report.contact import contact_onset, outward_normals


@pytest.fixture(scope='module')
def shipped():
    return ForceModel.load(DATA_DIR / 'default_model.json')


@pytest.fixture(scope='module')
def data():
    return load_dataset()


def _surface_point(data, r_frac, angle):
    """A point on the scene's skin inside the palpated disc (0 <= r_frac <= 1)."""
    rx, ry, rz = data.provenance['scene_si']['radii']
    r_max = np.hypot(data.X[:, 1], data.X[:, 2]).max()
    y, z = r_max * r_frac * np.cos(angle), r_max * r_frac * np.sin(angle)
    x = rx * np.sqrt(max(0.0, 1.0 - (y / ry) ** 2 - (z / rz) ** 2))
    return np.array([x, y, z])


def _stiffness_bound(data):
    """c of |F(ε)| <= c·ε: twice the data's largest |F| / depth [N/m]."""
    return 2.0 * np.max(np.linalg.norm(data.Y, axis=1) / data.X[:, 3])


r_fracs = st.floats(0.0, 1.0, allow_nan=False)
angles = st.floats(0.0, 2 * np.pi, allow_nan=False)


def test_shipped_model_is_depth_scaled(shipped):
    assert shipped.scale_col_ == 3


@given(r_fracs, angles)
def test_zero_force_at_zero_depth_exactly(shipped, data, r, a):
    p = _surface_point(data, r, a)
    assert shipped.predict_one(*p, 0.0) == (0.0, 0.0, 0.0)
    np.testing.assert_array_equal(shipped.predict(np.append(p, 0.0)[None]), 0.0)
    F, _ = shipped.jacobian_one(*p, 0.0)
    np.testing.assert_array_equal(F, 0.0)


@given(r_fracs, angles, st.floats(1e-9, 2e-3, allow_nan=False))
def test_force_grows_continuously_from_contact(shipped, data, r, a, eps):
    p = _surface_point(data, r, a)
    F = np.array(shipped.predict_one(*p, eps))
    assert np.linalg.norm(F) <= _stiffness_bound(data) * eps


@given(r_fracs, angles, st.floats(0.0, 1.0, allow_nan=False))
def test_never_pulls_into_the_tissue_along_the_normal(shipped, data, r, a, depth_frac):
    p = _surface_point(data, r, a)
    depth = depth_frac * 1.25 * data.X[:, 3].max()
    F = np.array(shipped.predict_one(*p, depth))
    n = outward_normals(data, p[None])[0]
    assert F @ n >= 0.0


def test_contact_onset_check_over_the_dataset_points(shipped, data):
    r = contact_onset(shipped, data)
    assert r['max_force_at_zero_N'] == 0.0
    assert r['n_points_pulling'] == 0
    assert r['max_slope_at_eps_N_per_m'] <= _stiffness_bound(data)


def test_contact_onset_check_detects_a_force_step(small_model, synthetic):
    """The plain form has no zero-at-contact guarantee: the check must see its step."""
    r = contact_onset(small_model, synthetic)
    assert r['max_force_at_zero_N'] > 0.0


def test_no_contact_no_force(shipped):
    assert shipped.predict_one(0.04, 0.0, 0.0, -0.002) == (0.0, 0.0, 0.0)


def test_depth_scaled_fit_rejects_zero_depth_samples(synthetic):
    X = synthetic.X.copy()
    X[5, 3] = 0.0
    with pytest.raises(ValueError, match='sample 5 has depth 0.0'):
        ForceModel(structure=(2, 2, 2), epochs=1).fit(X, synthetic.Y, groups=synthetic.point)
