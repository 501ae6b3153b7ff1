"""Faults of the controller and the command link: :class:`DroppedTicks` (a command link that drops ticks) and the
builders of the ``link`` and ``controller`` faults of the registry (the QP's and the MPC's real, counted fallback
paths forced for a while)."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import numpy as np

from scenarios.faults.clock import EPS_S, in_window, sim_time_s

if TYPE_CHECKING:
    from scenarios.faults.spec import Injection


class DroppedTicks:
    """A :class:`~mmact_ctrl.loop.CommandLink` that drops ``n`` consecutive ticks from the first tick at or
    after ``t_fault_s`` (the robot re-applies the last torque it received)."""

    def __init__(self, n: int, t_fault_s: float) -> None:
        self.n = int(n)
        self.t_fault_s = float(t_fault_s)
        self.k0: int | None = None
        self.dropped = 0

    def delivered(self, k: int, t_s: float) -> bool:
        if self.k0 is None and t_s >= self.t_fault_s - EPS_S:
            self.k0 = int(k)
        if self.k0 is not None and self.k0 <= k < self.k0 + self.n:
            self.dropped += 1
            return False
        return True


# ---- builders of the registry -------------------------------------------------------------------------------


def dropped_ticks(n: int):
    def build(spec, world, source, controller, inj: Injection) -> None:
        start, end = inj.window_s
        ticks = int(round((end - start) / controller.config.dt_s)) if spec.duration_s is not None else n
        inj.link = DroppedTicks(ticks, start)

    return build


def qp_fail_burst(spec, world, source, controller, inj: Injection) -> None:
    """For the ticks of the window (50 from the onset) the QP's solve is its real, counted fallback."""
    qp = controller.qp
    start, end = inj.window_s
    n_ticks = int(round((end - start) / controller.config.dt_s))
    solve = qp.solve  # the bound method of the class
    done = [0]

    def faulty_solve(terms, q_rad, dq_rad_s, ref):
        if done[0] < n_ticks and sim_time_s(world) >= start - EPS_S:
            done[0] += 1
            return qp.fallback(terms, q_rad, dq_rad_s)
        return solve(terms, q_rad, dq_rad_s, ref)

    qp.solve = faulty_solve
    inj._undo.append(lambda: qp.__dict__.pop("solve", None))


def mpc_late(spec, world, source, controller, inj: Injection) -> None:
    """In the window every MPC solve is late: counted in ``mpc.late``, answered by the real fallback (the last
    plan re-timed). Not applicable without an MPC."""
    mpc = controller.mpc
    if mpc is None:
        inj.applicable = False
        return
    solve = mpc.solve
    window = inj.window_s

    def faulty_solve(t_s, q_rad, dq_rad_s, ee_pos_m, jacobian_6x7, pos_ref_m, rotvec_err_ref_rad=None):
        if not in_window(window, float(t_s)):
            return solve(t_s, q_rad, dq_rad_s, ee_pos_m, jacobian_6x7, pos_ref_m, rotvec_err_ref_rad)
        t_start = time.perf_counter()
        mpc.solves += 1
        mpc.late += 1
        return mpc._fallback(float(t_s), np.asarray(q_rad, dtype=np.float64), np.asarray(dq_rad_s, dtype=np.float64),
                             np.asarray(ee_pos_m, dtype=np.float64), np.asarray(jacobian_6x7, dtype=np.float64), t_start)

    mpc.solve = faulty_solve
    inj._undo.append(lambda: mpc.__dict__.pop("solve", None))
