"""The general path's solver kept warm: one OSQP problem set up on dense sparsity patterns and updated each tick.

:func:`controllers.qp.solve.solve_problem` sets OSQP up afresh for every problem (scipy's sparse matrices, OSQP's
setup and factorisation: ~1.1 ms a tick with ``--compliance``, measured under cProfile, against ~40 us for the whole
default tick). :class:`WarmProblemSolver` sets it up once for the problem's shape on patterns that store every entry
(the upper triangle of P, all of A; zeros included, so a value that passes through zero never changes the pattern),
then each tick replaces the values and solves from the last solution (OSQP's warm start), with the same settings as
the fast path's solver. Where OSQP does not solve it, DAQP's ladder takes over as in ``solve_problem``. The solutions
agree with the cold path's within the solver's tolerance, not bit for bit (the iterates start elsewhere).
"""

from __future__ import annotations

import numpy as np
import osqp
import scipy.sparse as sp

from controllers.qp.solve import Problem, daqp_fallback


def new_osqp(p_pattern: np.ndarray, a_pattern: np.ndarray, eps: float, max_iter: int) -> osqp.OSQP:
    """An OSQP problem set up on fixed sparsity patterns (every entry of ``p_pattern``'s upper triangle and of
    ``a_pattern`` stored), with the settings of every QP of the tick: warm starts, no polishing, and a fixed rho
    interval, which keeps runs deterministic (0 = by setup time)."""
    n, m = p_pattern.shape[0], a_pattern.shape[0]
    solver = osqp.OSQP()
    solver.setup(P=sp.csc_matrix(p_pattern), q=np.zeros(n), A=sp.csc_matrix(a_pattern), l=-np.ones(m),
                 u=np.ones(m), verbose=False, warm_starting=True, polishing=False, eps_abs=eps, eps_rel=eps,
                 max_iter=max_iter, check_termination=5, adaptive_rho_interval=25)
    return solver


class WarmProblemSolver:
    """Solves a sequence of :class:`~controllers.qp.solve.Problem` of one shape, warm (see the module).

    Args:
        eps: OSQP's absolute and relative tolerance.
        max_iter: OSQP's iteration cap.
    """

    def __init__(self, eps: float = 1e-5, max_iter: int = 400) -> None:
        self.eps, self.max_iter = float(eps), int(max_iter)
        self._ok = (int(osqp.SolverStatus.OSQP_SOLVED), int(osqp.SolverStatus.OSQP_SOLVED_INACCURATE))
        self.reset()

    def reset(self) -> None:
        """Forget the problem and its warm start (a new episode does not depend on the one before)."""
        self._ext = None
        self._shape: tuple[int, int] | None = None
        self._p_idx = np.zeros(0, dtype=np.int64)

    def _setup(self, n: int, m: int) -> None:
        p_pattern = np.triu(np.ones((n, n)))
        self._p_idx = np.flatnonzero(p_pattern.ravel(order="F"))  # P's upper triangle, column-major
        # the low-level object: the wrapper's bookkeeping is not needed per tick
        self._ext = new_osqp(p_pattern, np.ones((m, n)), self.eps, self.max_iter)._solver
        self._shape = (n, m)

    def solve(self, problem: Problem) -> np.ndarray | None:
        """The problem's solution: warm OSQP, else DAQP down the ladder of relaxations; None when nothing solves."""
        n, m = len(problem.g), len(problem.lower)
        if self._shape != (n, m):
            self._setup(n, m)
        ext = self._ext
        ext.update_data_vec(q=np.ascontiguousarray(problem.g, dtype=np.float64),
                            l=np.ascontiguousarray(problem.lower, dtype=np.float64),
                            u=np.ascontiguousarray(problem.upper, dtype=np.float64))
        ext.update_data_mat(P_x=np.ascontiguousarray(problem.P.ravel(order="F")[self._p_idx], dtype=np.float64),
                            P_i=None, A_x=np.ascontiguousarray(problem.A.ravel(order="F"), dtype=np.float64), A_i=None)
        ext.solve()
        x = np.array(ext.solution.x, dtype=np.float64)
        if int(ext.info.status_val) in self._ok and x.shape == (n,) and np.all(np.isfinite(x)):
            return x
        return daqp_fallback(problem)
