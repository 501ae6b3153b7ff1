"""The task-space MPC object: :class:`TaskSpaceMPC` (see :mod:`controllers.mpc` for the model)."""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from controllers.mpc.backends import Backend, make_backend
from controllers.mpc.config import N_JOINTS, MPCConfig
from controllers.mpc.double_integrator import rollout
from controllers.mpc.fallback import fallback_plan
from controllers.mpc.inputs import as_array, checked_inputs, clamp_rows
from controllers.mpc.null_space import null_projector
from controllers.mpc.plan import MPCPlan
from controllers.mpc.problem import QPBuilder
from controllers.robot_description import HOME_Q_RAD, JointLimits


class TaskSpaceMPC:
    """Linear-time-varying task-space MPC over a joint double integrator (see the :mod:`controllers.mpc` doc).

    The QP is built once in the constructor; :meth:`solve` re-evaluates its data for the new
    state and references and re-solves warm-started.

    Attributes:
        solves: number of :meth:`solve` calls.
        failures: calls whose solver failed (exception, status, non-finite result).
        late: calls whose solve took longer than ``config.max_solve_ms``.
        last_plan: the plan returned by the last call (None before the first).
    """

    def __init__(
        self,
        config: MPCConfig = MPCConfig(),
        limits: JointLimits = JointLimits(),
        q_nominal_rad: Any = HOME_Q_RAD,
    ) -> None:
        self.config = config
        self.limits = limits
        self.q_nominal_rad = as_array("q_nominal_rad", q_nominal_rad, (N_JOINTS,))
        self._qp = QPBuilder(config, limits)
        self._a_max = self._qp.a_max
        self._u_idx = self._qp.u_idx
        self.reset()

    def reset(self) -> None:
        """Forget the last plan, the counters and the solver's warm start (the back-end is set up again, ~2 ms; the
        CasADi problem, 0.3 s to build, is kept): an episode does not depend on the one before it."""
        self._backend: Backend = make_backend(self._qp, self.config.solver, dict(self.config.solver_options))
        self.solves = 0
        self.failures = 0
        self.late = 0
        self.last_plan: MPCPlan | None = None

    # ------------------------------------------------------------------ solve
    def solve(
        self,
        t_s: float,
        q_rad: Any,
        dq_rad_s: Any,
        ee_pos_m: Any,
        jacobian_6x7: Any,
        pos_ref_m: Any,
        rotvec_err_ref_rad: Any = None,
    ) -> MPCPlan:
        """Plan from the current state toward the task-space references.

        Args:
            t_s: current time, s (the plan's ``t0_s``).
            q_rad, dq_rad_s: current joint positions (rad) and velocities (rad/s), (7,).
            ee_pos_m: current TCP position in the world, m, (3,).
            jacobian_6x7: TCP Jacobian at ``q_rad`` in LOCAL_WORLD_ALIGNED (rows: linear m/rad, angular rad/rad).
            pos_ref_m: desired TCP positions, m, (N, 3): row i is the reference at ``t_s + (i+1) dt_s``;
                a single (3,) point is held over the horizon.
            rotvec_err_ref_rad: desired orientation as a world-frame rotation vector relative to the
                current TCP orientation, rad, (N, 3) or (3,) (a constant goal: e.g. ``log3(R_goal R^T)``).
                None holds the current orientation.

        Returns:
            The plan (``ok`` False when it is a fallback: see the module doc).

        Raises:
            ValueError: an argument has a wrong shape or is not finite.
        """
        t_start = time.perf_counter()
        n = self.config.horizon_steps
        t_s, q0, dq0, p0, jac, pos_ref, rot_ref = checked_inputs(n, t_s, q_rad, dq_rad_s, ee_pos_m, jacobian_6x7,
                                                                  pos_ref_m, rotvec_err_ref_rad)
        self.solves += 1
        prev = self.last_plan
        u_prev = prev.sample(t_s)[2] if prev is not None else np.zeros(N_JOINTS)
        e_pos = clamp_rows(pos_ref - p0, self.config.max_ref_dist_m)
        e_rot = clamp_rows(rot_ref, self.config.max_ref_angle_rad)
        params = np.concatenate([q0, dq0, u_prev, jac.ravel(order="F"), e_pos.ravel(), e_rot.ravel(),
                                 self.q_nominal_rad, self._null(jac)])
        try:
            z, ok = self._backend.solve(params)
        except Exception:  # noqa: BLE001 - any solver error means: fall back
            z, ok = np.full(self._qp.nz, np.nan), False
        u = z[self._u_idx].reshape(n, N_JOINTS) if z.size == self._qp.nz else np.full((n, N_JOINTS), np.nan)
        if not ok or not np.all(np.isfinite(u)):
            self.failures += 1
            return self._fallback(t_s, q0, dq0, p0, jac, t_start)
        solve_us = (time.perf_counter() - t_start) * 1e6
        if solve_us > 1e3 * self.config.max_solve_ms:
            self.late += 1
            return self._fallback(t_s, q0, dq0, p0, jac, t_start)
        # hard acceleration box (solver tolerance), then an exact rollout from the measured state
        u = np.clip(u, -self._a_max, self._a_max)
        q, dq = rollout(q0, dq0, u, self.config.dt_s)
        jl = jac[0:3]
        plan = MPCPlan(t_s, self.config.dt_s, q, dq, u, p0 + (q - q0) @ jl.T, True,
                       (time.perf_counter() - t_start) * 1e6, jl.copy())
        self.last_plan = plan
        return plan

    def _null(self, jac: np.ndarray) -> np.ndarray:
        """The null-space projector parameter (column-major), zeros when ``w_null_posture`` is 0 (unused)."""
        if self.config.w_null_posture <= 0.0:
            return np.zeros(N_JOINTS * N_JOINTS)
        return null_projector(jac, self.config.null_damping).ravel(order="F")

    # --------------------------------------------------------------- fallback
    def _fallback(self, t_s: float, q0: np.ndarray, dq0: np.ndarray, p0: np.ndarray, jac: np.ndarray,
                  t_start: float) -> MPCPlan:
        """Previous plan re-timed to start at ``t_s`` (braking to rest after its end), or,
        with no previous plan covering ``t_s``, a plan braking to rest from the current state
        (:func:`~controllers.mpc.fallback.fallback_plan`); it becomes ``last_plan``."""
        plan = fallback_plan(self.last_plan, t_s, q0, dq0, p0, jac, self._a_max, self.config.horizon_steps,
                             self.config.dt_s, t_start)
        self.last_plan = plan
        return plan
