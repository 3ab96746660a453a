"""The ANFIS engine: equations, gradients, least squares, out-of-range policy, evaluation paths."""
import itertools

import numpy as np
import pytest
from hypothesis import given, strategies as st

from haptic_anfis.anfis import ForceModel, SugenoModel, solve_consequents, train
from haptic_anfis.anfis import membership as mf
from haptic_anfis.anfis.force_model import numpy_forces
from force_models import assemble


def random_model(structure, rng, lo=None, hi=None, jitter=0.3):
    d = len(structure)
    lo = np.zeros(d) if lo is None else lo
    hi = np.ones(d) if hi is None else hi
    mfs = []
    for i, m in enumerate(structure):
        P = mf.grid_partition(lo[i], hi[i], m)
        P = P + jitter * (hi[i] - lo[i]) / max(m, 2) * rng.uniform(-1, 1, P.shape)
        mfs.append(mf.project(P, lo[i], hi[i]))
    R = int(np.prod(structure))
    return SugenoModel(mfs=mfs, coef=rng.normal(size=(R, d + 1)), lo=lo, hi=hi)


def reference_predict(model, X):
    """The paper's equations literally: firing = product over inputs, normalise over all rules."""
    Xm, Xe = model.clamp(X)
    out = []
    for x, xe in zip(Xm, Xe):
        mus = [mf.membership(np.array([x[i]]), P)[0] for i, P in enumerate(model.mfs)]
        w = np.array([np.prod([mus[i][j] for i, j in enumerate(idx)])
                      for idx in itertools.product(*(range(len(P)) for P in model.mfs))])
        f = model.coef[:, :-1] @ xe + model.coef[:, -1]
        out.append(w @ f / w.sum())
    return np.array(out)


def test_forward_pass_matches_the_paper_equations(rng):
    model = random_model((3, 2, 4, 2), rng)
    X = rng.uniform(-0.2, 1.2, (200, 4))  # inside and outside the domain
    np.testing.assert_allclose(model.predict(X), reference_predict(model, X), rtol=1e-12, atol=1e-12)


def test_mf_gradient_matches_finite_differences_away_from_kinks(rng):
    model = random_model((3, 3, 2, 2), rng)
    X = rng.uniform(0, 1, (300, 4))
    kinks = [np.concatenate(P) for P in model.mfs]
    far = np.all([np.min(np.abs(X[:, i:i + 1] - kinks[i][None]), axis=1) > 2e-3 for i in range(4)],
                 axis=0)
    X = X[far]
    t = np.sin(3 * X).sum(1)
    grads, _ = model.mf_gradient(X, t)
    h = 1e-7
    for i, P in enumerate(model.mfs):
        for j in range(len(P)):
            for k in range(3):
                pinned = (j == 0 and k < 2) or (j == len(P) - 1 and k > 0)
                if pinned:
                    assert grads[i][j, k] == 0.0
                    continue
                E = []
                for s in (+h, -h):
                    m2 = SugenoModel([Q.copy() for Q in model.mfs], model.coef, model.lo, model.hi)
                    m2.mfs[i][j, k] += s
                    E.append(0.5 * np.sum((m2.predict(X) - t) ** 2))
                fd = (E[0] - E[1]) / (2 * h)
                assert grads[i][j, k] == pytest.approx(fd, rel=1e-4, abs=1e-6), (i, j, k)


def test_least_squares_stays_finite_and_accurate_when_underdetermined(rng):
    """128 rules x 5 = 640 unknowns against 600 samples; the grid also makes columns dependent."""
    structure = (4, 4, 4, 2)
    model = random_model(structure, rng, jitter=0.0)
    X = rng.uniform(0, 1, (600, 4))
    t = 1.0 + X[:, 0] ** 2 - np.cos(2 * X[:, 1]) + X[:, 2] * X[:, 3]
    Phi = model.design_matrix(X)
    assert Phi.shape == (600, 640)
    assert np.linalg.matrix_rank(Phi) < 600  # genuinely rank deficient
    theta = solve_consequents(Phi, t, n_inputs=4)
    assert np.all(np.isfinite(theta))
    assert np.abs(theta).max() < 1e3  # min-norm least squares gives huge coefficients here
    model.coef = theta.reshape(128, 5)
    X_new = rng.uniform(0, 1, (2000, 4))
    t_new = 1.0 + X_new[:, 0] ** 2 - np.cos(2 * X_new[:, 1]) + X_new[:, 2] * X_new[:, 3]
    assert np.sqrt(np.mean((model.predict(X_new) - t_new) ** 2)) < 0.02


