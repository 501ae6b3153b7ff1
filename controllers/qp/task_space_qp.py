"""Task-space inverse-dynamics QP at 1 kHz: tasks and limits (``controllers.qp.tasks``, ``controllers.qp.limits``),
the default set on a compiled, warm-started fast path.

Decision variable: joint accelerations ``ddq`` (7). Torques follow as ``tau = M ddq + h``.

    minimize    sum_tasks 0.5 || J_i ddq + dJv_i - a_des_i ||^2_{W_i} + 0.5 w_post ||ddq - ddq_post||^2 + 0.5 reg ||ddq||^2
    subject to  tau_lo - h    <=  M ddq  <=  tau_hi - h           (effort and torque RATE: EffortRateLimit)
                ddq_lb        <=   ddq   <=  ddq_ub               (acceleration, jerk, velocity, position viability)

The torque-rate rows are the Panda's one necessary condition in torque control beyond finite values:
|tau_k - tau_(k-1)| < 1000 N m/s, measured against the last torque the robot *received* (``tau_last``; after a missed
tick that is the torque the robot held). It is a limit of this QP in every mode: the robot's limit, not a feature of
one method.

**The fast path** (the default tasks and limits: every tick of every study): the OSQP problem is set up once with the
full sparsity pattern of P (dense upper triangle) and A (dense M block + identity); each tick only the values are
updated, warm-started, assembled by one compiled kernel (``controllers.tick_kernels.assemble_qp``) straight into the
CSC value arrays. :meth:`TaskSpaceQP.problem` is the same QP summed from the task objects in numpy (the reference the
kernel is tested against). **Compliance** (``ImpedanceTask`` as the one extra task, the stiff position task weighed
0) runs the fast path too: a second kernel (``controllers.tick_kernels.impedance_acc``) computes the impedance's
desired acceleration, and the position rows take it as theirs with the impedance's weight (the position task, weighed
0, adds nothing: the sum is the same problem). With ``contact_task`` the QP holds both sets and
:meth:`TaskSpaceQP.set_contact` picks one each tick: the impedance in contact, the stiff position task in free space
(``--compliance``). **The general path** (any other set of tasks or limits, ``TaskSpaceQP(tasks=...,
limits=...)``): the stacked problem (:func:`controllers.qp.solve.build_problem`) solved by OSQP kept warm across ticks
(:class:`controllers.qp.warm.WarmProblemSolver`; ``solve_problem``, cold, gave the same within tolerance at ~1.1 ms a
tick).

If OSQP returns neither "solved" nor "solved inaccurate" (the latter counted in ``inaccurate``), or a non-finite
solution, the same QP goes to DAQP (dual active set; counted in ``rescues`` when it solves it): ADMM can stall when the
torque-rate rows and several joint bounds are active together, where an active-set method is exact in a few
iterations. If the rows cannot all hold, DAQP relaxes the limits of the highest priority first (the viability bounds,
priority 2; then the acceleration and jerk box, priority 1): the torque rows, priority 0, always hold. Only if that
fails too does the controller fall back (:meth:`TaskSpaceQP.fallback`, counted in ``failures``): the torque ramps
toward gravity compensation with joint damping, projected (DAQP again) onto the same rows. A solved torque that the
solver's tolerance left outside the rate limit is clamped onto it (counted in ``rate_clamps``).
"""

from __future__ import annotations

from ctypes import c_int
from dataclasses import replace

import numpy as np
import osqp

from controllers.limits import JointAccelerationBounds
from controllers.qp.config import QPConfig
from controllers.qp.impedance import ImpedanceTask
from controllers.qp.limits import AccelerationJerkLimit, DefaultLimits, EffortRateLimit, ViabilityLimit
from controllers.qp.solve import build_problem, daqp_ladder, soft_sense, stack_rows
from controllers.qp.warm import WarmProblemSolver, new_osqp
from controllers.qp.state import Constraint, QPState, TaskReference
from controllers.qp.tasks import PostureTask, RegularisationTask, TcpOrientationTask, TcpPositionTask
from controllers.robot_description import JointLimits
from controllers.robot_model import RobotTerms
from controllers.tick_kernels import assemble_qp, clamp_rate, impedance_acc, qp_params, torque


