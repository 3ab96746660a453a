"""Numerical hard cases of training and evaluation: ill-conditioned least squares, extreme input
scales, knots and out-of-range inputs of the depth-scaled form, float32 inputs, determinism."""
import itertools

import numpy as np
import pytest

from haptic_anfis.anfis import ANFIS, ForceModel, solve_consequents, train
from haptic_anfis.anfis.force_model import numpy_forces


def test_duplicate_samples_give_the_same_fit_as_weighted_unique_ones(rng):
    """Each sample repeated 20 times: Φ has rank ≤ n/20; the solve stays finite and equals the
    fit of the unique samples (duplication scales ΦᵀΦ, the relative ridge scales with it)."""
    X = rng.uniform(0, 1, (40, 2))
    t = np.sin(3 * X[:, 0]) * X[:, 1]
    a = train(X, t, (3, 3), epochs=5)
    b = train(np.repeat(X, 20, axis=0), np.repeat(t, 20), (3, 3), epochs=5)
    assert np.all(np.isfinite(b.model.coef))
    np.testing.assert_allclose(b.model.predict(X), a.model.predict(X), rtol=0, atol=1e-6)


def test_every_sample_identical_except_one_input(rng):
    """All rows but a constant-free input are duplicates of one point: no crash, no NaN."""
    X = np.tile([0.3, 0.6], (50, 1))
    X[:, 1] = np.linspace(0, 1, 50)
    X = np.vstack([X, [[1.0, 0.5], [0.0, 0.5]]])
    t = X[:, 1] ** 2
    res = train(X, t, (3, 3), epochs=3)
    assert np.all(np.isfinite(res.model.coef))
    assert np.all(np.isfinite(res.model.predict(np.random.default_rng(0).uniform(0, 1, (100, 2)))))


def test_unexcited_rules_of_a_scaled_fit_follow_the_global_trend(rng):
    """Depth-scaled least squares (rows × s) with every sample in one corner."""
    X = rng.uniform(0, 0.3, (60, 3))
    s = rng.uniform(0.5, 2.0, 60)
    g = 1.0 + X @ np.array([2.0, -1.0, 0.5])
    res = train(X, s * g, (3, 3, 3), epochs=2, scale=s, lo=np.zeros(3), hi=np.ones(3))
    far = rng.uniform(0.7, 1.0, (50, 3))
    np.testing.assert_allclose(res.model.predict(far), 1.0 + far @ np.array([2.0, -1.0, 0.5]),
                               atol=1e-5)


@pytest.mark.parametrize('unit', [1e-6, 1.0, 1e3])
def test_input_scale_does_not_change_the_fit(rng, unit):
    """The same problem in micrometres-sized and metre-sized inputs: identical predictions (the
    training normalises inputs; the ridge is relative)."""
    X = rng.uniform(0, 1, (200, 3))
    t = np.exp(-X[:, 0]) + X[:, 1] * X[:, 2]
    ref = train(X, t, (3, 2, 2), epochs=8).model.predict(X)
    got = train(X * unit, t, (3, 2, 2), epochs=8).model.predict(X * unit)
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-9)


def test_mixed_input_scales_in_one_model(rng):
    """1e-6 m next to 1 m in the same model: consequent slopes differ by 1e6, the fit is exact
    for a function linear in both."""
    X = np.column_stack([rng.uniform(0, 1e-6, 300), rng.uniform(0, 1.0, 300)])
    t = 3.0 + 2e6 * X[:, 0] - 4.0 * X[:, 1]
    res = train(X, t, (2, 3), epochs=3)
    np.testing.assert_allclose(res.model.predict(X), t, rtol=0, atol=1e-6)
    Phi = res.model.design_matrix(X)
    assert np.all(np.isfinite(solve_consequents(Phi, t, n_inputs=2)))


@pytest.fixture(scope='module')
def scaled(synthetic):
    return ForceModel(structure=[(3, 2, 2), (2, 3, 2), (2, 2, 3)], epochs=6).fit(
        synthetic.X, synthetic.Y, groups=synthetic.point)