def test_least_squares_with_unexcited_rules_falls_back_to_global_linear_trend(rng):
    # All samples in one corner: most rules never fire; they must carry the global linear fit.
    model = random_model((3, 3, 3, 3), rng, jitter=0.0)
    X = rng.uniform(0, 0.3, (50, 4))
    t = 2.0 + X @ np.array([1.0, -2.0, 0.5, 3.0])
    model.coef = solve_consequents(model.design_matrix(X), t, n_inputs=4).reshape(81, 5)
    far = rng.uniform(0.7, 1.0, (100, 4))
    np.testing.assert_allclose(model.predict(far), 2.0 + far @ np.array([1.0, -2.0, 0.5, 3.0]),
                               atol=1e-6)


def test_least_squares_handles_zero_and_degenerate_design():
    assert np.all(solve_consequents(np.zeros((10, 10)), np.ones(10), n_inputs=1) == 0.0)


def test_reproduces_a_smooth_four_input_function(rng):
    """A known smooth function to a stated accuracy: RMSE < 1 % of its range on unseen points."""
    f = lambda X: np.exp(-X[:, 0]) * (1 + X[:, 1]) + np.sin(2 * X[:, 2]) * X[:, 3]  # noqa: E731
    X = rng.uniform(0, 1, (600, 4))
    Xc = rng.uniform(0, 1, (150, 4))
    res = train(X, f(X), (3, 3, 3, 3), epochs=30, X_check=Xc, t_check=f(Xc))
    Xt = rng.uniform(0, 1, (3000, 4))
    err = np.sqrt(np.mean((res.model.predict(Xt) - f(Xt)) ** 2))
    assert err < 0.01 * np.ptp(f(Xt)), err
    assert 1 <= res.best_epoch <= 30
    assert res.check_rmse[res.best_epoch - 1] == min(res.check_rmse)


def test_training_keeps_mfs_valid_after_every_step(rng):
    X = rng.uniform(0, 1, (300, 4))
    t = np.where(X[:, 0] > 0.5, 1.0, 0.0) + X[:, 1]  # a step: strong gradients on input 0
    res = train(X, t, (4, 2, 2, 2), epochs=25, step=0.2)  # a large step invites reordering
    for i, P in enumerate(res.model.mfs):
        mf.check(P, res.model.lo[i], res.model.hi[i])
    assert res.train_rmse[res.best_epoch - 1] <= res.train_rmse[0]


def test_degenerate_initial_mf_parameters_are_repaired(rng):
    X = rng.uniform(0, 1, (200, 2))
    t = X[:, 0] + X[:, 1] ** 2
    res = train(X, t, (3, 3), epochs=5, initial_mfs=[np.zeros((3, 3)), np.full((3, 3), 0.5)])
    for i, P in enumerate(res.model.mfs):
        mf.check(P, res.model.lo[i], res.model.hi[i])
    assert res.train_rmse[-1] < 0.05


def test_constant_input_gives_a_clear_error(rng):
    X = rng.uniform(0, 1, (50, 4))
    X[:, 2] = 0.3
    with pytest.raises(ValueError, match='input 2 takes a single value'):
        train(X, X[:, 0], (2, 2, 2, 2), epochs=2)


# ---- out-of-range policy, knots, corners, NaN ----------------------------------------------------

