"""One function that stacks tasks and limits and solves, as mink's ``solve_ik`` does; and DAQP's ladder of
relaxations for when the rows cannot all hold.

:func:`build_problem` sums the tasks' costs into ``0.5 x' P x + g' x`` and stacks the limits' rows;
:func:`solve_problem` solves it with OSQP (a fresh, cold problem: the general path; the 1 kHz default set has its own
warm-started fast path in ``controllers.qp.task_space_qp``) and, when OSQP does not solve it, with DAQP's exact
active-set method down :func:`relaxation_levels`: every row hard; then the rows of the highest priority soft (DAQP's
slack penalty); then the next; the rows of priority 0 (the robot's own conditions) are never relaxed.
"""

from __future__ import annotations

from ctypes import c_int
from typing import Iterable, Iterator, NamedTuple

import daqp
import numpy as np
import osqp
import scipy.sparse as sp

from controllers.qp.state import Constraint, QPState

#: DAQP's sense flag of a soft row
DAQP_SOFT = 8


class Problem(NamedTuple):
    """``min 0.5 x' P x + g' x  s.t.  lower <= A x <= upper``; ``priority`` (rows,) of each row's limit."""

    P: np.ndarray
    g: np.ndarray
    A: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    priority: np.ndarray


def build_problem(tasks: Iterable, limits: Iterable, state: QPState) -> Problem:
    """The tasks' costs summed (in order) and the limits' rows stacked (in order)."""
    P, g = None, None
    for task in tasks:
        H, c = task.cost(state)
        P, g = (H.copy(), c.copy()) if P is None else (P + H, g + c)
    return Problem(P, g, *stack_rows([limit.rows(state) for limit in limits], len(g)))


def stack_rows(rows: Iterable[Constraint], n: int = 7) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(A, lower, upper, priority)`` of the limits' rows, stacked in order (no rows: empty arrays of ``n``
    columns)."""
    rows = list(rows)
    if not rows:
        return np.zeros((0, n)), np.zeros(0), np.zeros(0), np.zeros(0, dtype=int)
    return (np.vstack([r.A for r in rows]), np.concatenate([r.lower for r in rows]),
            np.concatenate([r.upper for r in rows]), np.concatenate([np.full(len(r.lower), r.priority) for r in rows]))


def soft_sense(priority: np.ndarray, relax_from: int) -> np.ndarray:
    """DAQP's sense flags: the rows of priority >= ``relax_from`` soft, the others hard."""
    return np.where(priority >= relax_from, DAQP_SOFT, 0).astype(c_int)


def relaxation_levels(priority: np.ndarray) -> Iterator[int | None]:
    """The ladder: None (every row hard), then ``k`` for each priority k > 0 from the highest down (rows of priority
    >= k soft)."""
    yield None
    for k in sorted({int(p) for p in priority if p > 0}, reverse=True):
        yield k


def daqp_ladder(P: np.ndarray, g: np.ndarray, levels: Iterable) -> np.ndarray | None:
    """``min 0.5 x'Px + g'x`` with DAQP under each level's ``(A, upper, lower, sense)`` in turn, until one solves;
    returns x or None (a solver error counts as no solution)."""
    n = len(g)
    for A, up, lo, sense in levels:
        try:
            x, _, flag, _ = daqp.solve(P, g, A, up, lo, sense)
        except Exception:  # noqa: BLE001 - a solver error means: no solution
            return None
        x = np.asarray(x, dtype=np.float64)
        if flag in (1, 2) and x.shape == (n,) and np.all(np.isfinite(x)):
            return x
    return None


def _osqp(problem: Problem, eps: float, max_iter: int) -> np.ndarray | None:
    solver = osqp.OSQP()
    solver.setup(P=sp.csc_matrix(np.triu(problem.P)), q=problem.g, A=sp.csc_matrix(problem.A), l=problem.lower,
                 u=problem.upper, verbose=False, polishing=False, eps_abs=eps, eps_rel=eps, max_iter=max_iter)
    result = solver.solve(raise_error=False)
    ok = (int(osqp.SolverStatus.OSQP_SOLVED), int(osqp.SolverStatus.OSQP_SOLVED_INACCURATE))
    x = np.asarray(result.x, dtype=np.float64)
    return x if int(result.info.status_val) in ok and np.all(np.isfinite(x)) else None


def solve_problem(problem: Problem, eps: float = 1e-5, max_iter: int = 400) -> np.ndarray | None:
    """The joint accelerations that solve ``problem``: OSQP, else DAQP down the ladder of relaxations; None when
    no level solves it."""
    x = _osqp(problem, eps, max_iter)
    return x if x is not None else daqp_fallback(problem)


def daqp_fallback(problem: Problem) -> np.ndarray | None:
    """``problem`` solved by DAQP down the ladder of relaxations (where OSQP did not solve it); None when no level
    solves it."""
    levels = ((problem.A, problem.upper, problem.lower,
               np.zeros(len(problem.lower), dtype=c_int) if k is None else soft_sense(problem.priority, k))
              for k in relaxation_levels(problem.priority))
    return daqp_ladder(problem.P, problem.g, levels)


def solve(tasks: Iterable, limits: Iterable, state: QPState, eps: float = 1e-5, max_iter: int = 400) -> np.ndarray | None:
    """mink's ``solve_ik`` for the inverse-dynamics QP: the joint accelerations (7,) rad/s^2 that minimise the tasks'
    costs within the limits' rows at ``state`` (None when no relaxation level solves it)."""
    return solve_problem(build_problem(tasks, limits, state), eps, max_iter)
