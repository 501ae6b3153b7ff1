"""Task-space inverse-dynamics QP at 1 kHz, solved with OSQP.

Decision variable: joint accelerations ``ddq`` (7). Torques follow as ``tau = M ddq + h``.

    minimize    sum_tasks || J_i ddq + dJv_i - a_des_i ||^2_{W_i} + w_post ||ddq - ddq_post||^2 + reg ||ddq||^2
    subject to  tau_lo - h    <=  M ddq  <=  tau_hi - h           (effort and torque RATE)
                ddq_lb        <=   ddq   <=  ddq_ub               (acceleration, jerk, velocity, position viability)

    tau_lo, tau_hi = max(-tau_max, tau_last - dtau), min(tau_max, tau_last + dtau)

The torque-rate rows are the Panda's one necessary condition in torque control beyond finite values:
|tau_k - tau_(k-1)| < 1000 N m/s, measured against the last torque the robot *received* (``tau_last``;
after a missed tick that is the torque the robot held). It is a constraint of this QP in every mode:
it is the robot's limit, not a feature of one method. ``dtau = rate_margin * 1000 N m/s * dt``. The
acceleration box is intersected with ``ddq_last +- jerk_margin * j_max * dt``, ``ddq_last`` being the
acceleration the last command asked for, so the commanded acceleration's jerk (backward Euler) stays
inside the Panda's dddq limits; the box itself uses ``a_margin * ddq_max``.

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
``inaccurate``), or a non-finite solution, the same QP goes to DAQP (dual active set; counted in
``rescues`` when it solves it): ADMM can stall for hundreds of iterations when the torque-rate rows
and several joint bounds are active together, where an active-set method is exact in a few
iterations. If the rows cannot all hold (a state the rate limit does not let the controller leave in
one tick), DAQP solves it again with the velocity/position viability bounds soft (the acceleration
and jerk box still hard), and if need be with every acceleration row soft: the torque rows, the
robot's necessary condition, always hold. Only if that fails too does the controller fall back
(:meth:`TaskSpaceQP.fallback`, counted in ``failures``): the torque ramps toward gravity
compensation with joint damping, projected (DAQP again) onto the same rows. A solved torque that
the solver's tolerance left outside the rate limit is clamped onto it (counted in ``rate_clamps``).
"""

from __future__ import annotations

from dataclasses import dataclass

from ctypes import c_int

import daqp
import numpy as np
import osqp
import scipy.sparse as sp

from controllers.limits import JointAccelerationBounds
from controllers.robot_description import JointLimits
from controllers.robot_model import RobotTerms
from controllers.rotations import orientation_error
from controllers.tick_kernels import assemble_qp, clamp_rate, jerk_box, qp_params, rate_box, torque


