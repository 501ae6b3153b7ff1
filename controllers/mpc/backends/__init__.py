"""The QP solvers the MPC can use: one object per back-end, each ``solve(p) -> (z, ok)`` on the QP of
:class:`~controllers.mpc.problem.QPBuilder` at parameter vector ``p``.

Measurements
------------
Whole ``solve()`` call (input checks, QP data, solve, rollout), closed loop on the Panda
(Pinocchio kinematics) tracking a point at 0.2 m/s, 300 calls, ``python -m
controllers.mpc_bench``, on the 2-core development machine while it was shared (load
average 5-6, i.e. about a third of a core for us; an idle machine should be ~2x faster)::

    back-end                                 median us   p99 us   TCP RMS error
    casadi.Opti('conic') re-built per call     ~40 000      -      (FACTS.md)
    osqp_piqp  (default, see below)              1 056     5 603   0.29 mm
    osqp_direct (OSQP 1.x, setup once, update)   1 109     5 690   0.29 mm
    piqp       (casadi.conic, via buffer)        3 238     8 256   0.27 mm
    osqp       (casadi.conic, eps 1e-4)          1 257     6 217   2.05 mm
    qrqp       (casadi.conic)                    3 908    11 175   0.27 mm
    proxqp     (casadi.conic)                    6 518    12 588   0.27 mm
    hpipm      (casadi.conic, OCP form with u_prev in the state, 581 vars, 9 IPM iters)
                                               ~2 200 (solver alone)
    fatrop (conic) asserted inside CasADi, daqp needs a strictly convex H: not usable.

OSQP (ADMM, warm-started, ~15 iterations, one KKT refactorization per call because H
changes with J) is the fastest while few constraints are active, but it stalls (2000
iterations, 30-70 ms) when many velocity / position limits are active at once (unreachable
goals).  PIQP (proximal interior point) is slower but its iteration count hardly depends on
the active set and it never failed.  The default ``osqp_piqp`` runs OSQP with at most 60
iterations and, when it has not converged, re-solves the same data with PIQP: nominal
tracking as above; with many limits active (goal out of reach / below the base) the median
was 1.8-7 ms and p99 10-17 ms under the same load (no failures).  Those saturated cases miss
the 5 ms p99 goal on a loaded machine: keep ``max_solve_ms`` at or below the MPC period, and
the fallback of :class:`~controllers.mpc.TaskSpaceMPC` handles a late solve.
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from controllers.mpc.backends.conic import ConicBackend
from controllers.mpc.backends.evaluator import Evaluator
from controllers.mpc.backends.hybrid import HybridBackend
from controllers.mpc.backends.osqp_direct import OSQPBackend
from controllers.mpc.problem import QPBuilder

__all__ = ["Backend", "ConicBackend", "Evaluator", "HybridBackend", "OSQPBackend", "make_backend"]


class Backend(Protocol):
    """A QP solver set up on the MPC's fixed sparsity."""

    def solve(self, p: np.ndarray) -> tuple[np.ndarray, bool]:
        """The decision vector z at parameter vector ``p`` and whether the solver succeeded."""
        ...


def make_backend(qp: QPBuilder, solver: str, options: dict[str, Any]) -> Backend:
    """The back-end named ``solver`` (one of :data:`~controllers.mpc.SOLVERS`), set up on ``qp`` (~2 ms)."""
    if solver == "osqp_piqp":
        return HybridBackend(qp, options)
    if solver == "osqp_direct":
        return OSQPBackend(qp, options)
    return ConicBackend(qp, solver, options)
