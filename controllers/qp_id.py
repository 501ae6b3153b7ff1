"""Task-space inverse-dynamics QP at 1 kHz, solved with OSQP.

Decision variable: joint accelerations ``ddq`` (7). Torques follow as ``tau = M ddq + h``.

    minimize    sum_tasks || J_i ddq + dJv_i - a_des_i ||^2_{W_i} + w_post ||ddq - ddq_post||^2 + reg ||ddq||^2
    subject to  -tau_max - h  <=  M ddq  <=  tau_max - h          (effort, with a margin)
                ddq_lb        <=   ddq   <=  ddq_ub               (acceleration, velocity, position viability)

Tasks (mink-style: each has a gain and a cost): TCP position and orientation (PD on the
reference, with velocity and acceleration feed-forward) and a joint posture task.
Limits: ``controllers.limits.joint_acceleration_bounds`` turns position/velocity/acceleration
limits into acceleration bounds for one control step.

The OSQP problem is set up once with the full sparsity pattern of P (dense upper triangle)
and A (dense M block + identity); each tick only the values are updated, warm-started.
The values are assembled by one compiled kernel (``controllers.tick_kernels.assemble_qp``)
straight into the CSC value arrays; ``problem`` is the same QP in dense numpy form (the
reference the kernel is tested against, and what cross-checks with other solvers use).
If OSQP returns neither "solved" nor "solved inaccurate" (the latter is counted in
``inaccurate``), or a non-finite solution, the controller falls back to gravity compensation
with joint damping (within the effort limits) and counts the failure in ``failures``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import osqp
import scipy.sparse as sp

from controllers.limits import JointAccelerationBounds
from controllers.robot_description import JointLimits
from controllers.robot_model import RobotTerms
from controllers.rotations import orientation_error
from controllers.tick_kernels import assemble_qp, qp_params, torque


@dataclass(frozen=True)
class QPConfig:
    """Gains, weights and solver settings of the task-space QP.

    Attributes:
        kp_pos, kd_pos: TCP position gains, 1/s^2 and 1/s.
        kp_ori, kd_ori: TCP orientation gains, 1/s^2 and 1/s.
        kp_post, kd_post: posture gains, 1/s^2 and 1/s.
        w_pos, w_ori, w_post, w_reg: task weights (cost units per (m/s^2)^2, (rad/s^2)^2, ...).
        tau_margin: fraction of the effort limit the QP may use (0 < tau_margin <= 1).
        dt_s: control period, s (for the one-step velocity/position bounds).
        brake_horizon_s: look-ahead for the position-limit viability bound, s.
        q_margin_rad: distance kept from the joint position limits, rad.
        v_margin: fraction of the velocity limit used.
        fallback_kd: joint damping of the fallback torque, N*m*s/rad.
        eps: OSQP absolute and relative tolerance.
        max_iter: OSQP iteration cap.
    """

    kp_pos: float = 400.0
    kd_pos: float = 40.0
    kp_ori: float = 300.0
    kd_ori: float = 35.0
    kp_post: float = 25.0
    kd_post: float = 10.0
    w_pos: float = 1.0
    w_ori: float = 0.3
    w_post: float = 1e-3
    w_reg: float = 1e-6
    tau_margin: float = 0.95
    dt_s: float = 0.001
    brake_horizon_s: float = 0.05
    q_margin_rad: float = 0.05
    v_margin: float = 0.95
    fallback_kd: float = 5.0
    eps: float = 1e-5
    max_iter: int = 400

    def __post_init__(self) -> None:
        for name in ("kp_pos", "kd_pos", "kp_ori", "kd_ori", "kp_post", "kd_post", "w_pos", "w_ori", "w_post", "w_reg"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"QPConfig.{name} must be >= 0, got {getattr(self, name)}")
        if not 0 < self.tau_margin <= 1:
            raise ValueError(f"QPConfig.tau_margin must be in (0, 1], got {self.tau_margin}")
        if not 0 < self.v_margin <= 1:
            raise ValueError(f"QPConfig.v_margin must be in (0, 1], got {self.v_margin}")
        if not self.dt_s > 0:
            raise ValueError(f"QPConfig.dt_s must be > 0, got {self.dt_s}")


@dataclass(frozen=True)
class TaskReference:
    """Task-space reference at one instant.

    Attributes:
        pos_m (3,), vel_m_s (3,), acc_m_s2 (3,): TCP position, velocity, acceleration, world frame.
        rot (3,3): desired TCP rotation; ang_vel_rad_s (3,), ang_acc_rad_s2 (3,) world frame.
        q_post_rad (7,): posture to pull the null space toward.
    """

    pos_m: np.ndarray
    vel_m_s: np.ndarray
    acc_m_s2: np.ndarray
    rot: np.ndarray
    ang_vel_rad_s: np.ndarray
    ang_acc_rad_s2: np.ndarray
    q_post_rad: np.ndarray


class TaskSpaceQP:
    """OSQP inverse-dynamics controller; ``solve`` returns torques and counts failures."""

    def __init__(self, config: QPConfig = QPConfig(), limits: JointLimits = JointLimits()) -> None:
        self.config = config
        self._tau_max = limits.arrays()["tau_max_nm"]
        self._tau_lim = self._tau_max * config.tau_margin
        self._bounds = JointAccelerationBounds(limits, config.dt_s, config.brake_horizon_s, config.q_margin_rad, config.v_margin)
        self.n = 7
        n = self.n
        self._w6 = np.array([config.w_pos] * 3 + [config.w_ori] * 3)
        self._kp6 = np.array([config.kp_pos] * 3 + [config.kp_ori] * 3)
        self._kd6 = np.array([config.kd_pos] * 3 + [config.kd_ori] * 3)
        self._p_diag = np.eye(n) * (config.w_post + config.w_reg)
        self._lower = np.empty(2 * n)
        self._upper = np.empty(2 * n)
        # Full sparsity patterns, fixed for the life of the solver.
        p_pattern = np.triu(np.ones((n, n)))
        a_pattern = np.vstack([np.ones((n, n)), np.eye(n)])
        self._p_idx = np.flatnonzero(p_pattern.ravel(order="F"))
        self._a_idx = np.flatnonzero(a_pattern.ravel(order="F"))
        self._a_full = np.vstack([np.eye(n), np.eye(n)])
        b = self._bounds
        self._params = qp_params(self._kp6, self._kd6, self._w6, config.kp_post, config.kd_post, config.w_post,
                                 config.w_post + config.w_reg, b.q_hi, b.q_lo, b.v_max, b.a_max, self._tau_lim,
                                 config.dt_s, config.brake_horizon_s)
        self._P_x = np.empty(len(self._p_idx))
        self._g = np.empty(n)
        self._A_x = np.empty(len(self._a_idx))
        self._l = np.empty(2 * n)
        self._u = np.empty(2 * n)
        self._solver = osqp.OSQP()
        self._solver.setup(
            P=sp.csc_matrix(p_pattern),
            q=np.zeros(n),
            A=sp.csc_matrix(a_pattern),
            l=-np.ones(2 * n),
            u=np.ones(2 * n),
            verbose=False,
            warm_starting=True,
            polishing=False,
            eps_abs=config.eps,
            eps_rel=config.eps,
            max_iter=config.max_iter,
            check_termination=5,
            adaptive_rho_interval=25,  # a fixed interval keeps runs deterministic (0 = by setup time)
        )
        # The low-level solver object: the high-level wrapper's update()/solve() spend ~50 us per tick
        # in Python bookkeeping (derivative caches, info namespaces) that a 1 kHz loop does not need.
        self._ext = self._solver._solver
        self._ok_status = (int(osqp.SolverStatus.OSQP_SOLVED), int(osqp.SolverStatus.OSQP_SOLVED_INACCURATE))
        self._inaccurate_status = int(osqp.SolverStatus.OSQP_SOLVED_INACCURATE)
        self.inaccurate = 0
        self.failures = 0
        self.solves = 0
        self.last_ok = True
        self.last_ddq = np.zeros(n)

    def problem(
        self, terms: RobotTerms, q_rad: np.ndarray, dq_rad_s: np.ndarray, ref: TaskReference
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The QP of this tick in dense form: ``min 0.5 x'Px + g'x  s.t.  lower <= A x <= upper``."""
        c = self.config
        e6 = np.concatenate((ref.pos_m - terms.pos_m, orientation_error(ref.rot, terms.rot)))
        v6 = np.concatenate((ref.vel_m_s, ref.ang_vel_rad_s))
        a6 = np.concatenate((ref.acc_m_s2, ref.ang_acc_rad_s2))
        a_des = a6 + self._kp6 * e6 + self._kd6 * (v6 - terms.vel)
        ddq_post = c.kp_post * (ref.q_post_rad - q_rad) - c.kd_post * dq_rad_s
        J = terms.J
        WJ = J * self._w6[:, None]
        P = J.T @ WJ + self._p_diag
        g = (terms.dJv - a_des) @ WJ - c.w_post * ddq_post
        n = self.n
        self._lower[n:], self._upper[n:] = self._bounds(q_rad, dq_rad_s)
        np.subtract(-self._tau_lim, terms.h, out=self._lower[:n])
        np.subtract(self._tau_lim, terms.h, out=self._upper[:n])
        self._a_full[:n] = terms.M
        return P, g, self._a_full, self._lower, self._upper

    def solve(self, terms: RobotTerms, q_rad: np.ndarray, dq_rad_s: np.ndarray, ref: TaskReference) -> np.ndarray:
        """Torques (7,) N*m that track ``ref`` within limits; a safe fallback (counted) if OSQP fails."""
        self.solves += 1
        assemble_qp(terms.M, terms.h, terms.J, terms.dJv, terms.pos_m, terms.rot, terms.vel, ref.pos_m, ref.vel_m_s,
                    ref.acc_m_s2, ref.rot, ref.ang_vel_rad_s, ref.ang_acc_rad_s2, ref.q_post_rad, q_rad, dq_rad_s,
                    self._params, self._P_x, self._g, self._A_x, self._l, self._u)
        ext = self._ext
        ext.update_data_vec(q=self._g, l=self._l, u=self._u)
        ext.update_data_mat(P_x=self._P_x, P_i=None, A_x=self._A_x, A_i=None)
        ext.solve()
        status = int(ext.info.status_val)
        ddq = np.array(ext.solution.x)
        tau = np.empty(self.n)
        if status in self._ok_status and torque(terms.M, terms.h, ddq, tau):  # tau = M ddq + h, all finite
            self.inaccurate += status == self._inaccurate_status
            self.last_ok = True
            self.last_ddq = ddq
            return tau  # not clipped: the caller measures limit violations
        self.last_ok = False
        self.failures += 1
        return self.fallback_torque(terms, dq_rad_s)

    def fallback_torque(self, terms: RobotTerms, dq_rad_s: np.ndarray) -> np.ndarray:
        """Gravity/Coriolis compensation with joint damping, within the effort limits."""
        tau = terms.h - self.config.fallback_kd * dq_rad_s
        return np.clip(tau, -self._tau_lim, self._tau_lim)