def test_out_of_range_never_silent_zero_or_nan(small_model):
    lo, hi = small_model.input_range_
    span = hi - lo
    from haptic_anfis.tissue.synthetic import surface_x
    # Far outside every input, including impossible combinations: finite.
    far = np.array([lo - 10 * span, hi + 10 * span, [lo[0], hi[1], lo[2], hi[3] * 5]])
    assert np.all(np.isfinite(small_model.predict(far)))
    # Contact points on the tissue surface beyond the palpated disc, depths in and past the
    # trained range: the tissue still pushes back.
    ang = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    r = 0.062
    y, z = r * np.cos(ang), r * np.sin(ang)
    x = surface_x(y, z, (0.045, 0.070, 0.070))
    for depth in (0.5 * (lo[3] + hi[3]), hi[3], 1.2 * hi[3], 3 * hi[3]):
        F = small_model.predict(np.column_stack([x, y, z, np.full_like(x, depth)]))
        assert np.all(np.isfinite(F))
        assert np.all(F[:, 0] > 0.1), (depth, F[:, 0])
    # Shallower than the shallowest sample: the force falls toward zero, stays finite.
    shallow = np.tile(0.5 * (lo + hi), (3, 1))
    shallow[:, 3] = [lo[3], 0.5 * lo[3], 0.0]
    Fs = small_model.predict(shallow)[:, 0]
    assert np.all(np.isfinite(Fs)) and Fs[0] > Fs[1] > Fs[2]


def test_out_of_range_extrapolates_linearly_then_saturates(small_model):
    lo, hi = small_model.input_range_
    centre = 0.5 * (lo + hi)
    deep = np.tile(centre, (6, 1))
    depth_span = hi[3] - lo[3]
    deep[:, 3] = hi[3] + depth_span * np.array([0.0, 0.1, 0.2, 0.25, 0.5, 5.0])
    F = small_model.predict(deep)[:, 0]
    # Linear in depth within the band (equal steps -> equal increments), constant beyond it.
    assert F[1] - F[0] == pytest.approx(F[2] - F[1], rel=1e-9)
    assert F[3] == pytest.approx(F[4]) and F[4] == pytest.approx(F[5])
    assert F[3] > F[0]  # deeper than trained: more force, not less


def test_continuous_across_the_domain_edge(small_model):
    lo, hi = small_model.input_range_
    x = 0.5 * (lo + hi)
    for i in range(4):
        for edge in (lo[i], hi[i]):
            a, b = x.copy(), x.copy()
            a[i], b[i] = edge - 1e-12, edge + 1e-12
            Fa, Fb = small_model.predict(np.array([a, b]))
            np.testing.assert_allclose(Fa, Fb, atol=1e-7)  # slopes are ~1e3 N/m at most


def test_all_paths_agree_on_knots_corners_and_outside(small_model, synthetic, rng):
    lo, hi = small_model.input_range_
    span = hi - lo
    knots = []
    for m in small_model.estimators_:
        grid = [P[:, 1] for P in m.mf_params_]
        knots += [np.array(k) for k in itertools.product(*grid)]
    corners = [np.where(np.array(c), hi, lo) for c in itertools.product((0, 1), repeat=4)]
    X = np.vstack([synthetic.X, np.array(knots), np.array(corners),
                   lo + span * rng.uniform(-0.5, 1.5, (2000, 4))])
    F_np = numpy_forces(small_model, X)
    F_jit = small_model.predict(X)
    F_one = np.array([small_model.predict_one(*x) for x in X])
    np.testing.assert_allclose(F_jit, F_np, rtol=0, atol=1e-12)
    np.testing.assert_allclose(F_one, F_np, rtol=0, atol=1e-12)


@pytest.mark.parametrize('bad', [np.nan, np.inf, -np.inf])
def test_non_finite_input_raises_clear_error(small_model, bad):
    with pytest.raises(ValueError, match='non-finite input'):
        small_model.predict_one(0.03, bad, 0.0, 0.005)
    with pytest.raises(ValueError, match=r'non-finite input depth'):
        small_model.predict(np.array([[0.03, 0.0, 0.0, bad]]))
    with pytest.raises(ValueError, match=r'non-finite input x'):
        small_model.predict(np.array([[bad, 0.0, 0.0, 0.0]]))