def test_scaled_paths_agree_on_knots_corners_and_outside(scaled, synthetic, rng):
    lo, hi = scaled.input_range_
    knots = []
    for m in scaled.estimators_:
        for k in itertools.product(*[P[:, 1] for P in m.mf_params_]):
            knots.append([0.04, *k])
    corners = [np.where(np.array(c), hi, lo) for c in itertools.product((0, 1), repeat=4)]
    span = hi - lo
    X = np.vstack([synthetic.X, np.array(knots), np.array(corners),
                   lo + span * rng.uniform(-0.5, 1.5, (2000, 4))])
    F_np = numpy_forces(scaled, X)
    np.testing.assert_allclose(scaled.predict(X), F_np, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.array([scaled.predict_one(*x) for x in X]), F_np, rtol=0,
                               atol=1e-12)
    F_j, _ = scaled.predict(X, jacobian=True)
    np.testing.assert_allclose(F_j, F_np, rtol=0, atol=1e-12)
    assert np.all(np.isfinite(F_np))
    np.testing.assert_array_equal(F_np[X[:, 3] <= 0], 0.0)


def test_scaled_force_is_linear_in_depth_outside_the_trained_depths(scaled):
    """g saturates: below the shallowest and past the deepest sample F = depth · g(edge)."""
    lo, hi = scaled.input_range_
    y, z = 0.5 * (lo[1] + hi[1]), 0.5 * (lo[2] + hi[2])
    F = lambda d: np.array(scaled.predict_one(0.04, y, z, d))  # noqa: E731
    np.testing.assert_allclose(F(0.5 * lo[3]), 0.5 * F(lo[3]), rtol=1e-12)
    np.testing.assert_allclose(F(3 * hi[3]), 3 * F(hi[3]), rtol=1e-12)


@pytest.mark.parametrize('model_name', ['small_model', 'scaled'])
def test_float32_inputs_equal_float64_of_the_same_values(request, model_name, synthetic):
    model = request.getfixturevalue(model_name)
    X32 = synthetic.X[:50].astype(np.float32)
    X64 = X32.astype(np.float64)
    np.testing.assert_array_equal(numpy_forces(model, X32), numpy_forces(model, X64))
    np.testing.assert_array_equal(model.predict(X32), model.predict(X64))
    for a, b in zip(X32[:5], X64[:5]):
        assert model.predict_one(*a) == model.predict_one(*b)
        assert model.predict_one(*(np.float32(v) for v in a)) == model.predict_one(*b)


def test_training_is_deterministic_for_a_seed(synthetic):
    kw = dict(candidates=[(2, 2, 2), (3, 2, 2)], search_epochs=2, epochs=3, seed=4)
    a = ForceModel(**kw).fit(synthetic.X, synthetic.Y, groups=synthetic.point)
    b = ForceModel(**kw).fit(synthetic.X, synthetic.Y, groups=synthetic.point)
    assert a.structures_ == b.structures_
    for ma, mb in zip(a.estimators_, b.estimators_):
        assert np.array_equal(ma.consequents_, mb.consequents_)
        assert all(np.array_equal(P, Q) for P, Q in zip(ma.mf_params_, mb.mf_params_))


def test_single_query_path_takes_ints_and_numpy_scalars_and_rejects_the_rest(scaled):
    """predict_one / jacobian_one call the compiled float signature directly (no type dispatch):
    ints and numpy scalars convert to the same float query; a non-number raises TypeError (it never
    compiles a new specialisation in the servo loop); NaN raises ValueError naming the input."""
    ref = scaled.predict_one(0.04, 0.0, 0.0, 0.008)
    assert scaled.predict_one(0.04, np.int64(0), 0, np.float64(0.008)) == ref
    d32 = np.float32(0.008)
    assert scaled.predict_one(0.04, 0.0, 0.0, d32) == scaled.predict_one(0.04, 0.0, 0.0, float(d32))
    assert scaled.predict_one(0, 0, 0, 0) == (0.0, 0.0, 0.0)
    F, J = scaled.jacobian_one(np.float64(0.04), 0, 0.0, 0.008)
    np.testing.assert_array_equal(F, ref)
    with pytest.raises(TypeError):
        scaled.predict_one(0.04, object(), 0.0, 0.008)
    with pytest.raises(TypeError):
        scaled.jacobian_one(None, 0.0, 0.0, 0.008)
    with pytest.raises(ValueError, match='depth=nan'):
        scaled.predict_one(0.04, 0.0, 0.0, float('nan'))


