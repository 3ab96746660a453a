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
costs at most an extra Newton iteration, never accuracy. ``pypardiso`` (optional extra
``fe-fast``) factorises when importable.
"""
from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ['ReusedFactorSolver', 'factorise', 'backend_name']


def backend_name() -> str:
    """'pypardiso' when importable (MKL PARDISO factorisation), else 'scipy-superlu-sym'."""
    try:
        import pypardiso  # noqa: F401

        return 'pypardiso'
    except ImportError:
        return 'scipy-superlu-sym'


class _Pardiso:
    """A kept pypardiso factorisation exposing ``solve(b)``."""

    def __init__(self, A) -> None:
        import pypardiso

        self.A = A.tocsr()
        self.ps = pypardiso.PyPardisoSolver()
        self.ps.factorize(self.A)

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
    from scipy.sparse.linalg import splu

    return splu(A.tocsc(), permc_spec='MMD_AT_PLUS_A', diag_pivot_thresh=0.0,
                options={'SymmetricMode': True})


class ReusedFactorSolver:
    """``solver(A, b) -> x`` for felupe's Newton loop, keeping the last factorisation.

    Args:
        rtol: relative preconditioned residual ||M^-1 (b - A x)|| / ||M^-1 b|` (about the
            relative error of x) GMRES must reach with the kept factor M.
        maxiter: Krylov iterations allowed before refactorising.
        backend: 'pypardiso' or 'scipy-superlu-sym' (default: :func:`backend_name`).
        newton_tol: the Newton loop's residual tolerance [N]; when given, each Krylov solve is
            only as accurate as the Newton iteration needs (an inexact Newton method,
            Eisenstat & Walker 1996, SIAM J. Sci. Comput. 17:16, their choice 2 with
            gamma = 0.9, alpha = 2): the tolerance follows the square of the last residual
            reduction, capped at :attr:`eta_max` (also for a new load step, whose right-hand
            side is larger than the last one), and is never tighter than needed to bring the
            error's share of the next residual below half of ``newton_tol``, nor than ``rtol``.
            Early iterations then take a few Krylov iterations instead of many; the converged
            answer still meets Newton's own test, so accuracy is unchanged.

    Counters ``factorisations`` and ``krylov_solves`` say what happened (for benchmarks).
    """

    #: loosest Krylov tolerance of the inexact Newton mode (relative error of the increment)
    eta_max = 1e-2

    def __init__(self, rtol: float = 1e-6, maxiter: int = 25, backend: str | None = None,
                 newton_tol: float | None = None) -> None:
        self.rtol, self.maxiter = float(rtol), int(maxiter)
        self.newton_tol = newton_tol
        self._last_norm: float | None = None
        self._last_eta = self.eta_max
        self.backend = backend or backend_name()
        self.factor: Any = None
        self.shape: tuple[int, int] | None = None
        self.factorisations = 0
        self.krylov_solves = 0
        self.krylov_iterations = 0

    def reset(self) -> None:
        """Forget the kept factorisation (e.g. after a cut-back restored an older state)."""
        self.factor, self.shape = None, None

    def _tolerance(self, bnorm: float) -> float:
        """The Krylov tolerance for a right-hand side of norm ``bnorm`` (see ``newton_tol``)."""
        if self.newton_tol is None:
            return self.rtol
        last, self._last_norm = self._last_norm, bnorm
        if last is None or not last > 0 or bnorm >= last:
            eta = self.eta_max  # a new load step (or a residual that grew)
        else:
            eta = 0.9 * (bnorm / last) ** 2
            if 0.9 * self._last_eta ** 2 > 0.1:  # the safeguard against over-solving too soon
                eta = max(eta, 0.9 * self._last_eta ** 2)
            eta = min(eta, self.eta_max)
        if bnorm > 0:
            eta = max(eta, 0.5 * self.newton_tol / bnorm)
        self._last_eta = eta = max(min(eta, self.eta_max), self.rtol)
        return eta

    def __call__(self, A, b) -> np.ndarray:
        from scipy.sparse.linalg import LinearOperator, gmres

        b = np.asarray(b, dtype=float).ravel()
        rtol = self._tolerance(float(np.linalg.norm(b)))
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
                x, info = gmres(MA, solve(b), rtol=rtol, atol=0.0, restart=self.maxiter,
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
