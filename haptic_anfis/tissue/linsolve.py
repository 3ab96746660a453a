"""Linear solves for the FE Newton iterations, reusing one factorisation across many systems.

Profiled on the validated mesh (6 cells across the probe, ~4.4k free DOF, ~3e5 non-zeros after
felupe's static condensation): SciPy's default ``spsolve`` (SuperLU, COLAMD ordering) took ~1.3 s
per Newton iteration, 90 % of a point's wall time, while assembly took ~0.09 s. The tangent is
symmetric and changes little between Newton iterations and between load steps, so:

1. factorise with SuperLU in symmetric mode (minimum-degree ordering on A + A^T, no pivoting
   search): ~0.45 s instead of ~1.3 s, back-solve ~3 ms;
2. keep that factor and solve the next systems by GMRES preconditioned with it (a few Krylov
   iterations of one mat-vec and one back-solve each); refactorise only when GMRES does not reach
   ``rtol`` within ``maxiter`` iterations (or the size changes). The test is on the
   preconditioned residual, i.e. on the error of the solution: the plain residual of this nearly
   incompressible tangent stays large for an accurate solution (it is scaled by the bulk modulus).

Newton's own convergence test (felupe: residual norm) is unchanged, so an inexact linear solve
costs at most an extra Newton iteration, never accuracy.

With ``pypardiso`` importable (extra ``fe-fast``, MKL) the default is :class:`PardisoLDLSolver`
instead: a symmetric-indefinite LDL^T factorisation of the upper triangle (MKL PARDISO, METIS
ordering, Bunch-Kaufman pivoting) at every Newton iteration, the fill-reducing analysis kept while
the sparsity pattern stays the same (it does for the whole load path of one mesh). Profiled
(cProfile, CPU time) on a nodular point (~3.3k free DOF, 2.3e5 non-zeros, 1.75e6 in SuperLU's
L + U): ~35 ms per factorisation against SuperLU's ~90 ms, so a fresh exact factor each
iteration costs less than the Krylov iterations the kept factor needs (~15 back-solves of
~1.4 ms per system, and about as many wasted before each refactorisation); the per-point times
before / after are bench/bench_fe_point.py's.
"""
from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import LinearOperator, gmres, splu

from ..optional import optional

pypardiso = optional('pypardiso')  # MKL PARDISO: the 'fe-fast' extra (loads MKL, ~700 MB)

__all__ = ['PardisoLDLSolver', 'ReusedFactorSolver', 'factorise', 'backend_name']


def backend_name() -> str:
    """'pypardiso' when importable (MKL PARDISO factorisation), else 'scipy-superlu-sym'."""
    if pypardiso is not None:
        try:
            pypardiso.PyPardisoSolver   # the first use runs the import (MKL may be missing)
            return 'pypardiso'
        except ImportError:
            pass
    return 'scipy-superlu-sym'


class _Pardiso:
    """A kept pypardiso factorisation exposing ``solve(b)``."""

    def __init__(self, A) -> None:
        self.A = A.tocsr()
        self.ps = pypardiso.PyPardisoSolver()
        try:  # PyPardisoError is no RuntimeError: the Newton loop must see one to cut back
            self.ps.factorize(self.A)
        except pypardiso.pardiso_wrapper.PyPardisoError as exc:
            raise RuntimeError(str(exc)) from None

    def solve(self, b: np.ndarray) -> np.ndarray:
        return np.asarray(self.ps.solve(self.A, b)).ravel()


def factorise(A, backend: str | None = None) -> Any:
    """A factorisation of the sparse matrix ``A`` with a ``solve(b)`` method.

    Raises:
        RuntimeError: ``A`` is singular (SuperLU's error, which the Newton loop treats as a
            failed increment).
    """
    backend = backend or backend_name()
    if backend == 'pypardiso':
        return _Pardiso(A)

    return splu(A.tocsc(), permc_spec='MMD_AT_PLUS_A', diag_pivot_thresh=0.0,
                options={'SymmetricMode': True})


