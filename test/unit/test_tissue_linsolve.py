"""The FE linear solver that keeps its factorisation: exact on the factorised matrix, reuses the
factor (GMRES) for a nearby matrix, refactorises for a far one or a new size; singular input is
an error the Newton loop turns into a cut-back."""
import numpy as np
import pytest
import scipy.sparse as sp

from haptic_anfis.tissue.linsolve import ReusedFactorSolver


def _spd(n: int, seed: int, bulk: float = 1e3) -> sp.csr_matrix:
    """A symmetric positive definite sparse matrix with a stiff (bulk-like) rank-deficient part,
    the kind of conditioning a nearly incompressible tangent has."""
    rng = np.random.default_rng(seed)
    lap = sp.diags([-np.ones(n - 1), 2.0 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1])
    B = sp.random(n // 4, n, density=0.05, random_state=seed)
    return (lap + bulk * (B.T @ B) + sp.diags(rng.uniform(0.5, 1.5, n))).tocsr()


def test_reuses_the_factor_for_a_nearby_matrix_and_refactorises_otherwise():
    A = _spd(300, 0)
    b = np.random.default_rng(1).normal(size=300)
    s = ReusedFactorSolver(backend='scipy-superlu-sym')
    x = s(A, b)
    np.testing.assert_allclose(A @ x, b, rtol=1e-9, atol=1e-9)
    assert (s.factorisations, s.krylov_solves) == (1, 0)
    A2 = A + 1e-3 * sp.diags(np.linspace(0.5, 1.0, 300))  # the next Newton iteration's tangent
    x2 = s(A2, b)
    assert (s.factorisations, s.krylov_solves) == (1, 1)
    ref = np.linalg.solve(A2.toarray(), b)
    assert np.linalg.norm(x2 - ref) <= 1e-5 * np.linalg.norm(ref)
    A3 = _spd(300, 7)  # unrelated: GMRES cannot converge with the old factor in 25 iterations
    x3 = s(A3, b)
    np.testing.assert_allclose(A3 @ x3, b, rtol=1e-8, atol=1e-8)
    assert s.factorisations == 2
    x4 = s(_spd(200, 3), b[:200])  # another size: a new factorisation
    assert s.factorisations == 3 and x4.shape == (200,)


def test_singular_matrix_raises():
    A = sp.csr_matrix(np.diag([1.0, 0.0, 2.0]))
    with pytest.raises((RuntimeError, ArithmeticError)):
        ReusedFactorSolver(backend='scipy-superlu-sym')(A, np.ones(3))


def test_pardiso_ldl_solves_exactly_and_keeps_the_analysis_for_one_pattern():
    pytest.importorskip('pypardiso')
    from haptic_anfis.tissue.linsolve import PardisoLDLSolver

    A = _spd(300, 0)
    b = np.random.default_rng(1).normal(size=300)
    s = PardisoLDLSolver()
    np.testing.assert_allclose(A @ s(A, b), b, rtol=1e-8, atol=1e-8)
    A2 = A.copy()
    A2.data = A2.data * np.random.default_rng(2).uniform(0.9, 1.1, A2.nnz)
    A2 = 0.5 * (A2 + A2.T)  # same pattern, other values: a later Newton iteration's tangent
    np.testing.assert_allclose(A2 @ s(A2, b), b, rtol=1e-8, atol=1e-8)
    assert (s.factorisations, s.analyses) == (2, 1)
    A3 = _spd(300, 7)  # another pattern: analysed anew
    np.testing.assert_allclose(A3 @ s(A3, b), b, rtol=1e-8, atol=1e-8)
    assert (s.factorisations, s.analyses) == (3, 2)
    # symmetric indefinite (a tangent past a stability limit) is solved too
    D = sp.diags(np.r_[-np.ones(10), np.ones(290)])
    x = s((A + 50 * D).tocsr(), b)
    np.testing.assert_allclose((A + 50 * D) @ x, b, rtol=1e-7, atol=1e-7)


def test_pardiso_ldl_singular_matrix_raises():
    pytest.importorskip('pypardiso')
    from haptic_anfis.tissue.linsolve import PardisoLDLSolver

    A = sp.csr_matrix(np.diag([1.0, 0.0, 2.0]))
    with pytest.raises((RuntimeError, ArithmeticError)):
        PardisoLDLSolver()(A, np.ones(3))


@pytest.mark.parametrize('where', ['matrix', 'rhs'])
def test_pardiso_ldl_refuses_non_finite_systems_instead_of_aborting(where):
    """An inverted cell gives NaN in the tangent: MKL would abort the process; the solver raises
    ArithmeticError, which the Newton loop takes as a failed increment."""
    pytest.importorskip('pypardiso')
    from haptic_anfis.tissue.linsolve import PardisoLDLSolver
    A = sp.csr_matrix(np.array([[4.0, 1.0], [1.0, 3.0]]))
    b = np.array([1.0, 2.0])
    if where == 'matrix':
        A.data[0] = np.nan
    else:
        b[1] = np.inf
    with pytest.raises(ArithmeticError, match='non-finite'):
        PardisoLDLSolver()(A, b)