def test_pickled_model_predicts_the_same(scaled, synthetic):
    import pickle
    clone = pickle.loads(pickle.dumps(scaled))
    X = synthetic.X[::7]
    np.testing.assert_array_equal(clone.predict(X), scaled.predict(X))
    assert [clone.predict_one(*x) for x in X] == [scaled.predict_one(*x) for x in X]
    np.testing.assert_array_equal(clone.jacobian_one(*X[3])[1], scaled.jacobian_one(*X[3])[1])


def test_no_hold_out_trains_every_output_on_all_the_data(synthetic, tmp_path):
    """val_fraction 0: no epoch hold-out; each output is the hybrid rule run for ``epochs`` epochs
    on all the data (its lowest-training-error epoch), and the model file still round-trips."""
    from haptic_anfis.anfis import train_on_dataset
    kw = dict(structure=(2, 3, 2), epochs=4, val_fraction=0)
    m = ForceModel(**kw).fit(synthetic.X, synthetic.Y, groups=synthetic.point)
    assert m.val_rmse_ == [None] * 3 and all(1 <= e <= 4 for e in m.best_epoch_)
    s = synthetic.X[:, 3]
    ref = ANFIS(n_mfs=(2, 3, 2), mf='triangular', epochs=4, ridge=m.ridges_[1],
                ridge_target='linear', extrapolation=(0.15, 0.15, 0.0)).fit(  # the force model's
        synthetic.X[:, 1:], synthetic.Y[:, 1] / s, sample_weight=s * s)
    np.testing.assert_array_equal(m.estimators_[1].consequents_, ref.consequents_)
    model, _ = train_on_dataset(synthetic, **kw)
    model.save(tmp_path / 'm.json')
    loaded = ForceModel.load(tmp_path / 'm.json')
    np.testing.assert_array_equal(loaded.predict(synthetic.X), model.predict(synthetic.X))
    with pytest.raises(ValueError, match='val_fraction 0'):
        ForceModel(structure=None, val_fraction=0, search_folds=1, epochs=2).fit(synthetic.X, synthetic.Y,
                                                                  groups=synthetic.point)


def test_the_step_guard_keeps_the_training_error_from_rising(synthetic):
    """With the guard (the default) no epoch ends above the previous one; without it a large
    initial step overshoots and the error goes up at least once."""
    X = synthetic.X[:, 1:]
    t = synthetic.Y[:, 2]
    kw = dict(step=0.5, ridge=1e-6, scale=synthetic.X[:, 3])
    guarded = train(X, t, (3, 3, 2), 25, **kw)
    assert np.all(np.diff(guarded.train_rmse) <= 0.0)
    free = train(X, t, (3, 3, 2), 25, guard=False, **kw)
    assert np.any(np.diff(free.train_rmse) > 0.0)


def test_the_force_model_is_three_triangular_estimators_whose_mfs_can_widen(scaled):
    """Every MF parameter is free (3 per triangle): trained feet pass the neighbouring peak, which
    the pinned partition of format version 2 forbade."""
    assert [type(e).__name__ for e in scaled.estimators_] == ['ANFIS'] * 3
    widened = False
    for e, st in zip(scaled.estimators_, scaled.structures_):
        assert e.mf == 'triangular'
        assert e.n_params_ == 3 * sum(st) + int(np.prod(st)) * (len(st) + 1)
        for P in e.mf_params_:
            widened |= bool(np.any(P[1:, 0] < P[:-1, 1]) or np.any(P[:-1, 2] > P[1:, 1]))
    assert widened


def test_epochs_per_output(synthetic):
    """One epoch count per output (Fx, Fy, Fz), recorded as given; a wrong count is one line."""
    m = ForceModel(structure=(2, 2, 2), epochs=[2, 3, 4]).fit(synthetic.X, synthetic.Y,
                                                                groups=synthetic.point)
    assert m.best_epoch_ == [2, 3, 4] and m.metadata_['training']['epochs'] == [2, 3, 4]
    for bad in (0, [1, 2], [1, 2, 0], True):
        with pytest.raises(ValueError, match=r'epochs: expected an integer >= 1, got .*one per'):
            ForceModel(structure=(2, 2, 2), epochs=bad).fit(synthetic.X, synthetic.Y)