def default_tasks(config: QPConfig) -> tuple:
    """The tasks of every tick: TCP position, TCP orientation, posture, regularisation (the kernel's order)."""
    t, p = config.tcp, config.posture
    return (TcpPositionTask(t.kp_pos, t.kd_pos, t.w_pos, t.pos_err_max_m, t.tcp_vel_cap_m_s),
            TcpOrientationTask(t.kp_ori, t.kd_ori, t.w_ori), PostureTask(p.kp_post, p.kd_post, p.w_post),
            RegularisationTask(p.w_reg))


def default_limits(config: QPConfig, joint_limits: JointLimits) -> DefaultLimits:
    """The limits of every tick from the margins: effort and rate (0), acceleration and jerk (1), viability (2)."""
    m, lim = config.limits, joint_limits.arrays()
    bounds = JointAccelerationBounds(joint_limits, config.dt_s, m.brake_horizon_s, m.q_margin_rad, m.v_margin,
                                     m.a_margin)
    dtau_step = m.rate_margin * m.dtau_max_nm_s * config.dt_s
    ddq_step = m.jerk_margin * lim["j_max_rad_s3"] * config.dt_s
    return DefaultLimits(EffortRateLimit(lim["tau_max_nm"] * m.tau_margin, dtau_step),
                         AccelerationJerkLimit(bounds.a_max, ddq_step),
                         ViabilityLimit(bounds, ddq_step, dtau_step, config.dt_s))


def _kernel_params(tasks: tuple, limits: DefaultLimits, impedance: ImpedanceTask | None = None) -> np.ndarray:
    """The flat parameter vector of ``assemble_qp`` for the default tasks and limits (and, with ``impedance``, its
    weight on the position rows, which then take the impedance's desired acceleration as it is)."""
    pos, ori, post, reg = tasks
    b = limits.viability.bounds
    w_pos = pos.weight if impedance is None else impedance.weight
    return qp_params(np.array([pos.kp] * 3 + [ori.kp] * 3), np.array([pos.kd] * 3 + [ori.kd] * 3),
                     np.array([w_pos] * 3 + [ori.weight] * 3), post.kp, post.kd, post.weight,
                     post.weight + reg.weight, b.q_hi, b.q_lo, b.v_max, b.a_max, limits.effort_rate.tau_lim_nm,
                     b.dt_s, 1.0 / b.inv_h, limits.effort_rate.dtau_step_nm, limits.accel_jerk.ddq_step_rad_s2,
                     pos.pos_err_max_m, pos.tcp_vel_cap_m_s, pos_direct=impedance is not None)


def _compiled_impedance(config: QPConfig, extra_tasks: tuple, extra_limits: tuple) -> ImpedanceTask | None:
    """The impedance task when it is the one extra (no extra limit) and the stiff position task is weighed 0: the
    sum of the two is then the kernel's problem with the impedance on the position rows."""
    if len(extra_tasks) == 1 and not extra_limits and type(extra_tasks[0]) is ImpedanceTask and config.tcp.w_pos == 0:
        return extra_tasks[0]
    return None


