"""The force model's analytic Jacobian (batch and compiled single query) against central finite
differences, away from the kinks of the triangular MFs and of the out-of-range clamps."""
import numpy as np
import pytest

from haptic_anfis.anfis import ANFIS, SugenoModel
from haptic_anfis.anfis import membership as mf
from haptic_anfis.anfis.force_model import numpy_forces
from force_models import assemble

H = 1e-7  # finite-difference step [m]


def _random_sugeno(structure, lo, hi, rng, extrapolation):
    mfs = []
    for i, m in enumerate(structure):
        P = mf.grid_partition(lo[i], hi[i], m)
        P = P + 0.3 * (hi[i] - lo[i]) / max(m, 2) * rng.uniform(-1, 1, P.shape)
        mfs.append(mf.project(P, lo[i], hi[i]))
    R = int(np.prod(structure))
    scale = np.concatenate([1.0 / (hi - lo), [1.0]])  # slopes comparable to the offsets
    return SugenoModel(mfs=mfs, coef=rng.normal(size=(R, len(structure) + 1)) * scale, lo=lo, hi=hi,
                       extrapolation=extrapolation)


def _kinks(fm):
    """Per query column, every coordinate where some output's derivative may jump."""
    out = [[] for _ in range(4)]
    for m in fm.estimators_:
        lo, hi = m.input_min_, m.input_max_
        ext = np.broadcast_to(np.asarray(m.extrapolation, dtype=float), lo.shape) * (hi - lo)
        for i, col in enumerate(fm.input_cols_):
            e = ext[i]
            out[col] += [*m.mf_params_[i].ravel(), lo[i], hi[i], lo[i] - e, hi[i] + e]
    if fm.scale_col_ >= 0:
        out[fm.scale_col_].append(0.0)
    return [np.array(k) for k in out]


def _finite_differences(fm, X):
    J = np.empty((len(X), 3, 4))
    for b in range(4):
        Xp, Xm = X.copy(), X.copy()
        Xp[:, b] += H
        Xm[:, b] -= H
        J[:, :, b] = (fm.predict(Xp) - fm.predict(Xm)) / (2 * H)
    return J


def _away_from_kinks(fm, X, margin=1e-5):
    kinks = _kinks(fm)
    keep = np.ones(len(X), bool)
    for b in range(4):
        if len(kinks[b]):
            keep &= np.min(np.abs(X[:, b:b + 1] - kinks[b][None]), axis=1) > margin
    return X[keep]


@pytest.fixture(scope='module')
def depth_scaled_model():
    """F = depth · g(y, z, depth): the zero-at-contact form, 3 model inputs, x unused."""
    rng = np.random.default_rng(7)
    lo, hi = np.array([-0.05, -0.05, 0.002]), np.array([0.05, 0.05, 0.016])
    return assemble([_random_sugeno(st, lo, hi, rng, (0.0, 0.0, 0.1))
                     for st in [(3, 3, 2), (4, 2, 3), (2, 3, 1)]], (1, 2, 3), 3)


@pytest.fixture(scope='module')
def wide_model():
    """Free triangles as the estimator allows them: feet reaching past several peaks and outer
    peaks off the domain edges, so up to all MFs of an input fire at once (the compiled kernel
    must visit every firing rule, not only two MFs per input)."""
    rng = np.random.default_rng(11)
    lo, hi = np.array([0.0, -0.05, -0.05, 0.002]), np.array([0.06, 0.05, 0.05, 0.016])
    fm = assemble([_random_sugeno(st, lo, hi, rng, (0.0, 0.1, 0.1, 0.25))
                   for st in [(2, 3, 4, 2), (3, 3, 3, 2), (1, 4, 2, 3)]])
    est = []
    for e in fm.estimators_:
        P = []
        for Q, a, b in zip(e.mf_params_, e.input_min_, e.input_max_):
            w = (b - a) * rng.uniform(0.6, 1.2, len(Q))
            c = np.sort(a + (b - a) * rng.uniform(0.05, 0.95, len(Q))) if len(Q) > 1 else Q[:, 1]
            P.append(np.column_stack([c - w, c, c + w * rng.uniform(0.5, 1.5, len(Q))]))
        est.append(ANFIS.from_params(mf='triangular', mf_params=P, consequents=e.consequents_,
                                     input_min=e.input_min_, input_max=e.input_max_,
                                     extrapolation=e.extrapolation))
    fm.estimators_ = est
    fm._compile()
    return fm


