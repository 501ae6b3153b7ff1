"""The ``osqp_direct`` back-end: OSQP 1.x set up once on the CasADi sparsity, then updated in place."""

from __future__ import annotations

from typing import Any

import numpy as np

from controllers.mpc.backends.evaluator import Evaluator
from controllers.mpc.config import N_JOINTS
from controllers.mpc.problem import QPBuilder

#: OSQP settings before ``solver_options`` (tolerances are absolute / relative, in the QP's units).
OSQP_SETTINGS: dict[str, Any] = dict(verbose=False, warm_starting=True, polishing=False, eps_abs=1e-4, eps_rel=1e-4,
                                     max_iter=2000, adaptive_rho=True, check_termination=5)


def _setup_params(qp: QPBuilder) -> np.ndarray:
    """A representative parameter vector (dense Jacobian and null-space projector) so no structural nonzero is 0."""
    nj = N_JOINTS
    p_setup = np.zeros(qp.n_params)
    p_setup[3 * nj : 3 * nj + 6 * nj] = 0.1
    p_setup[-nj * nj:] = 0.1  # the null-space projector (dense)
    return p_setup


class OSQPBackend:
    """OSQP 1.x driven directly: set up once on the CasADi sparsity (``[A; I]`` carries the
    simple bounds), then ``update()`` the values and re-solve warm-started.

    Attributes:
        solver: the ``osqp.OSQP`` object.
        last_iter: ADMM iterations of the last solve.
        last_status: OSQP status value of the last solve (1 solved, 2 solved inaccurate).
    """

    def __init__(self, qp: QPBuilder, options: dict[str, Any]) -> None:
        import osqp  # local: only this back-end needs it
        import scipy.sparse as sp

        self._eval = Evaluator(qp.eval_fun)
        nz = qp.nz
        sizes = np.cumsum([0] + qp.part_sizes)
        self._slices = [slice(int(a), int(b)) for a, b in zip(sizes[:-1], sizes[1:])]
        hx, g, ax, lba, uba, lbx, ubx = self._split(self._eval(_setup_params(qp)))
        hs = qp.h_triu_sp
        p_mat = sp.csc_matrix((hx.copy(), np.asarray(hs.row()), np.asarray(hs.colind())), shape=(nz, nz))
        a_full = self._stacked_constraints(qp, ax)
        self._l = np.empty(qp.n_con + nz)
        self._u = np.empty(qp.n_con + nz)
        settings = dict(OSQP_SETTINGS)
        settings.update(options)
        self.solver = osqp.OSQP()
        self._fill_bounds(lba, uba, lbx, ubx)
        self.solver.setup(P=p_mat, q=g, A=a_full, l=self._l, u=self._u, **settings)
        self._ext = self.solver._solver
        self.last_iter = 0
        self.last_status = 0

    def _stacked_constraints(self, qp: QPBuilder, ax: np.ndarray) -> Any:
        """``[A; I]`` as CSC, assembled by hand so that the position of every value of A in its data is known
        (``_a_pos``; ``_a_data`` holds the values, ``_a_last`` those of A set up)."""
        import scipy.sparse as sp

        nz = qp.nz
        as_ = qp.a_sp
        a_ptr = np.asarray(as_.colind())
        a_row = np.asarray(as_.row())
        cols = np.repeat(np.arange(nz), np.diff(a_ptr))
        self._a_pos = np.arange(a_row.size) + cols  # CasADi nonzero i of column j -> i + j
        indptr = a_ptr + np.arange(nz + 1)
        indices = np.empty(a_row.size + nz, dtype=np.int64)
        indices[self._a_pos] = a_row
        indices[a_ptr[1:] + np.arange(nz)] = qp.n_con + np.arange(nz)
        self._a_data = np.ones(a_row.size + nz)
        self._a_data[self._a_pos] = ax
        a_full = sp.csc_matrix((self._a_data.copy(), indices, indptr), shape=(qp.n_con + nz, nz))
        self._a_last = ax.copy()
        return a_full

    def _split(self, vec: list[np.ndarray]) -> list[np.ndarray]:
        return [vec[0][s] for s in self._slices]

    def _fill_bounds(self, lba, uba, lbx, ubx) -> None:
        m = lba.size
        self._l[:m], self._l[m:] = lba, lbx
        self._u[:m], self._u[m:] = uba, ubx
        np.clip(self._l, -1e30, 1e30, out=self._l)
        np.clip(self._u, -1e30, 1e30, out=self._u)

    def solve(self, p: np.ndarray) -> tuple[np.ndarray, bool]:
        """The QP at parameter vector ``p``: ``(z, ok)``, ok when OSQP reports solved or solved inaccurate."""
        hx, g, ax, lba, uba, lbx, ubx = self._split(self._eval(p))
        self._fill_bounds(lba, uba, lbx, ubx)
        # OSQP's low-level solver object: the high-level update()/solve() add ~100 us of Python bookkeeping
        ext = self._ext
        ext.update_data_vec(q=g, l=self._l, u=self._u)
        if np.array_equal(ax, self._a_last):
            ext.update_data_mat(P_x=hx, P_i=None, A_x=None, A_i=None)
        else:  # not expected with this formulation (A is constant), kept for safety
            self._a_data[self._a_pos] = ax
            self._a_last = ax.copy()
            ext.update_data_mat(P_x=hx, P_i=None, A_x=self._a_data, A_i=None)
        ext.solve()
        info = ext.info
        self.last_iter = int(info.iter)
        self.last_status = int(info.status_val)
        ok = self.last_status in (1, 2)  # solved / solved inaccurate
        return np.array(ext.solution.x, dtype=float), ok
