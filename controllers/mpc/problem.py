"""The MPC's parametric QP, built once symbolically with CasADi SX (fixed sparsity).

Decision vector ``z = [u_0, q_1, dq_1, u_1, q_2, dq_2, ..., u_{N-1}, q_N, dq_N]`` (the current state is a
parameter, not a variable); constraints ``[dynamics (2*7*N rows) = 0; terminal braking set (7 rows)]`` plus
simple bounds on every variable.  The parameter vector is, column-major, ``(q0, dq0, u_prev, J (6x7),
e_pos (3xN), r_ref (3xN), q_nom, N (7x7))``: see :class:`QPBuilder`.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from controllers.mpc.config import N_JOINTS, MPCConfig
from controllers.robot_description import JointLimits

#: How far the feasibility guard widens a bound past the braking trajectory (rad, rad/s).
_GUARD_EPS = 1e-9


@dataclass(frozen=True)
class JointBox:
    """The per-joint box the plan keeps at the knots, each (7,).

    Attributes:
        q_lo_rad, q_hi_rad: position bounds, rad: the limits shrunk by ``q_margin_rad`` and by the at most
            ``a_max dt^2 / 8`` a constant-acceleration interval can carry q past its knots.
        v_max_rad_s: velocity bound, rad/s (``v_limit_scale`` times the limits).
        a_max_rad_s2: acceleration bound, rad/s^2 (``a_limit_scale`` times the limits).
    """

    q_lo_rad: np.ndarray
    q_hi_rad: np.ndarray
    v_max_rad_s: np.ndarray
    a_max_rad_s2: np.ndarray


def joint_box(cfg: MPCConfig, limits: JointLimits) -> JointBox:
    """The knot bounds of the plan for ``cfg`` and ``limits``; ValueError when the margin leaves no range."""
    dt = cfg.dt_s
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
    return JointBox(q_lo, q_hi, v_max, a_max)


@dataclass(frozen=True)
class _Params:
    """The symbolic parameters of the QP (SX), in the order of the parameter vector."""

    q0: ca.SX  # joint positions now, rad (7)
    dq0: ca.SX  # joint velocities now, rad/s (7)
    u_prev: ca.SX  # acceleration the previous plan commands now, rad/s^2 (7)
    jac: ca.SX  # 6x7 LOCAL_WORLD_ALIGNED; p0 cancels out of the QP
    e_pos: ca.SX  # pos_ref[k] - p0, m (3xN)
    r_ref: ca.SX  # rotvec reference relative to the current orientation, rad (3xN)
    q_nom: ca.SX  # nominal posture, rad (7)
    null: ca.SX  # projector onto the task's (damped) null space at q0, symmetric (7x7)

    @staticmethod
    def symbols(n: int) -> _Params:
        nj = N_JOINTS
        return _Params(ca.SX.sym("q0", nj), ca.SX.sym("dq0", nj), ca.SX.sym("u_prev", nj), ca.SX.sym("jac", 6, nj),
                       ca.SX.sym("e_pos", 3, n), ca.SX.sym("r_ref", 3, n), ca.SX.sym("q_nom", nj),
                       ca.SX.sym("null", nj, nj))

    def vector(self) -> ca.SX:
        parts = [self.q0, self.dq0, self.u_prev, self.jac, self.e_pos, self.r_ref, self.q_nom, self.null]
        return ca.vertcat(*[ca.vec(p) for p in parts])


def _decision_symbols(n: int) -> tuple[list[ca.SX], list[ca.SX], list[ca.SX], ca.SX]:
    """``(us, qs, dqs, z)``: per-step accelerations u_k, knots q_{k+1}, dq_{k+1} and their stacking z."""
    nj = N_JOINTS
    us = [ca.SX.sym(f"u{k}", nj) for k in range(n)]
    qs = [ca.SX.sym(f"q{k + 1}", nj) for k in range(n)]
    dqs = [ca.SX.sym(f"dq{k + 1}", nj) for k in range(n)]
    z = ca.vertcat(*[ca.vertcat(us[k], qs[k], dqs[k]) for k in range(n)])
    return us, qs, dqs, z


def _cost_and_gaps(cfg: MPCConfig, par: _Params, us: list[ca.SX], qs: list[ca.SX],
                   dqs: list[ca.SX]) -> tuple[ca.SX, list[ca.SX]]:
    """The quadratic cost (module doc of :mod:`controllers.mpc`) and the dynamics gaps (zero when consistent)."""
    dt = cfg.dt_s
    jl, ja = par.jac[0:3, :], par.jac[3:6, :]
    cost = 0
    gaps = []
    q_prev, dq_prev, u_before = par.q0, par.dq0, par.u_prev
    for k in range(cfg.horizon_steps):
        uk, q1, dq1 = us[k], qs[k], dqs[k]
        gaps.append(q_prev + dt * dq_prev + 0.5 * dt * dt * uk - q1)
        gaps.append(dq_prev + dt * uk - dq1)
        cost += cfg.w_acc * ca.sumsqr(uk) + cfg.w_jerk * ca.sumsqr(uk - u_before)
        dqq = q1 - par.q0
        e = jl @ dqq - par.e_pos[:, k]
        if cfg.w_pos_z_scale == 1.0:  # the published problem, expression for expression
            cost += cfg.w_pos * ca.sumsqr(e)
        else:
            cost += cfg.w_pos * (ca.sumsqr(e[0:2]) + cfg.w_pos_z_scale * e[2] * e[2])
        cost += cfg.w_rot * ca.sumsqr(ja @ dqq - par.r_ref[:, k])
        cost += cfg.w_posture * ca.sumsqr(q1 - par.q_nom) + cfg.w_vel * ca.sumsqr(dq1)
        if cfg.w_null_posture > 0.0:
            dn = q1 - par.q_nom
            cost += cfg.w_null_posture * ca.dot(dn, par.null @ dn)
        q_prev, dq_prev, u_before = q1, dq1, uk
    cost += cfg.w_terminal_vel * ca.sumsqr(dqs[-1])
    return cost, gaps


def _braking_knots(par: _Params, a_max: np.ndarray, dt_s: float, n: int) -> tuple[list[ca.SX], list[ca.SX]]:
    """Knots (q rad, dq rad/s) of the maximal-braking trajectory from the current state (feasibility guard)."""
    qk, vk = par.q0, par.dq0
    qb, vb = [], []
    for _ in range(n):
        ak = -ca.sign(vk) * ca.fmin(a_max, ca.fabs(vk) / dt_s)
        qk = qk + dt_s * vk + 0.5 * dt_s * dt_s * ak
        vk = vk + dt_s * ak
        qb.append(qk)
        vb.append(vk)
    return qb, vb


def _guarded_bounds(box: JointBox, c_brake: np.ndarray, qb: list[ca.SX], vb: list[ca.SX], b_con: ca.SX,
                    n: int) -> tuple[ca.SX, ca.SX, ca.SX, ca.SX]:
    """``(lbx, ubx, lba, uba)``: the box and the terminal braking set, widened to contain the braking knots."""
    q_lo, q_hi, v_max, a_max = box.q_lo_rad, box.q_hi_rad, box.v_max_rad_s, box.a_max_rad_s2
    eps = _GUARD_EPS
    lbx = ca.vertcat(*[ca.vertcat(-a_max, ca.fmin(q_lo, qb[k] - eps), ca.fmin(-v_max, vb[k] - eps)) for k in range(n)])
    ubx = ca.vertcat(*[ca.vertcat(a_max, ca.fmax(q_hi, qb[k] + eps), ca.fmax(v_max, vb[k] + eps)) for k in range(n)])
    term_b = qb[-1] + c_brake * vb[-1]
    n_dyn = 2 * N_JOINTS * n
    lba = b_con + ca.vertcat(ca.DM.zeros(n_dyn), ca.fmin(q_lo, term_b - eps))
    uba = b_con + ca.vertcat(ca.DM.zeros(n_dyn), ca.fmax(q_hi, term_b + eps))
    return lbx, ubx, lba, uba


class QPBuilder:
    """Builds the parametric QP once with CasADi SX (fixed sparsity).

    ``eval_fun`` maps the parameter vector to one dense vector holding, in this order, the nonzeros of
    ``triu(H)`` (CSC order), ``g``, the nonzeros of ``A`` (CSC order), ``lba``, ``uba``, ``lbx``, ``ubx``
    (their lengths: ``part_sizes``); it is evaluated through ``Function.buffer()`` straight into numpy
    memory (converting CasADi DMs to numpy costs ~0.3 ms per call here, the SX evaluation itself ~30 us
    after common-subexpression elimination).  ``qp_fun`` gives the same data as sparse matrices (for
    ``casadi.conic``).

    Attributes:
        a_max: the plan's acceleration bound, rad/s^2, (7,).
        n: horizon steps N.
        n_params, nz, n_con: lengths of the parameter vector, the decision vector and the constraint rows.
        u_idx: indices of the accelerations u_0..u_{N-1} in z (N*7,).
        h_sp, h_triu_sp, a_sp: sparsity of H, triu(H) and A.
    """

    def __init__(self, cfg: MPCConfig, limits: JointLimits) -> None:
        n, dt, nj = cfg.horizon_steps, cfg.dt_s, N_JOINTS
        box = joint_box(cfg, limits)
        self.a_max = box.a_max_rad_s2
        self.n = n
        c_brake = box.v_max_rad_s / box.a_max_rad_s2  # s: conservative terminal braking-set coefficient

        par = _Params.symbols(n)
        p_all = par.vector()
        self.n_params = int(p_all.numel())
        us, qs, dqs, z = _decision_symbols(n)
        stride = 3 * nj
        self.u_idx = (np.arange(n)[:, None] * stride + np.arange(nj)[None, :]).ravel()

        cost, gaps = _cost_and_gaps(cfg, par, us, qs, dqs)
        g_con = ca.vertcat(*gaps, qs[-1] + c_brake * dqs[-1])
        self.n_con = int(g_con.numel())
        self.nz = int(z.numel())

        hess, grad = ca.hessian(cost, z)
        zero = ca.DM.zeros(self.nz)
        grad0 = ca.substitute(grad, z, zero)
        a_mat = ca.jacobian(g_con, z)
        b_con = -ca.substitute(g_con, z, zero)  # g_con = A z - b
        assert not ca.depends_on(a_mat, z) and not ca.depends_on(hess, z)

        qb, vb = _braking_knots(par, box.a_max_rad_s2, dt, n)
        lbx, ubx, lba, uba = _guarded_bounds(box, c_brake, qb, vb, b_con, n)
        self._make_functions(p_all, hess, grad0, a_mat, (lba, uba, lbx, ubx))

    def _make_functions(self, p_all: ca.SX, hess: ca.SX, grad0: ca.SX, a_mat: ca.SX,
                        bounds: tuple[ca.SX, ca.SX, ca.SX, ca.SX]) -> None:
        """Sets the sparsities, ``qp_fun`` (sparse matrices) and ``eval_fun`` (one vector of nonzeros, after cse)."""
        lba, uba, lbx, ubx = bounds
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