class ReusedFactorSolver:
    """``solver(A, b) -> x`` for felupe's Newton loop, keeping the last factorisation.

    Args:
        rtol: relative preconditioned residual ||M^-1 (b - A x)|| / ||M^-1 b|` (about the
            relative error of x) GMRES must reach with the kept factor M.
        maxiter: Krylov iterations allowed before refactorising.
        backend: 'pypardiso' or 'scipy-superlu-sym' (default: :func:`backend_name`).

    Counters ``factorisations`` and ``krylov_solves`` say what happened (for benchmarks).
    """

    def __init__(self, rtol: float = 1e-6, maxiter: int = 25, backend: str | None = None
                 ) -> None:
        self.rtol, self.maxiter = float(rtol), int(maxiter)
        self.backend = backend or backend_name()
        self.factor: Any = None
        self.shape: tuple[int, int] | None = None
        self.factorisations = 0
        self.krylov_solves = 0
        self.krylov_iterations = 0

    def reset(self) -> None:
        """Forget the kept factorisation (e.g. after a cut-back restored an older state)."""
        self.factor, self.shape = None, None

    def __call__(self, A, b) -> np.ndarray:

        b = np.asarray(b, dtype=float).ravel()
        if self.factor is not None and self.shape == A.shape:
            count = [0]

            def cb(_):
                count[0] += 1

            # GMRES on the left-preconditioned system M^-1 A x = M^-1 b: its residual is
            # M^-1 (b - A x) ~ A^-1 (b - A x), the error of x itself. (The unpreconditioned
            # residual of the nearly incompressible tangent stays large for an accurate x: its
            # norm is dominated by the bulk modulus.)
            solve = self.factor.solve
            MA = LinearOperator(A.shape, matvec=lambda v: solve(A @ v), dtype=float)
            with np.errstate(all='ignore'):
                x, info = gmres(MA, solve(b), rtol=self.rtol, atol=0.0, restart=self.maxiter,
                                maxiter=1, callback=cb, callback_type='pr_norm')
            if info == 0 and np.all(np.isfinite(x)):
                self.krylov_solves += 1
                self.krylov_iterations += count[0]
                return x
        self.factor = factorise(A, self.backend)
        self.shape = A.shape
        self.factorisations += 1
        x = np.asarray(self.factor.solve(b)).ravel()
        if not np.all(np.isfinite(x)):
            self.reset()
            raise ArithmeticError('linear solve produced non-finite values')
        return x


class PardisoLDLSolver:
    """``solver(A, b) -> x`` for felupe's Newton loop: a fresh LDL^T factorisation of the
    symmetric ``A`` (its upper triangle; MKL PARDISO, matrix type -2) for every system.

    The ordering and symbolic analysis (PARDISO phase 11) are kept and reused while the sparsity
    pattern of ``A`` is unchanged; each call does the numerical factorisation and solve
    (phase 23). Needs ``pypardiso``.

    Counters ``factorisations`` (numerical) and ``analyses`` (symbolic) say what happened.

    Raises (from a call):
        RuntimeError: PARDISO reports an error (e.g. a structurally singular matrix), which the
            Newton loop treats as a failed increment.
        ArithmeticError: the solution has non-finite values.
    """

    backend = 'pypardiso-ldl'

    def __init__(self) -> None:
        self._ps = pypardiso.PyPardisoSolver(mtype=-2)
        self._error = pypardiso.pardiso_wrapper.PyPardisoError
        self._key: tuple[np.ndarray, np.ndarray] | None = None  # A's kept pattern
        self._keep: np.ndarray | None = None  # which of A's entries are in the upper triangle
        self._U = None
        self.factorisations = 0
        self.analyses = 0

    def _pardiso(self, phase: int, U, b: np.ndarray) -> np.ndarray:
        self._ps.set_phase(phase)
        try:
            return np.asarray(self._ps._call_pardiso(U, b)).ravel()
        except self._error as exc:  # not a RuntimeError: the Newton loop must see one
            self._key = None  # analyse again next time
            raise RuntimeError(str(exc)) from None

    def _upper(self, A):
        """The upper triangle of ``A`` (CSR, sorted indices, float64); the index arrays and the
        selection of ``A``'s entries are reused while ``A``'s pattern is the kept one."""
        A = A.tocsr()
        if not A.has_sorted_indices:
            A = A.sorted_indices()
        key = self._key
        if (key is not None and key[0].shape == A.indptr.shape and key[1].shape == A.indices.shape
                and np.array_equal(key[0], A.indptr) and np.array_equal(key[1], A.indices)):
            U = self._U
            U.data = np.asarray(A.data[self._keep], dtype=np.float64)
            return U, False
        rows = np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))
        keep = A.indices >= rows
        U = sp.csr_matrix((np.asarray(A.data[keep], dtype=np.float64), A.indices[keep],
                           np.r_[0, np.cumsum(np.bincount(rows[keep], minlength=A.shape[0]))]),
                          shape=A.shape)
        if np.any(np.diff(U.indptr) == 0):  # PARDISO crashes on an empty row
            raise RuntimeError('linear solve: the matrix has an empty row (singular)')
        self._key, self._keep, self._U = (A.indptr.copy(), A.indices.copy()), keep, U
        return U, True

    def __call__(self, A, b) -> np.ndarray:
        b = np.asarray(b, dtype=float).ravel()
        U, new_pattern = self._upper(A)
        # MKL aborts the whole process on a NaN/Inf matrix (an inverted cell's tangent): refuse
        # it here so the Newton loop cuts the increment back instead.
        if not (np.all(np.isfinite(U.data)) and np.all(np.isfinite(b))):
            raise ArithmeticError('linear solve: the system has non-finite values')
        if new_pattern:
            self._pardiso(11, U, b)
            self.analyses += 1
        x = self._pardiso(23, U, b)
        self.factorisations += 1
        if not np.all(np.isfinite(x)):
            raise ArithmeticError('linear solve produced non-finite values')
        return x
