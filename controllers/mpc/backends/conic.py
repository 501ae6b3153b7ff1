"""The ``casadi.conic`` back-ends (``piqp``, ``osqp``, ``qrqp``, ``proxqp``), evaluated through one buffer."""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np

from controllers.mpc.backends.evaluator import Evaluator
from controllers.mpc.problem import QPBuilder

#: A conic solution counts as a success when it is finite and primal feasible to this (the QP's units).
FEAS_TOL = 1e-3


def _plugin_options(plugin: str, options: dict[str, Any]) -> dict[str, Any]:
    """The ``casadi.conic`` options for ``plugin`` (quiet, warm-started where it can be), then ``options``."""
    opts: dict[str, Any] = {"error_on_fail": False}
    if plugin == "osqp":
        opts["osqp"] = {"verbose": False, "eps_abs": 1e-4, "eps_rel": 1e-4, "polishing": False}
        opts["warm_start_primal"] = True
        opts["warm_start_dual"] = True
    elif plugin == "qrqp":
        opts.update(print_iter=False, print_header=False, print_info=False)
    elif plugin == "piqp":
        opts["piqp"] = {"verbose": False}
    opts.update(options)
    return opts


def _packed_solve_function(qp: QPBuilder, plugin: str, solver: ca.Function) -> ca.Function:
    """One MX Function ``[p; x0; lam_x0; lam_a0] -> [x; lam_x; lam_a; max violation]``: the QP data and the solve."""
    p = ca.MX.sym("p", qp.n_params)
    x0 = ca.MX.sym("x0", qp.nz)
    lam_x0 = ca.MX.sym("lam_x0", qp.nz)
    lam_a0 = ca.MX.sym("lam_a0", qp.n_con)
    h, g, a, lba, uba, lbx, ubx = qp.qp_fun(p)
    r = solver(h=h, g=g, a=a, lba=lba, uba=uba, lbx=lbx, ubx=ubx, x0=x0, lam_x0=lam_x0, lam_a0=lam_a0)
    ax = ca.mtimes(a, r["x"])
    viol = ca.mmax(ca.vertcat(lba - ax, ax - uba, lbx - r["x"], r["x"] - ubx))
    packed = ca.vertcat(r["x"], r["lam_x"], r["lam_a"], viol)
    inputs = ca.vertcat(p, x0, lam_x0, lam_a0)
    return ca.Function("mpc_conic_" + plugin, [inputs], [packed])


class ConicBackend:
    """``casadi.conic`` with a given plugin, created once on the fixed sparsity and wrapped with
    the QP-data function into one MX Function evaluated through ``buffer()`` (no DM
    conversions).  Success = finite and primal feasible to ``feas_tol`` (the conic stats are
    not reachable from inside an MX graph); a success's primal and dual solution warm-start the next solve."""

    def __init__(self, qp: QPBuilder, plugin: str, options: dict[str, Any]) -> None:
        opts = _plugin_options(plugin, options)
        self.feas_tol = FEAS_TOL
        solver = ca.conic("mpc_" + plugin, plugin, {"h": qp.h_sp, "a": qp.a_sp}, opts)
        self._eval = Evaluator(_packed_solve_function(qp, plugin, solver))
        self._np, self._nz, self._nc = qp.n_params, qp.nz, qp.n_con
        self._warm = np.zeros(2 * qp.nz + qp.n_con)

    def solve(self, p: np.ndarray) -> tuple[np.ndarray, bool]:
        """The QP at parameter vector ``p``: ``(z, ok)``."""
        out = self._eval(np.concatenate([p, self._warm]))[0]
        x = out[: self._nz].copy()
        viol = out[-1]
        ok = bool(np.all(np.isfinite(out)) and viol <= self.feas_tol)
        if ok:
            self._warm[:] = out[:-1]
        return x, ok