#: OSQP's iteration cap for a loop on the wall clock (``--realtime``): a solve that has not converged by then goes to
#: DAQP's exact active-set solve at once, which on these 7-variable problems costs about as much as 50-100 ADMM
#: iterations. Measured here (a 2-core EPYC, the residual mode, whose reference steps every 10 ms and keeps the
#: torque-rate rows active): a capped tick's solve took 438 us median at 400 and 233 us at 100; the simulated-time
#: studies keep ``QPConfig.max_iter`` (400).
REALTIME_MAX_ITER: int = 100


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
        dtau_max_nm_s: the robot's torque-rate limit, N*m/s (Panda: 1000).
        rate_margin: fraction of the torque-rate limit the QP may use per step (0 < rate_margin <= 1).
        a_margin: fraction of the joint acceleration limits the QP may use.
        jerk_margin: fraction of the joint jerk limits the commanded acceleration may use.
        pos_err_max_m: the TCP position error of the PD term is saturated at this length, m: a reference that
            jumped far away (a stale plan dropped, a chunk switch) is approached at about
            ``kp_pos / kd_pos * pos_err_max_m`` (1 m/s), not at the 7 x error per second of a raw PD step.
        tcp_vel_cap_m_s: the TCP velocity the PD term steers toward, ``v_ref + kp_pos / kd_pos * e``, is capped at
            this speed (the reference velocity and acceleration feed-forward are scaled down with it), m/s: a
            reference that moves or jumps faster than the Panda's 1.7 m/s end-effector limit (a fast correction on
            top of a fast chunk) is followed at a speed the robot accepts.
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
    dtau_max_nm_s: float = 1000.0
    rate_margin: float = 0.95
    a_margin: float = 0.97
    jerk_margin: float = 0.9
    pos_err_max_m: float = 0.1
    tcp_vel_cap_m_s: float = 1.4

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
        if not self.tcp_vel_cap_m_s > 0:
            raise ValueError(f"QPConfig.tcp_vel_cap_m_s must be > 0, got {self.tcp_vel_cap_m_s}")
        if not self.pos_err_max_m > 0:
            raise ValueError(f"QPConfig.pos_err_max_m must be > 0, got {self.pos_err_max_m}")
        if not self.dtau_max_nm_s > 0:
            raise ValueError(f"QPConfig.dtau_max_nm_s must be > 0, got {self.dtau_max_nm_s}")
        for name in ("rate_margin", "a_margin", "jerk_margin"):
            if not 0 < getattr(self, name) <= 1:
                raise ValueError(f"QPConfig.{name} must be in (0, 1], got {getattr(self, name)}")


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
        lim = limits.arrays()
        self._tau_max = lim["tau_max_nm"]
        self._tau_lim = self._tau_max * config.tau_margin
        self._bounds = JointAccelerationBounds(limits, config.dt_s, config.brake_horizon_s, config.q_margin_rad, config.v_margin,
                                               config.a_margin)
        #: the largest torque step per control period the QP plans (margined) and the hard guard (just inside the limit)
        self.dtau_step_nm = config.rate_margin * config.dtau_max_nm_s * config.dt_s
        self.dtau_hard_nm = (1.0 - 1e-6) * config.dtau_max_nm_s * config.dt_s
        self._ddq_step = config.jerk_margin * lim["j_max_rad_s3"] * config.dt_s
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
                                 config.dt_s, config.brake_horizon_s, self.dtau_step_nm, self._ddq_step,
                                 config.pos_err_max_m, config.tcp_vel_cap_m_s)
        self._P_x = np.empty(len(self._p_idx))
        self._g = np.empty(n)
        self._A_x = np.empty(len(self._a_idx))
        self._l = np.empty(2 * n)
        self._u = np.empty(2 * n)
        self._p_pattern, self._a_pattern = p_pattern, a_pattern
        self._setup_solver()
        self._P_dense = np.zeros((n, n))
        self._A_dense = np.vstack([np.zeros((n, n)), np.eye(n)])
        self._sense = np.zeros(2 * n, dtype=c_int)
        self._sense_viability_soft = np.array([0] * (2 * n) + [8] * n, dtype=c_int)  # DAQP: 8 = soft constraint
        self._sense_all_soft = np.array([0] * n + [8] * (2 * n), dtype=c_int)
        self._ok_status = (int(osqp.SolverStatus.OSQP_SOLVED), int(osqp.SolverStatus.OSQP_SOLVED_INACCURATE))
        self._inaccurate_status = int(osqp.SolverStatus.OSQP_SOLVED_INACCURATE)
        self.inaccurate = 0
        self.failures = 0
        self.solves = 0
        self.rate_clamps = 0
        self.rescues = 0
        self.last_ok = True
        self.last_ddq = np.zeros(n)
        #: the last torque the robot received, N*m (None until :meth:`reset` or the first command: then the
        #: bias torque h of that first state, i.e. the robot holding itself as it does before a controller starts)
        self.tau_last: np.ndarray | None = None

    def _setup_solver(self) -> None:
        """(Re)build the OSQP problem on the fixed sparsity patterns (~0.3 ms): no warm start or adapted rho left."""
        n, config = self.n, self.config
        self._solver = osqp.OSQP()
        self._solver.setup(
            P=sp.csc_matrix(self._p_pattern),
            q=np.zeros(n),
            A=sp.csc_matrix(self._a_pattern),
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

    def reset(self, tau_start_nm: np.ndarray, ddq_start_rad_s2: np.ndarray | None = None) -> None:
        """Start of a motion: the torque the robot applies now (the first command's rate is measured against
        it) and the acceleration that torque commands (default rest); clears the counters and the solver's warm
        start, so an episode does not depend on the one before it."""
        self._setup_solver()
        tau = np.asarray(tau_start_nm, dtype=np.float64)
        if tau.shape != (self.n,) or not np.all(np.isfinite(tau)):
            raise ValueError(f"tau_start_nm must be {self.n} finite torques, got {tau_start_nm!r}")
        self.tau_last = tau.copy()
        self.last_ddq = np.zeros(self.n) if ddq_start_rad_s2 is None else np.asarray(ddq_start_rad_s2, dtype=np.float64).copy()
        self.failures = self.solves = self.inaccurate = self.rate_clamps = self.rescues = 0
        self.last_ok = True

    def warm_up(self, terms: RobotTerms, q_rad: np.ndarray, dq_rad_s: np.ndarray, ref: TaskReference) -> None:
        """Run every path of :meth:`solve` once on this state, the rare ones too (DAQP's rescue in its three levels
        and the fallback, with the compiled kernels only they call), then forget it: the first rescue of a run no
        longer pays for loading those kernels on the 1 kHz path (measured: 6 ms, in a real-time episode 7 missed
        commands in a row). The solver and the counters are set up anew (:meth:`reset` does it again per episode)."""
        tau_was, ddq_was = self.tau_last, self.last_ddq
        self.tau_last, self.last_ddq = np.array(terms.h, dtype=np.float64), np.zeros(self.n)
        self.solve(terms, q_rad, dq_rad_s, ref)
        self._rescue(terms, q_rad, dq_rad_s)
        self.fallback(terms, q_rad, dq_rad_s)
        self._accel_jerk_box()  # what only DAQP's levels 2 and 3 compute
        self._bounds(q_rad, dq_rad_s, self._j_eff(terms))
        self._setup_solver()
        self.tau_last, self.last_ddq = tau_was, ddq_was
        self.failures = self.solves = self.inaccurate = self.rate_clamps = self.rescues = 0
        self.last_ok = True

    def hold(self, tau_held_nm: np.ndarray) -> np.ndarray:
        """A control tick whose command did not reach the robot: the robot re-applies ``tau_held_nm``, which becomes
        the last torque (the next command's rate is measured against it). No new command was sent, so the last
        commanded acceleration stands (the jerk of the next command is measured against it); it is returned."""
        self.tau_last = np.asarray(tau_held_nm, dtype=np.float64).copy()
        return self.last_ddq

    def _ensure_started(self, terms: RobotTerms) -> None:
        if self.tau_last is None:
            self.tau_last = np.array(terms.h, dtype=np.float64)

    def problem(
        self, terms: RobotTerms, q_rad: np.ndarray, dq_rad_s: np.ndarray, ref: TaskReference
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The QP of this tick in dense form: ``min 0.5 x'Px + g'x  s.t.  lower <= A x <= upper``."""
        c = self.config
        e_pos = ref.pos_m - terms.pos_m
        e_norm = float(np.linalg.norm(e_pos))
        if e_norm > c.pos_err_max_m:
            e_pos = e_pos * (c.pos_err_max_m / e_norm)
        ref_vel, ref_acc = ref.vel_m_s, ref.acc_m_s2
        v_des = ref_vel + (self._kp6[:3] / self._kd6[:3]) * e_pos  # the TCP velocity the PD term steers toward
        v_norm = float(np.linalg.norm(v_des))
        if v_norm > c.tcp_vel_cap_m_s:
            scale = c.tcp_vel_cap_m_s / v_norm
            ref_vel = v_des * scale - (self._kp6[:3] / self._kd6[:3]) * e_pos
            ref_acc = ref_acc * scale
        e6 = np.concatenate((e_pos, orientation_error(ref.rot, terms.rot)))
        v6 = np.concatenate((ref_vel, ref.ang_vel_rad_s))
        a6 = np.concatenate((ref_acc, ref.ang_acc_rad_s2))
        a_des = a6 + self._kp6 * e6 + self._kd6 * (v6 - terms.vel)
        ddq_post = c.kp_post * (ref.q_post_rad - q_rad) - c.kd_post * dq_rad_s
        J = terms.J
        WJ = J * self._w6[:, None]
        P = J.T @ WJ + self._p_diag
        g = (terms.dJv - a_des) @ WJ - c.w_post * ddq_post
        lower, upper = self.constraint_bounds(terms, q_rad, dq_rad_s)
        self._lower[:], self._upper[:] = lower, upper
        self._a_full[:self.n] = terms.M
        return P, g, self._a_full, self._lower, self._upper

    def constraint_bounds(self, terms: RobotTerms, q_rad: np.ndarray, dq_rad_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(lower, upper)`` (14,) of ``lower <= [M; I] ddq <= upper`` in this state: the torque rows (effort and
        rate around ``tau_last``, minus h) and the acceleration rows (acceleration, jerk-aware velocity and position
        viability, intersected with the jerk box around ``last_ddq``); numpy, the reference of the kernel."""
        n = self.n
        self._ensure_started(terms)
        lb, ub = self._bounds(q_rad, dq_rad_s, self._j_eff(terms))
        jerk_box(self.last_ddq, self._ddq_step, lb, ub)
        lower, upper = np.empty(2 * n), np.empty(2 * n)
        lower[n:], upper[n:] = lb, ub
        rate_box(self.tau_last, self._tau_lim, self.dtau_step_nm, lower[:n], upper[:n])
        lower[:n] -= terms.h
        upper[:n] -= terms.h
        return lower, upper

    def solve(self, terms: RobotTerms, q_rad: np.ndarray, dq_rad_s: np.ndarray, ref: TaskReference) -> np.ndarray:
        """Torques (7,) N*m that track ``ref`` within limits, the torque rate included; a safe fallback
        (counted) if OSQP fails. The result becomes ``tau_last`` (the caller sends it to the robot)."""
        self.solves += 1
        self._ensure_started(terms)
        assemble_qp(terms.M, terms.h, terms.J, terms.dJv, terms.pos_m, terms.rot, terms.vel, ref.pos_m, ref.vel_m_s,
                    ref.acc_m_s2, ref.rot, ref.ang_vel_rad_s, ref.ang_acc_rad_s2, ref.q_post_rad, q_rad, dq_rad_s,
                    self.tau_last, self.last_ddq, self._params, self._P_x, self._g, self._A_x, self._l, self._u)
        ext = self._ext
        ext.update_data_vec(q=self._g, l=self._l, u=self._u)
        ext.update_data_mat(P_x=self._P_x, P_i=None, A_x=self._A_x, A_i=None)
        ext.solve()
        status = int(ext.info.status_val)
        ddq = np.array(ext.solution.x)
        tau = np.empty(self.n)
        ok = status in self._ok_status and torque(terms.M, terms.h, ddq, tau)  # tau = M ddq + h, all finite
        if not ok:  # ADMM stalls when many limits are active at once: the exact active-set solver takes over
            ddq = self._rescue(terms, q_rad, dq_rad_s)
            ok = ddq is not None and torque(terms.M, terms.h, ddq, tau)
            self.rescues += ok
        elif status == self._inaccurate_status:
            self.inaccurate += 1
        if ok:
            if clamp_rate(tau, self.tau_last, self.dtau_hard_nm) > 1e-9:  # the solver's tolerance, rare
                self.rate_clamps += 1
                ddq = commanded_accel(terms, tau, ddq)
            self.last_ok = True
            self.last_ddq = ddq
            self.tau_last = tau
            return tau  # not clipped to the effort limits: the safety monitor checks what is sent
        return self.fallback(terms, q_rad, dq_rad_s)

    def _daqp(self, P: np.ndarray, g: np.ndarray, terms: RobotTerms, q_rad: np.ndarray, dq_rad_s: np.ndarray,
              lower: np.ndarray, upper: np.ndarray) -> np.ndarray | None:
        """``min 0.5 x'Px + g'x`` over ddq with DAQP (dual active set) under the rows of this tick, in three levels:

        1. every row hard: ``lower <= [M; I] ddq <= upper`` (the rows OSQP had);
        2. if infeasible (the joint bounds and the torque-rate box do not meet: a state the rate limit does not let
           the controller leave in one tick): the torque rows and the acceleration and jerk box hard, the velocity
           and position viability bounds soft (DAQP's slack penalty, 1e6);
        3. if still infeasible: only the torque rows hard, every acceleration row soft.

        The torque rows, the robot's necessary condition, hold at every level. Returns ddq or None."""
        n = self.n

        def candidates():  # levels 2 and 3 are built only when level 1 has no solution (a rescue is on the 1 kHz path)
            yield self._A_dense, upper, lower, self._sense
            box_lo, box_hi = self._accel_jerk_box()
            v_lo, v_hi = self._bounds(q_rad, dq_rad_s, self._j_eff(terms))
            A3 = np.vstack([terms.M, np.eye(n), np.eye(n)])
            up3 = np.concatenate([upper[:n], box_hi, v_hi])
            lo3 = np.concatenate([lower[:n], box_lo, v_lo])
            yield A3, up3, lo3, self._sense_viability_soft
            yield A3, up3, lo3, self._sense_all_soft

        for A, up, lo, sense in candidates():
            try:
                x, _, flag, _ = daqp.solve(P, g, A, up, lo, sense)
            except Exception:  # noqa: BLE001 - a solver error means: no solution
                return None
            x = np.asarray(x, dtype=np.float64)
            if flag in (1, 2) and x.shape == (n,) and np.all(np.isfinite(x)):
                return x
        return None

    def _j_eff(self, terms: RobotTerms) -> np.ndarray:
        """How fast each joint's commanded acceleration can change, rad/s^3 (``tick_kernels.effective_jerk``)."""
        return np.minimum(self._ddq_step, 0.5 * self.dtau_step_nm / np.diag(terms.M)) / self.config.dt_s

    def _accel_jerk_box(self) -> tuple[np.ndarray, np.ndarray]:
        """The acceleration box intersected with the jerk box around ``last_ddq`` (nearest point when apart)."""
        a = self._bounds.a_max
        lo, hi = -a.copy(), a.copy()
        jerk_box(self.last_ddq, self._ddq_step, lo, hi)
        return lo, hi

    def _rescue(self, terms: RobotTerms, q_rad: np.ndarray, dq_rad_s: np.ndarray) -> np.ndarray | None:
        """The QP just assembled, solved by DAQP where OSQP's ADMM ran out of iterations (typically with the
        torque-rate rows and several joint bounds active at once; ~16 us). Returns ddq or None."""
        n = self.n
        P = self._P_dense
        P.T.flat[self._p_idx] = self._P_x  # upper triangle, column-major
        P = np.triu(P) + np.triu(P, 1).T
        self._A_dense[:n] = self._A_x.reshape(n, n + 1)[:, :n].T
        return self._daqp(P, self._g, terms, q_rad, dq_rad_s, self._l, self._u)

    def fallback(self, terms: RobotTerms, q_rad: np.ndarray, dq_rad_s: np.ndarray) -> np.ndarray:
        """The torque of a tick the QP could not solve (counted in ``failures``): see :meth:`fallback_torque`."""
        self.last_ok = False
        self.failures += 1
        self._ensure_started(terms)
        tau = self.fallback_torque(terms, q_rad, dq_rad_s)
        self.last_ddq = commanded_accel(terms, tau, self.last_ddq)
        self.tau_last = tau
        return tau

    def fallback_torque(self, terms: RobotTerms, q_rad: np.ndarray, dq_rad_s: np.ndarray) -> np.ndarray:
        """Ramp toward gravity/Coriolis compensation with joint damping (``h - fallback_kd dq``) within the robot's
        conditions: the acceleration nearest (DAQP) to the one that torque asks for, with the torque rows (effort,
        rate from the last torque) hard and the acceleration rows (acceleration, jerk, viability) soft. When even
        that has no solution, or the model terms are not finite, the last torque is held (zero rate)."""
        self._ensure_started(terms)
        tau_last = self.tau_last
        M, h = terms.M, terms.h
        if not all(np.all(np.isfinite(x)) for x in (M, h, q_rad, dq_rad_s)):
            return tau_last.copy()
        try:
            ddq_goal = np.linalg.solve(M, -self.config.fallback_kd * np.asarray(dq_rad_s, dtype=float))
        except np.linalg.LinAlgError:
            return tau_last.copy()
        lower, upper = self.constraint_bounds(terms, q_rad, dq_rad_s)
        self._A_dense[:self.n] = M
        ddq = self._daqp(np.eye(self.n), -ddq_goal, terms, q_rad, dq_rad_s, lower, upper)
        if ddq is None:
            return tau_last.copy()
        tau = M @ ddq + h
        clamp_rate(tau, tau_last, self.dtau_hard_nm)
        return tau if np.all(np.isfinite(tau)) else tau_last.copy()


def commanded_accel(terms: RobotTerms, tau_nm: np.ndarray, default: np.ndarray) -> np.ndarray:
    """The joint acceleration (7,) rad/s^2 that torque ``tau_nm`` commands in the state of ``terms``:
    ``M^-1 (tau - h)`` (``default`` when the terms are not finite or M is singular)."""
    try:
        ddq = np.linalg.solve(terms.M, np.asarray(tau_nm, dtype=np.float64) - terms.h)
    except np.linalg.LinAlgError:
        return np.array(default, dtype=np.float64)
    return ddq if np.all(np.isfinite(ddq)) else np.array(default, dtype=np.float64)
