"""Task-space MPC between the Ruckig smoother and the 1 kHz inverse-dynamics QP.

At 50-100 Hz the MPC previews the task-space reference (the retargeted chunk, the Kalman
filter's predicted target) over a short horizon (default 10 x 40 ms = 0.4 s), respects the
joint position / velocity / acceleration limits, and hands the QP a joint- and task-space
reference for the next interval (:meth:`MPCPlan.sample`, :meth:`MPCPlan.sample_task`).

Model
-----
Joint-space double integrator with the joint accelerations piecewise constant over each step
of ``dt_s`` (exact discretization, so :meth:`MPCPlan.sample` interpolates exactly):
``dq[k+1] = dq[k] + dt u[k]``, ``q[k+1] = q[k] + dt dq[k] + dt^2/2 u[k]``.
The task is linearized around the current state: ``p[k] = p0 + J_lin (q[k] - q0)`` and the
orientation error (a world-frame rotation vector relative to the current orientation)
``r[k] = J_ang (q[k] - q0)``, with ``J`` the 6x7 TCP Jacobian in LOCAL_WORLD_ALIGNED.
The linearization is refreshed at every solve (real-time-iteration style); only the first
interval of each plan is used before the next solve, where the model is accurate.

Decision variables ``z = [u_0, q_1, dq_1, ..., u_{N-1}, q_N, dq_N]`` (210 for N = 10; the
current state is a parameter), 14 N dynamics equality rows, 7 terminal rows, simple bounds on
every variable.  Cost, per step k = 1..N::

    w_pos |p[k] - pos_ref[k-1]|^2 + w_rot |r[k] - rotvec_ref[k-1]|^2 + w_posture |q[k] - q_nom|^2
    + w_null_posture (q[k] - q_nom)' N (q[k] - q_nom)
    + w_vel |dq[k]|^2 + w_acc |u[k-1]|^2 + w_jerk |u[k-1] - u[k-2]|^2,   plus w_terminal_vel |dq[N]|^2

with ``N`` the (damped) null-space projector of the 6x7 Jacobian at the current state (:func:`null_projector`:
the self-motion is pulled toward the nominal posture, the TCP task is not traded off) and
``u[-1]`` the acceleration the previous plan commands now (smooth hand-over between
plans).  References farther than ``max_ref_dist_m`` / ``max_ref_angle_rad`` from the current
pose are pulled in along their direction (the linear model means nothing farther away, and a
far goal makes the QP badly scaled).

Constraints at every step: ``q`` inside the limits shrunk by ``q_margin_rad`` (and by the at most
``a_max dt^2 / 8`` a constant-acceleration interval can overshoot its knots), ``|dq|`` and
``|u|`` inside ``v_limit_scale`` / ``a_limit_scale`` times the limits, and a terminal
*braking set* ``q_min <= q[N] + dq[N] * v_max / a_max <= q_max`` (per joint).  It is linear and
conservative (stopping distance v^2/(2a) <= v v_max / a, and one braking step keeps a state
inside it): from a terminal state inside it the arm can always stop within the limits after
the horizon, so the shifted problem stays feasible (recursive feasibility, nominal model).

Feasibility guard: if the current state is already outside the margins (model error, a
bump, solver tolerance), the position/velocity bounds of each step are widened per joint just
enough to contain the maximal-braking trajectory from the current state, so the QP stays
feasible and the plan brakes back toward the admissible set instead of failing.

The returned accelerations are clipped to the acceleration box and re-integrated exactly
from the measured state, so a plan is always dynamically consistent and never exceeds the
acceleration limits; positions/velocities can enter the margin band by the solver tolerance
(measured <= 2.2 mrad of the 50 mrad band), never the true limits.

Implementation and measurements
-------------------------------
The QP is built ONCE symbolically with CasADi (SX): one ``casadi.Function`` (after ``cse``)
maps the parameter vector (q0, dq0, u_prev, J, references, q_nom, N) to the nonzeros of
(triu(H), g, A, bounds) with a fixed sparsity; it is evaluated through ``Function.buffer()``
straight into numpy memory (~30 us; going through ``DM`` -> numpy cost ~300-400 us).  ``A``
is constant, only ``H`` (through J), ``g`` and the bounds change.

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
the fallback below handles a late solve.

Fallback: on a solver exception, a non-success status, a non-finite solution or a solve
slower than ``max_solve_ms``, :meth:`TaskSpaceMPC.solve` returns the previous plan re-timed
to start now (or, without one still covering ``t_s``, a plan that brakes to rest within the
acceleration limits) with ``ok=False`` and counts it in ``failures`` / ``late``.

This module imports numpy and casadi (and osqp for the direct OSQP backend) only.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from controllers.robot_description import HOME_Q_RAD, JointLimits

N_JOINTS = 7

#: Solver back-ends understood by :class:`MPCConfig.solver`. ``"osqp_direct"`` drives OSQP 1.x
#: itself (set up once on the CasADi sparsity, then ``update()``); the others go through
#: ``casadi.conic`` with the named plugin.
SOLVERS: tuple[str, ...] = ("osqp_piqp", "osqp_direct", "piqp", "osqp", "qrqp", "proxqp")


@dataclass(frozen=True)
class MPCConfig:
    """Settings of :class:`TaskSpaceMPC` (all fixed when the problem is built).

    Attributes:
        horizon_steps: number of steps N of the horizon.
        dt_s: step length, s (horizon = N * dt_s).
        rate_hz: rate at which the caller re-solves (informational; the plan is valid for its horizon).
        w_pos: weight of the TCP position error, 1/m^2.
        w_rot: weight of the TCP orientation error (rotation vector), 1/rad^2.
        w_posture: weight pulling q toward the nominal posture, 1/rad^2 (in every direction: it biases the task).
        w_null_posture: weight of the posture error projected onto the null space of the 6x7 task Jacobian at
            the current state (:func:`null_projector`), 1/rad^2: pulls the self-motion toward the nominal posture
            without trading off the TCP task (in the linear model). Without it the self-motion of the 7-DoF arm
            drifts wherever the approach leaves it (the plain ``w_posture`` is too weak to move it against the
            acceleration costs): measured on the 0.4 m/s circle, the arm wound up to ``q1 ~ 1.4, q3 ~ -1.8``
            (smallest singular value of J 0.035-0.06 instead of ~0.2 at the posture the same TCP pose has near
            home), saturated joint velocities / accelerations and left the circle by up to 0.1 m. Measured
            (circle, mean error after the first reach, seeds 0-19 / 100-119, with the turn-aware preview of
            ``target_estimator.turn_extrapolate``): 22.8 / 21.1 mm without, 21.4 / 21.3 with it (3.0: 22.2 / 20.1);
            alone, with the old preview, it made no difference (24.0 vs 23.5 mm): docs/perception/circle_tracking.md.
        null_damping: damping of the pseudo-inverse in the null-space projector, m (or rad): directions of the
            task the arm can barely move in (singular values below it) count as null space, so the posture
            pull also leads the arm out of a near-singular configuration.
        w_vel: joint velocity damping weight, s^2/rad^2.
        w_acc: joint acceleration weight, s^4/rad^2.
        w_jerk: weight of the acceleration change between steps (including from the
            previously applied acceleration), s^4/rad^2.
        w_terminal_vel: weight of the terminal joint velocity, s^2/rad^2.
        max_ref_dist_m: each position reference is pulled toward the current TCP position to at
            most this distance, m (the linearization is not meaningful farther away, and a far
            goal otherwise makes the QP badly scaled; the direction is kept).
        max_ref_angle_rad: the same for the orientation references, rad.
        q_margin_rad: the position limits are shrunk by this much on each side, rad.
        v_limit_scale: fraction of the velocity limits used by the plan.
        a_limit_scale: fraction of the acceleration limits used by the plan.
        solver: one of :data:`SOLVERS`.
        max_solve_ms: a solve slower than this counts as late and its result is discarded.
        solver_options: extra options passed to the solver (a tuple of (key, value) pairs so
            the config stays hashable).
    """

    horizon_steps: int = 10
    dt_s: float = 0.04
    rate_hz: float = 50.0
    w_pos: float = 1.0e4
    w_rot: float = 1.0e3
    w_posture: float = 1.0e-2
    w_null_posture: float = 1.0
    null_damping: float = 0.05
    w_vel: float = 1.0e-3
    w_acc: float = 1.0e-3
    w_jerk: float = 1.0e-3
    w_terminal_vel: float = 1.0e-1
    max_ref_dist_m: float = 0.2
    max_ref_angle_rad: float = 0.5
    q_margin_rad: float = 0.05
    v_limit_scale: float = 0.95
    a_limit_scale: float = 0.95
    solver: str = "osqp_piqp"
    max_solve_ms: float = 10.0
    solver_options: tuple[tuple[str, Any], ...] = ()

    def __post_init__(self) -> None:
        if self.horizon_steps < 1:
            raise ValueError("horizon_steps must be >= 1")
        if not self.dt_s > 0.0:
            raise ValueError("dt_s must be > 0")
        if self.solver not in SOLVERS:
            raise ValueError(f"solver must be one of {SOLVERS}, got {self.solver!r}")
        if not (0.0 < self.v_limit_scale <= 1.0 and 0.0 < self.a_limit_scale <= 1.0):
            raise ValueError("v_limit_scale and a_limit_scale must be in (0, 1]")
        if not (self.max_ref_dist_m > 0.0 and self.max_ref_angle_rad > 0.0):
            raise ValueError("max_ref_dist_m and max_ref_angle_rad must be > 0")
        if self.q_margin_rad < 0.0:
            raise ValueError("q_margin_rad must be >= 0")
        if not self.null_damping > 0.0:
            raise ValueError("null_damping must be > 0")
        for name in ("w_pos", "w_rot", "w_posture", "w_null_posture", "w_vel", "w_acc", "w_jerk", "w_terminal_vel"):
            if getattr(self, name) < 0.0:
                raise ValueError(f"{name} must be >= 0")
        if self.w_acc <= 0.0:
            raise ValueError("w_acc must be > 0 (keeps the QP strictly convex)")


@dataclass(frozen=True)
class MPCPlan:
    """One solution of the MPC: a joint trajectory with piecewise-constant accelerations.

    Attributes:
        t0_s: time of the first knot, s.
        dt_s: knot spacing, s.
        q_rad: joint positions at the knots, (N+1, 7).
        dq_rad_s: joint velocities at the knots, (N+1, 7).
        ddq_rad_s2: joint accelerations over each interval, (N, 7).
        ee_pos_m: predicted TCP positions at the knots (linearized model), (N+1, 3).
        ok: False when this plan is a fallback (failure, late solve).
        solve_us: wall time of the solve() call that produced it, microseconds.
        ee_jacobian_lin: 3x7 linear Jacobian used for the task-space prediction.
    """

    t0_s: float
    dt_s: float
    q_rad: np.ndarray
    dq_rad_s: np.ndarray
    ddq_rad_s2: np.ndarray
    ee_pos_m: np.ndarray
    ok: bool
    solve_us: float
    ee_jacobian_lin: np.ndarray = field(default_factory=lambda: np.zeros((3, N_JOINTS)))

    @property
    def horizon_steps(self) -> int:
        return int(self.ddq_rad_s2.shape[0])

    @property
    def t_end_s(self) -> float:
        return self.t0_s + self.horizon_steps * self.dt_s

    def sample(self, t_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Joint reference (q rad, dq rad/s, ddq rad/s^2) at time ``t_s``.

        Exact inside the horizon (constant acceleration per interval); clamped to the first
        knot before ``t0_s``; past the end the last position is held at rest (dq = ddq = 0).
        """
        tau = float(t_s) - self.t0_s
        n = self.horizon_steps
        if tau >= n * self.dt_s:
            return self.q_rad[n].copy(), np.zeros(N_JOINTS), np.zeros(N_JOINTS)
        tau = max(tau, 0.0)
        k = min(int(np.floor(tau / self.dt_s + 1e-9)), n - 1)  # robust at the knots
        s = max(tau - k * self.dt_s, 0.0)
        a = self.ddq_rad_s2[k]
        q = self.q_rad[k] + self.dq_rad_s[k] * s + 0.5 * a * s * s
        dq = self.dq_rad_s[k] + a * s
        return q, dq, a.copy()

    def sample_task(self, t_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Predicted TCP reference (pos m, vel m/s, acc m/s^2) at ``t_s``, linearized:
        ``p0 + J_lin (q(t) - q0)``, ``J_lin dq(t)``, ``J_lin ddq(t)`` (the dJ/dt dq term is neglected)."""
        q, dq, ddq = self.sample(t_s)
        jl = self.ee_jacobian_lin
        pos = self.ee_pos_m[0] + jl @ (q - self.q_rad[0])
        return pos, jl @ dq, jl @ ddq


def null_projector(jacobian_6x7: np.ndarray, damping: float) -> np.ndarray:
    """``I - J^T (J J^T + damping^2 I)^-1 J`` (7x7, symmetric): the projector onto the joint motions that do not move
    the TCP (the self-motion of a 7-DoF arm), damped so that it is continuous across singularities (directions with
    singular values well below ``damping`` count as null space)."""
    j = np.asarray(jacobian_6x7, dtype=float)
    jjt = j @ j.T + (damping * damping) * np.eye(j.shape[0])
    return np.eye(j.shape[1]) - j.T @ np.linalg.solve(jjt, j)


def _rollout(q0: np.ndarray, dq0: np.ndarray, ddq: np.ndarray, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact double-integrator rollout of piecewise-constant accelerations ddq (N, 7)."""
    n = ddq.shape[0]
    q = np.empty((n + 1, q0.size))
    dq = np.empty((n + 1, q0.size))
    q[0], dq[0] = q0, dq0
    for k in range(n):
        dq[k + 1] = dq[k] + dt_s * ddq[k]
        q[k + 1] = q[k] + dt_s * dq[k] + 0.5 * dt_s * dt_s * ddq[k]
    return q, dq


def braking_accelerations(dq0_rad_s: np.ndarray, a_max_rad_s2: np.ndarray, n_steps: int, dt_s: float) -> np.ndarray:
    """Per-joint accelerations (n_steps, 7) that bring ``dq0`` to rest as fast as ``a_max`` allows."""
    out = np.zeros((n_steps, dq0_rad_s.size))
    v = np.asarray(dq0_rad_s, dtype=float).copy()
    for k in range(n_steps):
        a = -np.sign(v) * np.minimum(a_max_rad_s2, np.abs(v) / dt_s)
        out[k] = a
        v = v + dt_s * a
    return out


class _QPBuilder:
    """Builds the parametric QP once with CasADi SX (fixed sparsity).

    Decision vector ``z = [u_0, q_1, dq_1, u_1, q_2, dq_2, ..., u_{N-1}, q_N, dq_N]`` (the
    current state is a parameter, not a variable); constraints ``[dynamics (2*7*N rows) = 0;
    terminal braking set (7 rows)]`` plus simple bounds on every variable.  ``eval_fun`` maps
    the parameter vector to one dense vector holding, in this order, the nonzeros of
    ``triu(H)`` (CSC order), ``g``, the nonzeros of ``A`` (CSC order), ``lba``, ``uba``,
    ``lbx``, ``ubx``; it is evaluated through ``Function.buffer()`` straight into numpy
    memory (converting CasADi DMs to numpy costs ~0.3 ms per call here, the SX evaluation
    itself ~30 us after common-subexpression elimination).
    """

    def __init__(self, cfg: MPCConfig, limits: JointLimits) -> None:
        n, dt, nj = cfg.horizon_steps, cfg.dt_s, N_JOINTS
        lim = limits.arrays()
        q_lo = lim["q_min_rad"] + cfg.q_margin_rad
        q_hi = lim["q_max_rad"] - cfg.q_margin_rad
        if np.any(q_lo >= q_hi):
            raise ValueError("q_margin_rad leaves no admissible joint range")
        v_max = cfg.v_limit_scale * lim["v_max_rad_s"]
        a_max = cfg.a_limit_scale * lim["a_max_rad_s2"]
        # The bounds hold at the knots; between two knots a constant acceleration a can carry q at
        # most a dt^2 / 8 past them (a peak mid-interval): shrink the knot bounds by that much so the
        # continuous plan, which the 1 kHz QP tracks, stays inside the margined range.
        q_lo = q_lo + a_max * dt * dt / 8.0
        q_hi = q_hi - a_max * dt * dt / 8.0
        self.a_max = a_max
        self.n = n
        c_brake = v_max / a_max  # s: conservative terminal braking-set coefficient

        # parameters
        q0 = ca.SX.sym("q0", nj)
        dq0 = ca.SX.sym("dq0", nj)
        u_prev = ca.SX.sym("u_prev", nj)
        jac = ca.SX.sym("jac", 6, nj)  # 6x7 LOCAL_WORLD_ALIGNED; p0 cancels out of the QP
        e_pos = ca.SX.sym("e_pos", 3, n)  # pos_ref[k] - p0, m
        r_ref = ca.SX.sym("r_ref", 3, n)  # rotvec reference relative to the current orientation, rad
        q_nom = ca.SX.sym("q_nom", nj)
        null = ca.SX.sym("null", nj, nj)  # projector onto the task's (damped) null space at q0, symmetric
        params = [q0, dq0, u_prev, jac, e_pos, r_ref, q_nom, null]
        p_all = ca.vertcat(*[ca.vec(p) for p in params])
        self.n_params = int(p_all.numel())

        us = [ca.SX.sym(f"u{k}", nj) for k in range(n)]
        qs = [ca.SX.sym(f"q{k + 1}", nj) for k in range(n)]
        dqs = [ca.SX.sym(f"dq{k + 1}", nj) for k in range(n)]
        z = ca.vertcat(*[ca.vertcat(us[k], qs[k], dqs[k]) for k in range(n)])
        stride = 3 * nj
        self.u_idx = (np.arange(n)[:, None] * stride + np.arange(nj)[None, :]).ravel()

        jl, ja = jac[0:3, :], jac[3:6, :]
        cost = 0
        gaps = []
        q_prev, dq_prev, u_before = q0, dq0, u_prev
        for k in range(n):
            uk, q1, dq1 = us[k], qs[k], dqs[k]
            gaps.append(q_prev + dt * dq_prev + 0.5 * dt * dt * uk - q1)
            gaps.append(dq_prev + dt * uk - dq1)
            cost += cfg.w_acc * ca.sumsqr(uk) + cfg.w_jerk * ca.sumsqr(uk - u_before)
            dqq = q1 - q0
            cost += cfg.w_pos * ca.sumsqr(jl @ dqq - e_pos[:, k])
            cost += cfg.w_rot * ca.sumsqr(ja @ dqq - r_ref[:, k])
            cost += cfg.w_posture * ca.sumsqr(q1 - q_nom) + cfg.w_vel * ca.sumsqr(dq1)
            if cfg.w_null_posture > 0.0:
                dn = q1 - q_nom
                cost += cfg.w_null_posture * ca.dot(dn, null @ dn)
            q_prev, dq_prev, u_before = q1, dq1, uk
        cost += cfg.w_terminal_vel * ca.sumsqr(dqs[-1])
        g_con = ca.vertcat(*gaps, qs[-1] + c_brake * dqs[-1])
        self.n_con = int(g_con.numel())
        self.nz = int(z.numel())

        hess, grad = ca.hessian(cost, z)
        zero = ca.DM.zeros(self.nz)
        grad0 = ca.substitute(grad, z, zero)
        a_mat = ca.jacobian(g_con, z)
        b_con = -ca.substitute(g_con, z, zero)  # g_con = A z - b
        assert not ca.depends_on(a_mat, z) and not ca.depends_on(hess, z)

        # bounds; feasibility guard: widen them to contain the maximal-braking trajectory
        qk, vk = q0, dq0
        qb, vb = [], []
        for _ in range(n):
            ak = -ca.sign(vk) * ca.fmin(a_max, ca.fabs(vk) / dt)
            qk = qk + dt * vk + 0.5 * dt * dt * ak
            vk = vk + dt * ak
            qb.append(qk)
            vb.append(vk)
        eps = 1e-9
        lbx = ca.vertcat(*[ca.vertcat(-a_max, ca.fmin(q_lo, qb[k] - eps), ca.fmin(-v_max, vb[k] - eps)) for k in range(n)])
        ubx = ca.vertcat(*[ca.vertcat(a_max, ca.fmax(q_hi, qb[k] + eps), ca.fmax(v_max, vb[k] + eps)) for k in range(n)])
        term_b = qb[-1] + c_brake * vb[-1]
        n_dyn = 2 * nj * n
        lba = b_con + ca.vertcat(ca.DM.zeros(n_dyn), ca.fmin(q_lo, term_b - eps))
        uba = b_con + ca.vertcat(ca.DM.zeros(n_dyn), ca.fmax(q_hi, term_b + eps))

        self.h_sp = hess.sparsity()
        self.a_sp = a_mat.sparsity()
        hess_triu = ca.triu(hess)
        self.h_triu_sp = hess_triu.sparsity()
        #: symbolic QP data (for the conic back-ends, which take sparse matrices)
        self.qp_fun = ca.Function("mpc_qp", [p_all], [hess, grad0, a_mat, lba, uba, lbx, ubx],
                                  ["p"], ["h", "g", "a", "lba", "uba", "lbx", "ubx"])
        parts = [ca.vertcat(*hess_triu.nonzeros()), grad0, ca.vertcat(*a_mat.nonzeros()), lba, uba, lbx, ubx]
        self.part_sizes = [int(p.numel()) for p in parts]
        self.eval_fun = ca.Function("mpc_qp_vec", [p_all], [ca.cse(ca.vertcat(*parts))])


class _Evaluator:
    """Zero-copy evaluation of a one-input / one-output CasADi Function into numpy buffers."""

    def __init__(self, fun: ca.Function) -> None:
        self.fun = fun
        self.arg = np.zeros(fun.nnz_in(0))
        self.res = [np.zeros(fun.nnz_out(i)) for i in range(fun.n_out())]
        self._buf, self._trigger = fun.buffer()
        self._buf.set_arg(0, memoryview(self.arg))
        for i, r in enumerate(self.res):
            self._buf.set_res(i, memoryview(r))

    def __call__(self, p: np.ndarray) -> list[np.ndarray]:
        self.arg[:] = p
        self._trigger()
        return self.res


class _OSQPBackend:
    """OSQP 1.x driven directly: set up once on the CasADi sparsity (``[A; I]`` carries the
    simple bounds), then ``update()`` the values and re-solve warm-started."""

    def __init__(self, qp: _QPBuilder, options: dict[str, Any]) -> None:
        import osqp  # local: only this back-end needs it
        import scipy.sparse as sp

        self._eval = _Evaluator(qp.eval_fun)
        nz, nj = qp.nz, N_JOINTS
        sizes = np.cumsum([0] + qp.part_sizes)
        self._slices = [slice(int(a), int(b)) for a, b in zip(sizes[:-1], sizes[1:])]
        # set up on a representative parameter (dense Jacobian) so no structural nonzero is 0
        p_setup = np.zeros(qp.n_params)
        p_setup[3 * nj : 3 * nj + 6 * nj] = 0.1
        p_setup[-nj * nj:] = 0.1  # the null-space projector (dense)
        hx, g, ax, lba, uba, lbx, ubx = self._split(self._eval(p_setup))
        hs, as_ = qp.h_triu_sp, qp.a_sp
        p_mat = sp.csc_matrix((hx.copy(), np.asarray(hs.row()), np.asarray(hs.colind())), shape=(nz, nz))
        # [A; I] assembled by hand so that the position of every value in the CSC data is known
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
        self._l = np.empty(qp.n_con + nz)
        self._u = np.empty(qp.n_con + nz)
        settings = dict(verbose=False, warm_starting=True, polishing=False, eps_abs=1e-4, eps_rel=1e-4,
                        max_iter=2000, adaptive_rho=True, check_termination=5)
        settings.update(options)
        self.solver = osqp.OSQP()
        self._fill_bounds(lba, uba, lbx, ubx)
        self.solver.setup(P=p_mat, q=g, A=a_full, l=self._l, u=self._u, **settings)
        self._ext = self.solver._solver
        self.last_iter = 0
        self.last_status = 0

    def _split(self, vec: list[np.ndarray]) -> list[np.ndarray]:
        return [vec[0][s] for s in self._slices]

    def _fill_bounds(self, lba, uba, lbx, ubx) -> None:
        m = lba.size
        self._l[:m], self._l[m:] = lba, lbx
        self._u[:m], self._u[m:] = uba, ubx
        np.clip(self._l, -1e30, 1e30, out=self._l)
        np.clip(self._u, -1e30, 1e30, out=self._u)

    def solve(self, p: np.ndarray) -> tuple[np.ndarray, bool]:
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


class _ConicBackend:
    """``casadi.conic`` with a given plugin, created once on the fixed sparsity and wrapped with
    the QP-data function into one MX Function evaluated through ``buffer()`` (no DM
    conversions).  Success = finite and primal feasible to ``feas_tol`` (the conic stats are
    not reachable from inside an MX graph)."""

    def __init__(self, qp: _QPBuilder, plugin: str, options: dict[str, Any]) -> None:
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
        self.feas_tol = 1e-3
        solver = ca.conic("mpc_" + plugin, plugin, {"h": qp.h_sp, "a": qp.a_sp}, opts)
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
        fun = ca.Function("mpc_conic_" + plugin, [inputs], [packed])
        self._eval = _Evaluator(fun)
        self._np, self._nz, self._nc = qp.n_params, qp.nz, qp.n_con
        self._warm = np.zeros(2 * qp.nz + qp.n_con)

    def solve(self, p: np.ndarray) -> tuple[np.ndarray, bool]:
        out = self._eval(np.concatenate([p, self._warm]))[0]
        x = out[: self._nz].copy()
        viol = out[-1]
        ok = bool(np.all(np.isfinite(out)) and viol <= self.feas_tol)
        if ok:
            self._warm[:] = out[:-1]
        return x, ok


class _HybridBackend:
    """OSQP first (cheap when few constraints are active, warm-started); when it does not reach
    ``solved`` within ``osqp_max_iter`` iterations (it stalls when many velocity / position
    limits are active at once), the same QP is re-solved by PIQP (a proximal interior-point
    method whose iteration count hardly depends on the active set)."""

    def __init__(self, qp: _QPBuilder, options: dict[str, Any]) -> None:
        osqp_opts = {"max_iter": 60, **options}
        self.osqp = _OSQPBackend(qp, osqp_opts)
        self.piqp = _ConicBackend(qp, "piqp", {})
        self.piqp_calls = 0

    def solve(self, p: np.ndarray) -> tuple[np.ndarray, bool]:
        x, ok = self.osqp.solve(p)
        if ok and self.osqp.last_status == 1:
            return x, True
        self.piqp_calls += 1
        return self.piqp.solve(p)


def _as_array(name: str, value: Any, shape: tuple[int, ...]) -> np.ndarray:
    """Float64 copy of ``value`` with the given shape; ValueError naming ``name`` otherwise."""
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: not convertible to a float array ({exc})") from None
    if arr.shape != shape:
        raise ValueError(f"{name}: expected shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: contains NaN or inf")
    return arr


def _clamp_rows(vecs: np.ndarray, max_norm: float) -> np.ndarray:
    """Scale the rows of ``vecs`` whose norm exceeds ``max_norm`` down to ``max_norm``."""
    norms = np.linalg.norm(vecs, axis=1, keepdims=True)
    return vecs * np.minimum(1.0, max_norm / np.maximum(norms, 1e-300))


def _as_sequence(name: str, value: Any, n: int) -> np.ndarray:
    """(n, 3) reference sequence; a single (3,) point is held over the horizon."""
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: not convertible to a float array ({exc})") from None
    if arr.shape == (3,):
        arr = np.tile(arr, (n, 1))
    if arr.shape != (n, 3):
        raise ValueError(f"{name}: expected shape ({n}, 3) or (3,), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: contains NaN or inf")
    return arr


class TaskSpaceMPC:
    """Linear-time-varying task-space MPC over a joint double integrator (see the module doc).

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
        self.q_nominal_rad = _as_array("q_nominal_rad", q_nominal_rad, (N_JOINTS,))
        self._qp = _QPBuilder(config, limits)
        self._a_max = self._qp.a_max
        self._u_idx = self._qp.u_idx
        self.reset()

    def reset(self) -> None:
        """Forget the last plan, the counters and the solver's warm start (the back-end is set up again, ~2 ms; the
        CasADi problem, 0.3 s to build, is kept): an episode does not depend on the one before it."""
        config = self.config
        opts = dict(config.solver_options)
        if config.solver == "osqp_piqp":
            self._backend: _ConicBackend | _OSQPBackend | _HybridBackend = _HybridBackend(self._qp, opts)
        elif config.solver == "osqp_direct":
            self._backend = _OSQPBackend(self._qp, opts)
        else:
            self._backend = _ConicBackend(self._qp, config.solver, opts)
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
        t_s = float(t_s)
        if not np.isfinite(t_s):
            raise ValueError("t_s: not finite")
        q0 = _as_array("q_rad", q_rad, (N_JOINTS,))
        dq0 = _as_array("dq_rad_s", dq_rad_s, (N_JOINTS,))
        p0 = _as_array("ee_pos_m", ee_pos_m, (3,))
        jac = _as_array("jacobian_6x7", jacobian_6x7, (6, N_JOINTS))
        pos_ref = _as_sequence("pos_ref_m", pos_ref_m, n)
        rot_ref = np.zeros((n, 3)) if rotvec_err_ref_rad is None else _as_sequence("rotvec_err_ref_rad", rotvec_err_ref_rad, n)

        self.solves += 1
        prev = self.last_plan
        u_prev = prev.sample(t_s)[2] if prev is not None else np.zeros(N_JOINTS)
        e_pos = _clamp_rows(pos_ref - p0, self.config.max_ref_dist_m)
        e_rot = _clamp_rows(rot_ref, self.config.max_ref_angle_rad)
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
        q, dq = _rollout(q0, dq0, u, self.config.dt_s)
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
        with no previous plan covering ``t_s``, a plan braking to rest from the current state."""
        n, dt = self.config.horizon_steps, self.config.dt_s
        prev = self.last_plan
        if prev is not None and prev.t0_s <= t_s < prev.t_end_s:
            qs, dqs, _ = prev.sample(t_s)
            u = np.zeros((n, N_JOINTS))
            k_in = 0
            for k in range(n):
                tk = t_s + k * dt
                if tk >= prev.t_end_s - 1e-9:
                    break
                u[k] = prev.sample(tk + 1e-9)[2]
                k_in = k + 1
            if k_in < n:
                _, dq_mid = _rollout(qs, dqs, u[:k_in], dt)
                u[k_in:] = braking_accelerations(dq_mid[-1], self._a_max, n - k_in, dt)
            u = np.clip(u, -self._a_max, self._a_max)
            q, dq = _rollout(qs, dqs, u, dt)
            jl = prev.ee_jacobian_lin
            ee = prev.ee_pos_m[0] + (q - prev.q_rad[0]) @ jl.T
        else:
            u = braking_accelerations(dq0, self._a_max, n, dt)
            q, dq = _rollout(q0, dq0, u, dt)
            jl = jac[0:3].copy()
            ee = p0 + (q - q0) @ jl.T
        plan = MPCPlan(t_s, dt, q, dq, u, ee, False, (time.perf_counter() - t_start) * 1e6, jl)
        self.last_plan = plan
        return plan