def test_no_underflow_with_tiny_memberships():
    """Memberships of 1e-200 on every input: their product underflows, the per-input
    normalisation does not."""
    lo, hi = np.zeros(4), np.ones(4)
    mfs = []
    for _ in range(4):
        P = mf.grid_partition(0.0, 1.0, 2)
        mfs.append(P)
    model = SugenoModel(mfs=mfs, coef=np.tile([0, 0, 0, 0, 1.0], (16, 1)) + np.arange(16)[:, None]
                        * np.array([0, 0, 0, 0, 1.0]), lo=lo, hi=hi)
    x = np.full((1, 4), 1e-200)  # MF 1 grade 1e-200 on every input; product 1e-800 -> 0 in float
    y = model.predict(x)[0]
    assert np.isfinite(y) and y == pytest.approx(1.0)  # rule (0,0,0,0) has q = 1
    fm = assemble([model] * 3)
    assert fm.predict_one(*x[0]) == pytest.approx((y, y, y))


@given(st.tuples(*[st.floats(-1.0, 2.0, allow_nan=False)] * 4))
def test_property_outputs_finite_and_paths_agree(small_model, q):
    lo, hi = small_model.input_range_
    x = lo + (hi - lo) * np.array(q)
    a = np.array(small_model.predict_one(*x))
    b = small_model.predict(x[None])[0]
    assert np.all(np.isfinite(a))
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)


@pytest.mark.slow  # > 5 s: out of the developer loop (docs/tests.md)
def test_fit_on_synthetic_tissue_meets_paper_level_accuracy(synthetic):
    """The end-to-end protocol (structure search, hybrid learning) on the synthetic fixture."""
    from haptic_anfis.anfis import train_on_dataset
    model, test = train_on_dataset(synthetic, structure=None, search_folds=3,
                                   val_fraction=0.2, search_epochs=15, epochs=30)
    r = model.metadata_['rmse']['test']
    # Test errors on surface points never seen in training, vs the force range (~11 N / ~2.5 N).
    assert r[0] < 0.15 and r[1] < 0.02 and r[2] < 0.02, r
    for o in range(3):
        cands = model.metadata_['training']['candidates'][o]
        assert len(cands) >= 5
        chosen = model.structures_[o]
        best = min(c['val_rmse'] for c in cands)
        assert any(tuple(c['structure']) == chosen and c['val_rmse'] <= best * 1.05 for c in cands)


def test_structure_search_k_fold_scores_every_training_point(rng):
    """k-fold scoring: each candidate is trained once per fold; a candidate's score is the root
    mean of its fold scores, so it can be checked by hand."""
    from haptic_anfis.anfis import search_structure
    from haptic_anfis.anfis.training import train as train_one

    X = rng.random((120, 2))
    t = np.sin(3 * X[:, 0]) + X[:, 1] ** 2
    folds = [(np.setdiff1d(np.arange(120), v), v) for v in np.array_split(rng.permutation(120), 3)]
    res = search_structure(X, t, candidates=[(2, 2), (3, 2)], epochs=3, folds=folds)
    by_hand = []
    for f, v in folds:
        r = train_one(X[f], t[f], (3, 2), 3, X_check=X[v], t_check=t[v], lo=None, hi=None)
        by_hand.append(r.check_rmse[r.best_epoch - 1])
    got = next(c for c in res.candidates if c.structure == (3, 2))
    assert got.val_rmse == pytest.approx(np.sqrt(np.mean(np.square(by_hand))), rel=1e-12)
    with pytest.raises(ValueError, match='either'):
        search_structure(X, t, epochs=3)
    with pytest.raises(ValueError, match='either'):
        search_structure(X, t, X[:10], t[:10], epochs=3, folds=folds)


@pytest.mark.parametrize('bad', [0, -2, 2.5, True])
def test_search_folds_must_be_a_positive_integer(synthetic, bad):
    with pytest.raises(ValueError, match='search_folds'):
        ForceModel(search_folds=bad).fit(synthetic.X, synthetic.Y, groups=synthetic.point)


def test_search_folds_capped_by_points_and_recorded(synthetic):
    pts = np.unique(synthetic.point)
    few = np.isin(synthetic.point, pts[np.linspace(0, len(pts) - 1, 4).astype(int)])
    X = synthetic.X[few]
    assert np.all(np.ptp(X, axis=0) > 0)
    m = ForceModel(search_folds=5, candidates=[(2, 2, 2, 2)], search_epochs=2, epochs=2, form='plain')
    m.fit(X, synthetic.Y[few], groups=synthetic.point[few])  # 4 points: 4 folds, not 5
    assert m.metadata_['training']['search_folds'] == 5


