"""Triangular MFs: partition, constraint repair, the two-MF guarantee, derivatives."""
import numpy as np
import pytest
from hypothesis import given, strategies as st

from haptic_anfis.anfis import membership as mf


@pytest.mark.parametrize('m', [1, 2, 3, 5, 8])
def test_grid_partition_is_a_partition_of_unity(m):
    P = mf.grid_partition(-0.02, 0.05, m)
    mf.check(P, -0.02, 0.05)
    x = np.linspace(-0.02, 0.05, 1001)
    mu = mf.membership(x, P)
    if m == 1:  # one MF: positive everywhere; normalisation makes it the constant 1
        assert np.all(mu > 0)
    else:
        np.testing.assert_allclose(mu.sum(1), 1.0, atol=1e-12)


def test_membership_is_one_on_knots_and_zero_at_feet():
    P = mf.grid_partition(0.0, 1.0, 3)
    mu = mf.membership(np.array([0.0, 0.5, 1.0]), P)
    np.testing.assert_array_equal(mu, np.eye(3))


@pytest.mark.parametrize('bad', [
    np.zeros((4, 3)),                                    # everything coincident
    np.array([[0.5, 0.5, 0.5]] * 3),                     # degenerate triangles
    np.array([[0.6, 0.9, 1.0], [0.0, 0.1, 0.2], [0.3, 0.4, 0.5]]),  # peaks out of order
    np.array([[-1.0, 2.0, -3.0], [5.0, -5.0, 0.0]]),     # feet on the wrong side
    np.full((3, 3), np.nan),
])
def test_project_repairs_any_input(bad):
    P = mf.project(bad, 0.0, 1.0)
    mf.check(P, 0.0, 1.0)


@given(st.lists(st.floats(-2, 3, allow_nan=False), min_size=9, max_size=9),
       st.floats(0.0, 1.0))
def test_project_then_at_most_two_mfs_fire_and_some_fires(params, x):
    P = mf.project(np.array(params).reshape(3, 3), 0.0, 1.0)
    mf.check(P, 0.0, 1.0)
    mu = mf.membership(np.array([x]), P)[0]
    assert mu.sum() > 0.0
    nz = np.flatnonzero(mu)
    assert len(nz) <= 2 and (len(nz) < 2 or nz[1] == nz[0] + 1)


def test_project_is_idempotent_on_valid_parameters():
    P = mf.grid_partition(0.0, 1.0, 4)
    np.testing.assert_array_equal(mf.project(P, 0.0, 1.0), P)


def test_check_rejects_gaps_and_misplaced_edges():
    P = mf.grid_partition(0.0, 1.0, 3)
    gap = P.copy()
    gap[0, 2], gap[1, 0] = 0.2, 0.3   # c_0 < a_1: no MF fires in (0.2, 0.3)
    with pytest.raises(ValueError, match='overlap'):
        mf.check(gap, 0.0, 1.0)
    moved = P.copy()
    moved[0, 1] = 0.1
    with pytest.raises(ValueError, match='edges'):
        mf.check(moved, 0.0, 1.0)


def test_membership_gradient_matches_finite_differences_away_from_kinks(rng):
    P = np.array([[-0.4, 0.0, 0.45], [0.2, 0.5, 0.8], [0.55, 1.0, 1.3]])
    x = rng.uniform(0, 1, 400)
    kinks = np.concatenate(P)
    x = x[np.min(np.abs(x[:, None] - kinks[None, :]), axis=1) > 1e-3]
    g = mf.membership_grad(x, P)
    h = 1e-7
    for j in range(3):
        for k in range(3):
            Pp, Pm = P.copy(), P.copy()
            Pp[j, k] += h
            Pm[j, k] -= h
            fd = (mf.membership(x, Pp)[:, j] - mf.membership(x, Pm)[:, j]) / (2 * h)
            np.testing.assert_allclose(g[:, j, k], fd, atol=1e-5)