class TaskSpaceQP:
    """The inverse-dynamics QP of the 1 kHz tick; ``solve`` returns torques and counts what it survived.

    Args:
        config: gains, weights, margins, solver settings.
        joint_limits: the robot's limits.
        extra_tasks: tasks beyond the default set (``controllers.qp.tasks.Task``): the general path.
        extra_limits: limits beyond the default set (``controllers.qp.limits.Limit``): the general path.
        contact_task: an impedance that takes the TCP position task's place while the robot is in contact
            (:meth:`set_contact`; ``--compliance``); in free space the position task tracks stiffly. None: the same
            tasks on every tick.
    """

    def __init__(self, config: QPConfig = QPConfig(), joint_limits: JointLimits = JointLimits(),
                 extra_tasks: tuple = (), extra_limits: tuple = (), contact_task: ImpedanceTask | None = None) -> None:
        self.config = config
        self.n = n = 7
        self.default_limits = default_limits(config, joint_limits)
        self.tasks = default_tasks(config) + tuple(extra_tasks)
        self.limits = self.default_limits.all + tuple(extra_limits)
        #: the impedance task the fast path computes in its kernel (compliance), or None
        self.impedance = _compiled_impedance(config, tuple(extra_tasks), tuple(extra_limits))
        self.fast_path = (not extra_tasks and not extra_limits) or self.impedance is not None
        er = self.default_limits.effort_rate
        #: the largest torque step per control period the QP plans (margined) and the hard guard (just inside the limit)
        self.dtau_step_nm = er.dtau_step_nm
        self.dtau_hard_nm = (1.0 - 1e-6) * config.limits.dtau_max_nm_s * config.dt_s
        self._params = _kernel_params(self.tasks[:4], self.default_limits, self.impedance)
        if self.impedance is not None:
            self._imp_k, self._imp_d = self.impedance.gains()
        self._set_up_contact(contact_task, extra_tasks)
        self._imp_acc = np.zeros(3)
        p_pattern = np.triu(np.ones((n, n)))
        a_pattern = np.vstack([np.ones((n, n)), np.eye(n)])
        self._p_pattern, self._a_pattern = p_pattern, a_pattern
        self._p_idx = np.flatnonzero(p_pattern.ravel(order="F"))
        self._P_x, self._g, self._A_x = np.empty(len(self._p_idx)), np.empty(n), np.empty(int(a_pattern.sum()))
        self._l, self._u = np.empty(2 * n), np.empty(2 * n)
        #: the general path's solver (extra tasks or limits): OSQP kept warm on the stacked problem
        self._general = WarmProblemSolver(config.solver.eps, config.solver.max_iter)
        self._setup_solver()
        self._P_dense = np.zeros((n, n))
        self._A_dense = np.vstack([np.zeros((n, n)), np.eye(n)])
        self._sense = np.zeros(2 * n, dtype=c_int)
        self._ok_status = (int(osqp.SolverStatus.OSQP_SOLVED), int(osqp.SolverStatus.OSQP_SOLVED_INACCURATE))
        self._inaccurate_status = int(osqp.SolverStatus.OSQP_SOLVED_INACCURATE)
        self.inaccurate = self.failures = self.solves = self.rate_clamps = self.rescues = 0
        self.last_ok = True
        self.last_ddq = np.zeros(n)
        #: the last torque the robot received, N*m (None until :meth:`reset` or the first command: then the
        #: bias torque h of that first state, i.e. the robot holding itself as it does before a controller starts)
        self.tau_last: np.ndarray | None = None

    def _set_up_contact(self, contact_task: ImpedanceTask | None, extra_tasks: tuple) -> None:
        """The two task sets :meth:`set_contact` switches between: as built (free space), and with the position task
        weighed 0 and ``contact_task`` in its place (in contact; on the fast path when there is no other extra)."""
        #: the impedance that replaces the position task in contact (None: no switch), and whether it does now
        self.contact_task, self.in_contact = contact_task, False
        self._tasks_free = self._tasks_contact = None  # (tasks, kernel parameters, compiled impedance) of each
        #: the measured contact normal the impedance's cap acts along (zeros: none; only with ``pressing_only``)
        self._normal = np.zeros(3)
        self._pressing_only = contact_task is not None and contact_task.pressing_only
        if contact_task is None:
            return
        if type(contact_task) is not ImpedanceTask or self.impedance is not None:
            raise ValueError(f"contact_task must be an ImpedanceTask, in a QP that has none among its extra tasks; "
                             f"got {contact_task!r}")
        soft = default_tasks(replace(self.config, tcp=replace(self.config.tcp, w_pos=0.0))) + tuple(extra_tasks)
        compiled = contact_task if self.fast_path else None
        self._tasks_free = (self.tasks, self._params, None)
        params = self._params if compiled is None else _kernel_params(soft[:4], self.default_limits, compiled)
        self._tasks_contact = (soft + (contact_task,), params, compiled)
        self._imp_k, self._imp_d = contact_task.gains()

    def set_contact(self, in_contact: bool, normal: np.ndarray | None = None) -> None:
        """Whether the robot is in contact this tick (the controller's :class:`ComplianceGate`): with a
        ``contact_task``, the impedance tracks the reference in contact and the stiff position task in free space
        (a soft spring whose force is capped cannot brake the arm's own momentum: measured, a pick's open hand fell
        5-8 cm under its reference onto the belt). Without one, nothing changes. ``normal``: the measured external
        force's direction this tick (3,), unit, world frame, or None (none measured): what an impedance whose cap
        acts on the push into the contact (``ImpedanceTask.pressing_only``) caps along."""
        if self.contact_task is None:
            return
        if self._pressing_only:
            if normal is None:
                self._normal[:] = 0.0
            else:
                self._normal[:] = normal
        if bool(in_contact) == self.in_contact:
            return
        self.in_contact = bool(in_contact)
        self.tasks, self._params, self.impedance = self._tasks_contact if self.in_contact else self._tasks_free

    def _new_solver(self) -> osqp.OSQP:
        """An OSQP problem set up on the fixed sparsity patterns (~0.3 ms), with this QP's settings."""
        s = self.config.solver
        return new_osqp(self._p_pattern, self._a_pattern, s.eps, s.max_iter)

    def _setup_solver(self) -> None:
        """(Re)build the OSQP problem: no warm start or adapted rho left (the general path's too)."""
        self._general.reset()
        self._solver = self._new_solver()
        # The low-level solver object: the high-level wrapper's update()/solve() spend ~50 us per tick
        # in Python bookkeeping (derivative caches, info namespaces) that a 1 kHz loop does not need.
        self._ext = self._solver._solver

    def assembled(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Copies of the last problem the fast path assembled, as OSQP takes it: ``(P_x, q, A_x, l, u)`` (the values
        of the fixed sparsity patterns, the linear term, the bounds). What ``mmact_ctrl.bench --floor`` replays."""
        return self._P_x.copy(), self._g.copy(), self._A_x.copy(), self._l.copy(), self._u.copy()

    def bare_solver(self) -> osqp.OSQP:
        """A fresh OSQP problem on this QP's sparsity patterns and settings, apart from the one this QP solves with
        (its warm start untouched); its low-level object ``._solver`` takes the calls the fast path makes each tick
        (``update_data_vec``, ``update_data_mat``, ``solve``): the floor benchmark times them."""
        return self._new_solver()

    def state(self, terms: RobotTerms, q_rad: np.ndarray, dq_rad_s: np.ndarray, ref: TaskReference) -> QPState:
        """What the tasks and limits read at this tick."""
        self._ensure_started(terms)
        normal = self._normal.copy() if self._pressing_only and np.any(self._normal != 0.0) else None
        return QPState(terms, q_rad, dq_rad_s, ref, self.tau_last, self.last_ddq, normal)

    # ---- the episode ----------------------------------------------------------------------------------------
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
        self.set_contact(False)

    def warm_up(self, terms: RobotTerms, q_rad: np.ndarray, dq_rad_s: np.ndarray, ref: TaskReference) -> None:
        """Run every path of :meth:`solve` once on this state, the rare ones too (DAQP's rescue in its three levels
        and the fallback, with the compiled kernels only they call), then forget it: the first rescue of a run no
        longer pays for loading those kernels on the 1 kHz path (measured: 6 ms, in a real-time episode 7 missed
        commands in a row). The solver and the counters are set up anew (:meth:`reset` does it again per episode)."""
        tau_was, ddq_was = self.tau_last, self.last_ddq
        self.tau_last, self.last_ddq = np.array(terms.h, dtype=np.float64), np.zeros(self.n)
        self.solve(terms, q_rad, dq_rad_s, ref)
        if self.contact_task is not None:  # the contact set's kernel too: not loaded at the first touch of a run
            self.set_contact(True)
            self.solve(terms, q_rad, dq_rad_s, ref)
            self.set_contact(False)
        self._rescue(terms, q_rad, dq_rad_s)
        self.fallback(terms, q_rad, dq_rad_s)
        state = self.state(terms, q_rad, dq_rad_s, ref)
        self.default_limits.accel_jerk.rows(state)  # what only DAQP's relaxed levels compute
        self.default_limits.viability.rows(state)
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

    # ---- the problem, in numpy ------------------------------------------------------------------------------
    def problem(self, terms: RobotTerms, q_rad: np.ndarray, dq_rad_s: np.ndarray,
                ref: TaskReference) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """This tick's QP summed from the task objects, in dense form ``min 0.5 x'Px + g'x  s.t.  lower <= A x <=
        upper``, with the default limits merged as the kernel merges them (``[M; I]``) and any extra limits' rows
        below."""
        state = self.state(terms, q_rad, dq_rad_s, ref)
        P, g = build_problem(self.tasks, (), state)[:2]
        lower, upper = self.constraint_bounds(terms, q_rad, dq_rad_s)
        A = np.vstack([terms.M, np.eye(self.n)])
        extra = [lim.rows(state) for lim in self.limits[3:]]
        if extra:
            A = np.vstack([A] + [r.A for r in extra])
            lower = np.concatenate([lower] + [r.lower for r in extra])
            upper = np.concatenate([upper] + [r.upper for r in extra])
        return P, g, A, lower, upper

    def constraint_bounds(self, terms: RobotTerms, q_rad: np.ndarray, dq_rad_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(lower, upper)`` (14,) of ``lower <= [M; I] ddq <= upper`` in this state: the torque rows (effort and
        rate around ``tau_last``, minus h) and the acceleration rows (acceleration, jerk-aware velocity and position
        viability, intersected with the jerk box around ``last_ddq``); numpy, the reference of the kernel."""
        self._ensure_started(terms)
        return self.default_limits.merged(QPState(terms, q_rad, dq_rad_s, None, self.tau_last, self.last_ddq))

    # ---- the tick -------------------------------------------------------------------------------------------
    def solve(self, terms: RobotTerms, q_rad: np.ndarray, dq_rad_s: np.ndarray, ref: TaskReference) -> np.ndarray:
        """Torques (7,) N*m that track ``ref`` within limits, the torque rate included; a safe fallback
        (counted) if no solver solves it. The result becomes ``tau_last`` (the caller sends it to the robot)."""
        self.solves += 1
        self._ensure_started(terms)
        tau = np.empty(self.n)
        if self.fast_path:
            ddq, ok = self._solve_fast(terms, q_rad, dq_rad_s, ref, tau)
        else:
            ddq = self._general.solve(build_problem(self.tasks, self.limits, self.state(terms, q_rad, dq_rad_s, ref)))
            ok = ddq is not None and torque(terms.M, terms.h, ddq, tau)
        if ok:
            if clamp_rate(tau, self.tau_last, self.dtau_hard_nm) > 1e-9:  # the solver's tolerance, rare
                self.rate_clamps += 1
                ddq = commanded_accel(terms, tau, ddq)
            self.last_ok = True
            self.last_ddq = ddq
            self.tau_last = tau
            return tau  # not clipped to the effort limits: the safety monitor checks what is sent
        return self.fallback(terms, q_rad, dq_rad_s)

    def _solve_fast(self, terms: RobotTerms, q_rad, dq_rad_s, ref: TaskReference, tau: np.ndarray):
        """The default set (or with compliance's impedance): the compiled assembly, warm-started OSQP, DAQP's rescue.
        Returns (ddq, ok)."""
        acc = ref.acc_m_s2
        if self.impedance is not None:  # the position rows' desired acceleration is the impedance's
            acc = self._imp_acc
            impedance_acc(terms.M, terms.J, terms.pos_m, terms.rot, terms.vel, ref.pos_m, ref.vel_m_s, ref.acc_m_s2,
                          self._imp_k, self._imp_d, self.impedance.force_max_n, self._normal, acc)
        assemble_qp(terms.M, terms.h, terms.J, terms.dJv, terms.pos_m, terms.rot, terms.vel, ref.pos_m, ref.vel_m_s,
                    acc, ref.rot, ref.ang_vel_rad_s, ref.ang_acc_rad_s2, ref.q_post_rad, q_rad, dq_rad_s,
                    self.tau_last, self.last_ddq, self._params, self._P_x, self._g, self._A_x, self._l, self._u)
        ext = self._ext
        ext.update_data_vec(self._g, self._l, self._u)  # (q, l, u) and (P_x, P_i, A_x, A_i): positional arguments
        ext.update_data_mat(self._P_x, None, self._A_x, None)  # are parsed faster than keywords (0.4 us a tick)
        ext.solve()
        status = int(ext.info.status_val)
        ddq = np.array(ext.solution.x)
        ok = status in self._ok_status and torque(terms.M, terms.h, ddq, tau)  # tau = M ddq + h, all finite
        if not ok:  # ADMM stalls when many limits are active at once: the exact active-set solver takes over
            ddq = self._rescue(terms, q_rad, dq_rad_s)
            ok = ddq is not None and torque(terms.M, terms.h, ddq, tau)
            self.rescues += ok
        elif status == self._inaccurate_status:
            self.inaccurate += 1
        return ddq, ok

    def _daqp(self, P: np.ndarray, g: np.ndarray, terms: RobotTerms, q_rad: np.ndarray, dq_rad_s: np.ndarray,
              lower: np.ndarray, upper: np.ndarray) -> np.ndarray | None:
        """``min 0.5 x'Px + g'x`` over ddq with DAQP under the rows of this tick, down the ladder of relaxations:
        every row hard (``lower <= [M; I] ddq <= upper``, the rows OSQP had); then the viability bounds soft
        (priority 2; the torque rows and the acceleration and jerk box hard); then the box soft too (priority 1). The
        torque rows, the robot's necessary condition (priority 0), hold at every level. Returns ddq or None."""
        n = self.n

        def levels():  # the relaxed levels are built only when every row hard has no solution (on the 1 kHz path)
            yield self._A_dense, upper, lower, self._sense
            state = QPState(terms, q_rad, dq_rad_s, None, self.tau_last, self.last_ddq)
            lim = self.default_limits
            rows = (Constraint(terms.M, lower[:n], upper[:n], lim.effort_rate.priority), lim.accel_jerk.rows(state),
                    lim.viability.rows(state))
            A, lo, up, priority = stack_rows(rows)
            for relax_from in (lim.viability.priority, lim.accel_jerk.priority):
                yield A, up, lo, soft_sense(priority, relax_from)

        return daqp_ladder(P, g, levels())

    def _rescue(self, terms: RobotTerms, q_rad: np.ndarray, dq_rad_s: np.ndarray) -> np.ndarray | None:
        """The QP just assembled, solved by DAQP where OSQP's ADMM ran out of iterations (typically with the
        torque-rate rows and several joint bounds active at once; ~16 us). Returns ddq or None."""
        n = self.n
        P = self._P_dense
        P.T.flat[self._p_idx] = self._P_x  # upper triangle, column-major
        P = np.triu(P) + np.triu(P, 1).T
        self._A_dense[:n] = self._A_x.reshape(n, n + 1)[:, :n].T
        return self._daqp(P, self._g, terms, q_rad, dq_rad_s, self._l, self._u)

    # ---- when nothing solves ---------------------------------------------------------------------------------
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
        rate from the last torque) hard and the acceleration rows (acceleration, jerk, viability) relaxed as needed.
        When even that has no solution, or the model terms are not finite, the last torque is held (zero rate)."""
        self._ensure_started(terms)
        tau_last = self.tau_last
        M, h = terms.M, terms.h
        if not all(np.all(np.isfinite(x)) for x in (M, h, q_rad, dq_rad_s)):
            return tau_last.copy()
        try:
            ddq_goal = np.linalg.solve(M, -self.config.solver.fallback_kd * np.asarray(dq_rad_s, dtype=float))
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