def test_ridge_is_chosen_with_the_structure_on_the_same_folds(rng):
    """``ridges``: every structure is scored with each ridge on the same folds (each score checked
    by hand); the chosen pair is the smallest structure within tol, then its best ridge."""
    from haptic_anfis.anfis import search_structure
    from haptic_anfis.anfis.training import train as train_one

    X = rng.random((90, 2))
    t = np.sin(4 * X[:, 0]) * X[:, 1] + 0.05 * rng.standard_normal(90)  # noisy: ridge matters
    folds = [(np.setdiff1d(np.arange(90), v), v) for v in np.array_split(rng.permutation(90), 3)]
    ridges = [1e-6, 1e-2, 1.0]
    res = search_structure(X, t, candidates=[(2, 2), (4, 4)], epochs=3, folds=folds,
                           ridges=ridges, tol=0.0, ridge=123.0)  # the ladder overrides ridge
    assert len(res.candidates) == 6
    assert {(c.structure, c.ridge) for c in res.candidates} == {
        (s, r) for s in [(2, 2), (4, 4)] for r in ridges}
    for c in res.candidates:
        fold = []
        for f, v in folds:
            r = train_one(X[f], t[f], c.structure, 3, X_check=X[v], t_check=t[v], ridge=c.ridge)
            fold.append(r.check_rmse[r.best_epoch - 1])
        assert c.val_rmse == pytest.approx(np.sqrt(np.mean(np.square(fold))), rel=1e-12)
    best = min(res.candidates, key=lambda c: c.val_rmse)
    assert (res.chosen.structure, res.chosen.ridge) == (best.structure, best.ridge)
    # with a wide tolerance the smaller structure wins, with its own best ridge
    loose = search_structure(X, t, candidates=[(2, 2), (4, 4)], epochs=3, folds=folds,
                             ridges=ridges, tol=10.0)
    small = min((c for c in loose.candidates if c.structure == (2, 2)), key=lambda c: c.val_rmse)
    assert (loose.chosen.structure, loose.chosen.ridge) == ((2, 2), small.ridge)
    for bad in ([], [np.nan], [-1.0]):
        with pytest.raises(ValueError, match='ridges'):
            search_structure(X, t, candidates=[(2, 2)], epochs=1, folds=folds, ridges=bad)


def test_force_model_keeps_the_chosen_ridge_per_output_and_refits_with_it(synthetic, tmp_path):
    m = ForceModel(candidates=[(2, 2, 2), (3, 3, 2)], ridge_candidates=[1e-6, 1e-3],
                   search_epochs=2, epochs=3, search_folds=3)
    m.fit(synthetic.X, synthetic.Y, groups=synthetic.point)
    assert len(m.ridges_) == 3 and set(m.ridges_) <= {1e-6, 1e-3}
    tr = m.metadata_['training']
    assert tr['ridge_candidates'] == [1e-6, 1e-3]
    for o in range(3):  # the recorded choice is a scored candidate of that output
        assert any(c['ridge'] == m.ridges_[o] and tuple(c['structure']) == m.structures_[o]
                   for c in tr['candidates'][o])
    # refit with the chosen structures and ridges (what the case's grouped CV does)
    again = ForceModel(structure=m.structures_, ridge=m.ridges_, search_epochs=2, epochs=3)
    again.fit(synthetic.X, synthetic.Y, groups=synthetic.point)
    assert again.ridges_ == m.ridges_
    m.save(tmp_path / 'm.json')  # a loaded model knows the ridges it was trained with
    assert ForceModel.load(tmp_path / 'm.json').ridges_ == m.ridges_
    with pytest.raises(ValueError, match='ridge_candidates'):
        ForceModel(structure=(2, 2, 2), ridge_candidates=[1e-6]).fit(
            synthetic.X, synthetic.Y, groups=synthetic.point)
    for bad in ([1e-6, 1e-6], [np.nan] * 3, -1.0):
        with pytest.raises(ValueError, match='ridge'):
            ForceModel(structure=(2, 2, 2), ridge=bad).fit(synthetic.X, synthetic.Y,
                                                           groups=synthetic.point)