@pytest.fixture(scope='module', params=['plain', 'depth_scaled', 'wide'])
def model(request, small_model, depth_scaled_model, wide_model):
    return {'plain': small_model, 'depth_scaled': depth_scaled_model,
            'wide': wide_model}[request.param]


def test_wide_mfs_fire_more_than_two_per_input_and_paths_agree(wide_model, rng):
    """The case the old two-MF interval search could not evaluate."""
    X = _queries(wide_model, rng, 2000)
    e = wide_model.estimators_[1]
    u = X[:, 1:2]
    P = e.mf_params_[1]
    assert np.any(((u > P[:, 0]) & (u < P[:, 2])).sum(axis=1) >= 3)
    np.testing.assert_allclose(wide_model.predict(X), numpy_forces(wide_model, X), rtol=0,
                               atol=1e-12)
    np.testing.assert_allclose([wide_model.predict_one(*q) for q in X[:300]],
                               numpy_forces(wide_model, X[:300]), rtol=0, atol=1e-12)


def _queries(fm, rng, n=1500):
    lo = np.array([0.0, -0.06, -0.06, -0.001])
    hi = np.array([0.06, 0.06, 0.06, 0.022])
    if fm.scale_col_ < 0:
        lo, hi = fm.input_range_
        lo, hi = lo - 0.3 * (hi - lo), hi + 0.3 * (hi - lo)  # inside, in the band, saturated
    return lo + (hi - lo) * rng.uniform(0, 1, (n, 4))


def test_batch_jacobian_matches_central_differences(model, rng):
    X = _away_from_kinks(model, _queries(model, rng))
    assert len(X) > 1000
    F, J = model.predict(X, jacobian=True)
    np.testing.assert_allclose(F, numpy_forces(model, X), rtol=0, atol=1e-12)
    Jfd = _finite_differences(model, X)
    scale = np.abs(Jfd).max()
    np.testing.assert_allclose(J, Jfd, rtol=0, atol=1e-6 * scale)
    assert np.any(J != 0.0) and np.all(np.isfinite(J))


def test_single_query_jacobian_equals_batch(model, rng):
    X = _queries(model, rng, 300)
    F, J = model.predict(X, jacobian=True)
    for k in range(len(X)):
        f1, j1 = model.jacobian_one(*X[k])
        assert f1.shape == (3,) and j1.shape == (3, 4)
        np.testing.assert_array_equal(f1, F[k])
        np.testing.assert_array_equal(j1, J[k])
        np.testing.assert_allclose(f1, model.predict_one(*X[k]), rtol=0, atol=1e-12)


def test_jacobian_is_zero_where_inputs_saturate(small_model):
    lo, hi = small_model.input_range_
    span = hi - lo
    x = lo + 0.5 * span
    x[0] = hi[0] + 0.5 * span[0]  # x far past the trained range: memberships and consequent clamp
    _, J = small_model.jacobian_one(*x)
    np.testing.assert_array_equal(J[:, 0], 0.0)


def test_depth_scaled_model_ignores_x_and_gives_no_force_without_contact(depth_scaled_model):
    F, J = depth_scaled_model.jacobian_one(0.04, 0.01, -0.02, 0.0)
    np.testing.assert_array_equal(F, 0.0)
    np.testing.assert_array_equal(J[:, :3], 0.0)
    F, J = depth_scaled_model.jacobian_one(0.04, 0.01, -0.02, -0.003)
    np.testing.assert_array_equal(F, 0.0)
    np.testing.assert_array_equal(J, 0.0)


def test_float32_and_non_finite_inputs(small_model):
    X = np.array([[0.03, 0.01, 0.0, 0.008]], dtype=np.float32)
    F, J = small_model.predict(X, jacobian=True)
    F64, J64 = small_model.predict(X.astype(np.float64), jacobian=True)
    np.testing.assert_array_equal(F, F64)
    np.testing.assert_array_equal(J, J64)
    with pytest.raises(ValueError, match='non-finite input'):
        small_model.jacobian_one(0.03, np.nan, 0.0, 0.005)
    with pytest.raises(ValueError, match='non-finite input depth'):
        small_model.predict(np.array([[0.03, 0.0, 0.0, np.inf]]), jacobian=True)
