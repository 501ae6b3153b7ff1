"""Task-space MPC between the Ruckig smoother and the 1 kHz inverse-dynamics QP.

At 50-100 Hz the MPC previews the task-space reference (the retargeted chunk, the Kalman
filter's predicted target) over a short horizon (default 20 x 20 ms = 0.4 s), respects the
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

State ``x = (q, dq, u_prev)`` (21): the previous acceleration is carried in the state so that
the acceleration-change (jerk) penalty stays stage-wise, which keeps the problem in the
banded optimal-control form that HPIPM / fatrop exploit.  Cost, per step k = 1..N::

    w_pos |p[k] - pos_ref[k-1]|^2 + w_rot |r[k] - rotvec_ref[k-1]|^2 + w_posture |q[k] - q_nom|^2
    + w_vel |dq[k]|^2 + w_acc |u[k-1]|^2 + w_jerk |u[k-1] - u[k-2]|^2,   plus w_terminal_vel |dq[N]|^2

Constraints at every step: ``q`` inside the limits shrunk by ``q_margin_rad``, ``|dq|`` and
``|u|`` inside ``v_limit_scale`` / ``a_limit_scale`` times the limits, and a terminal
*braking set* ``q_min <= q[N] + dq[N] * v_max / a_max <= q_max`` (per joint). The braking set
is linear and conservative (stopping distance v^2/(2a) <= v v_max / a): from a terminal
state inside it the arm can always stop within the position limits after the horizon, so
the shifted problem stays feasible (recursive feasibility for the nominal model).

Feasibility guard: if the current state is already outside the margins (model error, a
bump), the position/velocity bounds of each step are widened per joint just enough to
contain the maximal-braking trajectory from the current state, so the QP is always feasible
and the plan brakes back toward the admissible set instead of failing.

Implementation and measurements
-------------------------------
The QP is built ONCE symbolically with CasADi (SX): a ``casadi.Function`` maps the parameter
vector (q0, dq0, u_prev, p0, J, references, q_nom) to the nonzeros of (H, g, A, bounds) with
a fixed sparsity.  Each solve evaluates that function and re-solves a solver instance
created once, warm-started.  Measured on the 2-core development machine (7 joints, N = 20,
581 variables, 427 equality rows, a 0.2 m/s moving target, ``python -m controllers.mpc_bench``;
medians / p99 in microseconds, whole ``solve()`` call including input checks and plan
post-processing):

    ===============================================  =========  ========
    backend                                          median us  p99 us
    ===============================================  =========  ========
    ``casadi.Opti('conic')`` re-built per call        ~40 000    (FACTS.md)
    ``casadi.conic('hpipm')`` (OCP structure)           SEE_BENCH
    ===============================================  =========  ========

The default solver is the fastest robust one of these (see :data:`SOLVERS`).

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
_NX = 3 * N_JOINTS  # state (q, dq, u_prev)
_NU = N_JOINTS  # control: joint accelerations

#: Solver back-ends understood by :class:`MPCConfig.solver`. ``"osqp_direct"`` drives OSQP 1.x
#: itself (set up once on the CasADi sparsity, then ``update()``); the others go through
#: ``casadi.conic`` with the named plugin.
SOLVERS: tuple[str, ...] = ("hpipm", "osqp_direct", "osqp", "fatrop", "piqp", "proxqp", "qrqp")


@dataclass(frozen=True)
class MPCConfig:
    """Settings of :class:`TaskSpaceMPC` (all fixed when the problem is built).

    Attributes:
        horizon_steps: number of steps N of the horizon.
        dt_s: step length, s (horizon = N * dt_s).
        rate_hz: rate at which the caller re-solves (informational; the plan is valid for its horizon).
        w_pos: weight of the TCP position error, 1/m^2.
        w_rot: weight of the TCP orientation error (rotation vector), 1/rad^2.
        w_posture: weight pulling q toward the nominal posture, 1/rad^2.
        w_vel: joint velocity damping weight, s^2/rad^2.
        w_acc: joint acceleration weight, s^4/rad^2.
        w_jerk: weight of the acceleration change between steps (including from the
            previously applied acceleration), s^4/rad^2.
        w_terminal_vel: weight of the terminal joint velocity, s^2/rad^2.
        q_margin_rad: the position limits are shrunk by this much on each side, rad.
        v_limit_scale: fraction of the velocity limits used by the plan.
        a_limit_scale: fraction of the acceleration limits used by the plan.
        solver: one of :data:`SOLVERS`.
        max_solve_ms: a solve slower than this counts as late and its result is discarded.
        solver_options: extra options passed to the solver (a tuple of (key, value) pairs so
            the config stays hashable).
    """

    horizon_steps: int = 20
    dt_s: float = 0.02
    rate_hz: float = 50.0
    w_pos: float = 1.0e4
    w_rot: float = 1.0e3
    w_posture: float = 1.0e-2
    w_vel: float = 1.0e-3
    w_acc: float = 1.0e-3
    w_jerk: float = 1.0e-3
    w_terminal_vel: float = 1.0e-1
    q_margin_rad: float = 0.05
    v_limit_scale: float = 0.95
    a_limit_scale: float = 0.95
    solver: str = "hpipm"
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
        if self.q_margin_rad < 0.0:
            raise ValueError("q_margin_rad must be >= 0")
        for name in ("w_pos", "w_rot", "w_posture", "w_vel", "w_acc", "w_jerk", "w_terminal_vel"):
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
        k = min(int(tau // self.dt_s), n - 1)
        s = tau - k * self.dt_s
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
    """Builds the parametric QP once with CasADi SX (fixed sparsity) in OCP order
    ``[x0 u0 x1 u1 ... x_N]`` with the constraints ``[gap0 gap1 ... gap_{N-1} lincon_N]``."""

    def __init__(self, cfg: MPCConfig, limits: JointLimits) -> None:
        n, dt, nj = cfg.horizon_steps, cfg.dt_s, N_JOINTS
        lim = limits.arrays()
        q_lo = lim["q_min_rad"] + cfg.q_margin_rad
        q_hi = lim["q_max_rad"] - cfg.q_margin_rad
        if np.any(q_lo >= q_hi):
            raise ValueError("q_margin_rad leaves no admissible joint range")
        v_max = cfg.v_limit_scale * lim["v_max_rad_s"]
        a_max = cfg.a_limit_scale * lim["a_max_rad_s2"]
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
        params = [q0, dq0, u_prev, jac, e_pos, r_ref, q_nom]
        self.param_sizes = [int(p.numel()) for p in params]
        p_all = ca.vertcat(*[ca.vec(p) for p in params])

        xs = [ca.SX.sym(f"x{k}", _NX) for k in range(n + 1)]
        us = [ca.SX.sym(f"u{k}", _NU) for k in range(n)]
        z_parts: list[ca.SX] = []
        for k in range(n):
            z_parts += [xs[k], us[k]]
        z_parts.append(xs[n])
        z = ca.vertcat(*z_parts)

        jl, ja = jac[0:3, :], jac[3:6, :]
        cost = 0
        gaps = []
        for k in range(n):
            qk, dqk, upk = xs[k][0:nj], xs[k][nj : 2 * nj], xs[k][2 * nj :]
            uk = us[k]
            x_next = ca.vertcat(qk + dt * dqk + 0.5 * dt * dt * uk, dqk + dt * uk, uk)
            gaps.append(x_next - xs[k + 1])
            cost += cfg.w_acc * ca.sumsqr(uk) + cfg.w_jerk * ca.sumsqr(uk - upk)
            q1, dq1 = xs[k + 1][0:nj], xs[k + 1][nj : 2 * nj]
            dqq = q1 - q0
            cost += cfg.w_pos * ca.sumsqr(jl @ dqq - e_pos[:, k])
            cost += cfg.w_rot * ca.sumsqr(ja @ dqq - r_ref[:, k])
            cost += cfg.w_posture * ca.sumsqr(q1 - q_nom) + cfg.w_vel * ca.sumsqr(dq1)
        qn, dqn = xs[n][0:nj], xs[n][nj : 2 * nj]
        cost += cfg.w_terminal_vel * ca.sumsqr(dqn)
        g_con = ca.vertcat(*gaps, qn + c_brake * dqn)
        self.n_eq = n * _NX
        self.n_con = int(g_con.numel())

        hess, grad = ca.hessian(cost, z)
        grad0 = ca.substitute(grad, z, ca.DM.zeros(z.numel()))
        a_mat = ca.jacobian(g_con, z)
        # sanity: the dynamics and constraint functions are linear homogeneous in z
        assert ca.depends_on(a_mat, z) is False and ca.depends_on(hess, z) is False

        # bounds (the feasibility guard: widen each bound to contain the braking trajectory)
        inf = np.inf
        qb, vb = [q0], [dq0]
        qk, vk = q0, dq0
        for _ in range(n):
            ak = -ca.sign(vk) * ca.fmin(a_max, ca.fabs(vk) / dt)
            qk = qk + dt * vk + 0.5 * dt * dt * ak
            vk = vk + dt * ak
            qb.append(qk)
            vb.append(vk)
        eps = 1e-9
        lbx_parts, ubx_parts = [], []
        for k in range(n + 1):
            if k == 0:
                lbx_parts.append(ca.vertcat(q0, dq0, u_prev))
                ubx_parts.append(ca.vertcat(q0, dq0, u_prev))
            else:
                lbx_parts.append(ca.vertcat(ca.fmin(q_lo, qb[k] - eps), ca.fmin(-v_max, vb[k] - eps), -inf * np.ones(nj)))
                ubx_parts.append(ca.vertcat(ca.fmax(q_hi, qb[k] + eps), ca.fmax(v_max, vb[k] + eps), inf * np.ones(nj)))
            if k < n:
                lbx_parts.append(ca.DM(-a_max))
                ubx_parts.append(ca.DM(a_max))
        lbx = ca.vertcat(*lbx_parts)
        ubx = ca.vertcat(*ubx_parts)
        term_b = qb[n] + c_brake * vb[n]
        lba = ca.vertcat(ca.DM.zeros(self.n_eq), ca.fmin(q_lo, term_b - eps))
        uba = ca.vertcat(ca.DM.zeros(self.n_eq), ca.fmax(q_hi, term_b + eps))

        self.nz = int(z.numel())
        self.h_sp = hess.sparsity()
        self.a_sp = a_mat.sparsity()
        hess_triu = ca.triu(hess)
        self.h_triu_sp = hess_triu.sparsity()
        # dense-vector outputs of the nonzeros: cheap to convert to numpy
        self.qp_fun = ca.Function(
            "mpc_qp",
            [p_all],
            [hess, grad0, a_mat, lba, uba, lbx, ubx],
            ["p"],
            ["h", "g", "a", "lba", "uba", "lbx", "ubx"],
        )
        self.qp_nz_fun = ca.Function(
            "mpc_qp_nz",
            [p_all],
            [ca.vertcat(*hess_triu.nonzeros()), grad0, ca.vertcat(*a_mat.nonzeros()), lba, uba, lbx, ubx],
        )
        self.n_params = int(p_all.numel())

    def pack(self, q0, dq0, u_prev, jac, e_pos, r_ref, q_nom) -> np.ndarray:
        """Parameter vector (column-major for the matrices, as ``ca.vec``)."""
        return np.concatenate(
            [q0, dq0, u_prev, jac.ravel(order="F"), e_pos.ravel(), r_ref.ravel(), q_nom]
        )


class _ConicBackend:
    """``casadi.conic`` with a given plugin, created once on the fixed sparsity."""

    def __init__(self, qp: _QPBuilder, plugin: str, options: dict[str, Any]) -> None:
        opts: dict[str, Any] = {"error_on_fail": False, "verbose": False}
        n = qp.n
        if plugin in ("hpipm", "fatrop"):
            opts.update(N=n, nx=[_NX] * (n + 1), nu=[_NU] * n + [0], ng=[0] * n + [N_JOINTS])
            if plugin == "fatrop":
                opts["structure_detection"] = "manual"
        if plugin == "hpipm":
            opts["hpipm"] = {"warm_start": False, "iter_max": 50, "mode": "speed"}
        elif plugin == "osqp":
            opts["osqp"] = {"verbose": False, "eps_abs": 1e-5, "eps_rel": 1e-5, "polishing": True,
                            "max_iter": 4000}
            opts["warm_start_primal"] = True
            opts["warm_start_dual"] = True
        elif plugin == "fatrop":
            opts["fatrop"] = {"print_level": 0}
        elif plugin == "qrqp":
            opts["print_iter"] = False
            opts["print_header"] = False
            opts["print_info"] = False
        elif plugin in ("piqp", "proxqp"):
            pass
        opts.update(options)
        self.solver = ca.conic("mpc_" + plugin, plugin, {"h": qp.h_sp, "a": qp.a_sp}, opts)
        self.fun = qp.qp_fun
        self.x_prev: np.ndarray | None = None
        self.lam_x: np.ndarray | None = None
        self.lam_a: np.ndarray | None = None

    def solve(self, p: np.ndarray) -> tuple[np.ndarray, bool]:
        h, g, a, lba, uba, lbx, ubx = self.fun(p)
        args = dict(h=h, g=g, a=a, lba=lba, uba=uba, lbx=lbx, ubx=ubx)
        if self.x_prev is not None:
            args.update(x0=self.x_prev, lam_x0=self.lam_x, lam_a0=self.lam_a)
        res = self.solver(**args)
        ok = bool(self.solver.stats().get("success", False))
        x = np.asarray(res["x"]).ravel()
        if ok and np.all(np.isfinite(x)):
            self.x_prev, self.lam_x, self.lam_a = res["x"], res["lam_x"], res["lam_a"]
        return x, ok


class _OSQPBackend:
    """OSQP 1.x driven directly: set up once on the CasADi sparsity ([A; I] for the bounds),
    then ``update()`` the values and re-solve warm-started."""

    def __init__(self, qp: _QPBuilder, options: dict[str, Any]) -> None:
        import osqp  # local: only this backend needs it
        import scipy.sparse as sp

        self.fun = qp.qp_nz_fun
        nz = qp.nz
        p0 = np.zeros(qp.n_params)
        hx, g, ax, lba, uba, lbx, ubx = (np.asarray(v).ravel() for v in self.fun(p0))
        hs, as_ = qp.h_triu_sp, qp.a_sp
        self._P = sp.csc_matrix((hx + 0.0, np.asarray(hs.row()), np.asarray(hs.colind())), shape=(nz, nz))
        # [A; I] assembled by hand so that the position of every value in the CSC data is known
        a_ptr = np.asarray(as_.colind())
        a_row = np.asarray(as_.row())
        cols = np.repeat(np.arange(nz), np.diff(a_ptr))
        self._a_pos = np.arange(a_row.size) + cols  # CasADi nonzero i of column j -> i + j
        indptr = a_ptr + np.arange(nz + 1)
        indices = np.empty(a_row.size + nz, dtype=np.int64)
        indices[self._a_pos] = a_row
        eye_pos = a_ptr[1:] + np.arange(nz)
        indices[eye_pos] = qp.n_con + np.arange(nz)
        self._a_data = np.ones(a_row.size + nz)
        self._a_data[self._a_pos] = ax
        a_full = sp.csc_matrix((self._a_data.copy(), indices, indptr), shape=(qp.n_con + nz, nz))
        settings = dict(verbose=False, warm_starting=True, polishing=True, eps_abs=1e-5, eps_rel=1e-5,
                        max_iter=4000, adaptive_rho=True, check_termination=10)
        settings.update(options)
        self.solver = osqp.OSQP()
        l = np.concatenate([lba, lbx])
        u = np.concatenate([uba, ubx])
        self.solver.setup(P=self._P, q=g, A=a_full, l=np.maximum(l, -1e30), u=np.minimum(u, 1e30), **settings)

    def solve(self, p: np.ndarray) -> tuple[np.ndarray, bool]:
        hx, g, ax, lba, uba, lbx, ubx = (np.asarray(v).ravel() for v in self.fun(p))
        a_full = self._a_data
        a_full[self._a_pos] = ax
        l = np.maximum(np.concatenate([lba, lbx]), -1e30)
        u = np.minimum(np.concatenate([uba, ubx]), 1e30)
        self.solver.update(Px=hx, q=g, Ax=a_full, l=l, u=u)
        res = self.solver.solve()
        status = res.info.status_val
        ok = status in (1, 2)  # solved, solved inaccurate
        return np.asarray(res.x, dtype=float), ok


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
        opts = dict(config.solver_options)
        if config.solver == "osqp_direct":
            self._backend: _ConicBackend | _OSQPBackend = _OSQPBackend(self._qp, opts)
        else:
            self._backend = _ConicBackend(self._qp, config.solver, opts)
        n = config.horizon_steps
        stride = _NX + _NU
        self._u_idx = (np.arange(n)[:, None] * stride + _NX + np.arange(_NU)[None, :]).ravel()
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
        params = np.concatenate([q0, dq0, u_prev, jac.ravel(order="F"), (pos_ref - p0).ravel(), rot_ref.ravel(),
                                 self.q_nominal_rad])
        try:
            z, ok = self._backend.solve(params)
        except Exception:  # noqa: BLE001 - any solver error means: fall back
            z, ok = np.full(self._qp.nz, np.nan), False
        u = z[self._u_idx].reshape(n, _NU) if z.size == self._qp.nz else np.full((n, _NU), np.nan)
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
