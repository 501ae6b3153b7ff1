"""Compiled (numba) kernels of the 1 kHz path: the per-tick arithmetic between Pinocchio and OSQP.

Why: the C parts of one control tick are small (Pinocchio ~6 us, OSQP ~23 us), but assembling the QP
from them with numpy costs ~40 small-array calls of ~0.5-1 us each, more than the solvers themselves.
These kernels do the same arithmetic in one compiled call each (~1 us of dispatch). The numpy versions
stay the reference: ``TaskSpaceQP.problem``, ``JointAccelerationBounds.__call__``, ``MPCPlan.sample_task``
and ``pin.log3``; ``tests/test_fast_paths.py`` holds each kernel to its reference.

``cache=True`` keeps the compiled code next to this file (``__pycache__``), so only the first run of a
fresh install pays the compile (a few seconds).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from controllers.layout import packed_layout

# Layout of the ``params`` vector of :func:`assemble_qp` (filled by ``qp_params``); numba freezes the module-level
# ints below as constants.
QP_PARAMS, N_PARAMS = packed_layout(
    ("kp6", 6), ("kd6", 6), ("w6", 6), ("kp_post", 1), ("kd_post", 1), ("w_post", 1), ("p_diag", 1), ("q_hi", 7),
    ("q_lo", 7), ("v_max", 7), ("a_max", 7), ("tau_lim", 7), ("dt", 1), ("inv_h", 1), ("dtau", 1), ("ddq_step", 7),
    ("e_max", 1), ("v_tcp", 1), ("pos_direct", 1))
_KP6, _KD6, _W6, _KP_POST, _KD_POST, _W_POST, _P_DIAG = (QP_PARAMS[k] for k in (
    "kp6", "kd6", "w6", "kp_post", "kd_post", "w_post", "p_diag"))
_Q_HI, _Q_LO, _V_MAX, _A_MAX, _TAU_LIM = (QP_PARAMS[k] for k in ("q_hi", "q_lo", "v_max", "a_max", "tau_lim"))
_DT, _INV_H, _DTAU, _DDQ_STEP, _E_MAX, _V_TCP = (QP_PARAMS[k] for k in ("dt", "inv_h", "dtau", "ddq_step", "e_max", "v_tcp"))
_POS_DIRECT = QP_PARAMS["pos_direct"]


def qp_params(kp6, kd6, w6, kp_post, kd_post, w_post, p_diag, q_hi, q_lo, v_max, a_max, tau_lim, dt_s, brake_horizon_s,
              dtau_step_nm, ddq_step_rad_s2, pos_err_max_m, tcp_vel_cap_m_s=math.inf, pos_direct=False):
    """Pack the QP's constants into the flat vector :func:`assemble_qp` reads.

    ``dtau_step_nm``: the largest torque change per control step (rate limit x dt, with margin);
    ``ddq_step_rad_s2`` (7,): the largest change of the commanded joint acceleration per step (jerk limit x dt);
    ``pos_err_max_m``: the TCP position error the PD term sees is saturated at this length;
    ``tcp_vel_cap_m_s``: the TCP velocity the PD term steers toward is capped at this speed;
    ``pos_direct``: the position rows take the ``ref_acc`` argument of :func:`assemble_qp` as their desired
    acceleration as it is (no PD term): the impedance task's (:func:`impedance_acc`), weighed by ``w6[:3]``."""
    p = np.empty(N_PARAMS)
    p[_KP6:_KP6 + 6], p[_KD6:_KD6 + 6], p[_W6:_W6 + 6] = kp6, kd6, w6
    p[_KP_POST], p[_KD_POST], p[_W_POST], p[_P_DIAG] = kp_post, kd_post, w_post, p_diag
    p[_Q_HI:_Q_HI + 7], p[_Q_LO:_Q_LO + 7], p[_V_MAX:_V_MAX + 7] = q_hi, q_lo, v_max
    p[_A_MAX:_A_MAX + 7], p[_TAU_LIM:_TAU_LIM + 7] = a_max, tau_lim
    p[_DT], p[_INV_H], p[_DTAU] = dt_s, 1.0 / brake_horizon_s, dtau_step_nm
    p[_DDQ_STEP:_DDQ_STEP + 7] = ddq_step_rad_s2
    p[_E_MAX] = pos_err_max_m
    p[_V_TCP] = tcp_vel_cap_m_s
    p[_POS_DIRECT] = 1.0 if pos_direct else 0.0
    return p


@njit(cache=True, nogil=True)
def effective_jerk(M, ddq_step, dtau_step, dt_s, out):
    """How fast each joint's commanded acceleration can change, rad/s^3, into ``out`` (7,): the jerk limit's step,
    or half the torque-rate step divided by the joint's own inertia ``M_ii``, whichever is smaller (the half
    leaves room for the coupling through the off-diagonal inertia). On the Panda's shoulder the torque rate
    is the tighter one by far (about 200 vs 6750 rad/s^3)."""
    for i in range(ddq_step.shape[0]):
        out[i] = min(ddq_step[i], 0.5 * dtau_step / M[i, i]) / dt_s


@njit(cache=True, nogil=True)
def rate_box(tau_last, tau_lim, dtau_step, lo, hi):
    """Torque bounds of one step into ``lo``, ``hi`` (7,): within the effort limits and within ``dtau_step`` of the
    last torque the robot received. When the last torque lies outside the effort limits (it never should), the
    bound moves it back toward them as fast as the rate allows: the rate condition always wins."""
    for i in range(tau_last.shape[0]):
        a = max(-tau_lim[i], tau_last[i] - dtau_step)
        b = min(tau_lim[i], tau_last[i] + dtau_step)
        if a > b:
            a = b = tau_last[i] - dtau_step if tau_last[i] > 0.0 else tau_last[i] + dtau_step
        lo[i], hi[i] = a, b


@njit(cache=True, nogil=True)
def jerk_box(ddq_last, ddq_step, lb, ub):
    """Intersect the acceleration bounds ``lb``, ``ub`` (in place) with ``ddq_last +- ddq_step`` (the jerk limit).
    Where they do not overlap, the bound is the point of the jerk box nearest to them (the commanded acceleration
    moves toward what the position/velocity bounds ask for as fast as the jerk limit allows)."""
    for i in range(ddq_last.shape[0]):
        a = max(lb[i], ddq_last[i] - ddq_step[i])
        b = min(ub[i], ddq_last[i] + ddq_step[i])
        if a > b:
            a = b = ddq_last[i] - ddq_step[i] if ddq_last[i] - ddq_step[i] > ub[i] else ddq_last[i] + ddq_step[i]
        lb[i], ub[i] = a, b


@njit(cache=True, nogil=True)
def log3(R, out):
    """SO(3) logarithm: the rotation vector (rad) of rotation matrix ``R`` into ``out`` (3,).

    Same result as ``pinocchio.log3``: angle in [0, pi], the series form near 0 and the
    diagonal-based axis near pi (where ``(R - R^T)`` carries no information)."""
    tr = R[0, 0] + R[1, 1] + R[2, 2]
    c = 0.5 * (tr - 1.0)
    if c > 1.0:
        c = 1.0
    elif c < -1.0:
        c = -1.0
    theta = math.acos(c)
    wx = R[2, 1] - R[1, 2]
    wy = R[0, 2] - R[2, 0]
    wz = R[1, 0] - R[0, 1]
    if theta < 1e-4:
        k = 0.5 + theta * theta / 12.0  # theta / (2 sin theta), series
        out[0], out[1], out[2] = k * wx, k * wy, k * wz
    elif theta < math.pi - 1e-3:
        k = theta / (2.0 * math.sin(theta))
        out[0], out[1], out[2] = k * wx, k * wy, k * wz
    else:  # near pi: axis from the diagonal of (R + I) / 2 = a a^T (for theta = pi), sign from the skew part
        inv = 1.0 / (1.0 - c)
        ax = math.sqrt(max(0.0, (R[0, 0] - c) * inv))
        ay = math.sqrt(max(0.0, (R[1, 1] - c) * inv))
        az = math.sqrt(max(0.0, (R[2, 2] - c) * inv))
        if ax >= ay and ax >= az:
            if wx < 0.0:
                ax = -ax
            ay = math.copysign(ay, ax * (R[0, 1] + R[1, 0]))
            az = math.copysign(az, ax * (R[0, 2] + R[2, 0]))
        elif ay >= az:
            if wy < 0.0:
                ay = -ay
            ax = math.copysign(ax, ay * (R[0, 1] + R[1, 0]))
            az = math.copysign(az, ay * (R[1, 2] + R[2, 1]))
        else:
            if wz < 0.0:
                az = -az
            ax = math.copysign(ax, az * (R[0, 2] + R[2, 0]))
            ay = math.copysign(ay, az * (R[1, 2] + R[2, 1]))
        n = math.sqrt(ax * ax + ay * ay + az * az)
        out[0], out[1], out[2] = theta * ax / n, theta * ay / n, theta * az / n


@njit(cache=True, nogil=True)
def ramp_speed(a_max, j, d):
    """Largest speed from which a joint stops within distance ``d`` when its deceleration can only ramp up to
    ``a_max`` at jerk ``j`` (first the ramp time ``a_max / j`` at constant speed, then braking at ``a_max``):
    ``a (-T + sqrt(T^2 + 2 d / a))``, ``T = a_max / j``; ``sqrt(2 a_max d)`` for an unlimited jerk."""
    if d <= 0.0:
        return 0.0
    t_ramp = a_max / j if j < 1e15 else 0.0
    return a_max * (-t_ramp + math.sqrt(t_ramp * t_ramp + 2.0 * d / a_max))


@njit(cache=True, nogil=True)
def rise_accel(dv, j, dt_s):
    """Largest acceleration for the next step after which the velocity, still rising while the acceleration ramps
    down at jerk ``j``, gains at most ``dv`` > 0: the root of ``a dt + a^2 / (2 j) = dv``; ``dv / dt`` for an
    unlimited jerk (and for ``dv <= 0``, where the joint must slow down now)."""
    if dv <= 0.0 or j >= 1e15:
        return dv / dt_s
    return j * (-dt_s + math.sqrt(dt_s * dt_s + 2.0 * dv / j))


@njit(cache=True, nogil=True)
def accel_bounds(q, dq, q_hi, q_lo, v_max, a_max, dt_s, inv_h, j_eff, lb, ub):
    """Joint acceleration bounds of one control step into ``lb``, ``ub`` (7,); the arithmetic of
    ``JointAccelerationBounds.__call__`` (see there for the rules). ``j_eff`` (7,): how fast each joint's
    acceleration can change, rad/s^3 (>= 1e15: instantly)."""
    for i in range(q.shape[0]):
        qn = q[i] + dq[i] * dt_s
        d_hi = max(q_hi[i] - qn, 0.0)
        d_lo = max(qn - q_lo[i], 0.0)
        v_hi = min(v_max[i], ramp_speed(a_max[i], j_eff[i], d_hi), d_hi * inv_h)
        v_lo = -min(v_max[i], ramp_speed(a_max[i], j_eff[i], d_lo), d_lo * inv_h)
        u = min(a_max[i], rise_accel(v_hi - dq[i], j_eff[i], dt_s))
        lo = max(-a_max[i], -rise_accel(dq[i] - v_lo, j_eff[i], dt_s))
        if lo > u:  # outside the viable set: brake toward the nearest viable velocity
            v_near = min(max(dq[i], v_lo), v_hi)
            brake = min(max((v_near - dq[i]) / dt_s, -a_max[i]), a_max[i])
            lo, u = brake, brake
        lb[i], ub[i] = lo, u


@njit(cache=True, nogil=True)
def assemble_qp(M, h, J, dJv, pos, rot, vel, ref_pos, ref_vel, ref_acc, ref_rot, ref_w, ref_dw, q_post, q, dq,
                tau_last, ddq_last, params, P_x, g, A_x, lower, upper):
    """The task-space inverse-dynamics QP of one tick, written straight into OSQP's CSC value arrays.

    Same problem as ``TaskSpaceQP.problem`` (see there): ``P = J^T W J + p_diag I`` (upper triangle,
    column-major, 28 values), ``g``, ``A = [M; I]`` (column-major, 8 values per column) and the bounds
    ``[tau_lo - h, lb] <= A ddq <= [tau_hi - h, ub]`` (``tau_lo``, ``tau_hi``: :func:`rate_box` around
    ``tau_last``; ``lb``, ``ub``: :func:`accel_bounds` intersected with :func:`jerk_box` around ``ddq_last``).
    With the ``pos_direct`` parameter set, ``ref_acc`` is the position rows' desired acceleration itself (the
    impedance task's, ``--compliance``) and ``ref_pos``, ``ref_vel`` are not read."""
    n = 7
    # task-space error and desired acceleration
    R = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            R[i, j] = ref_rot[i, 0] * rot[j, 0] + ref_rot[i, 1] * rot[j, 1] + ref_rot[i, 2] * rot[j, 2]
    e_rot = np.empty(3)
    log3(R, e_rot)
    r = np.empty(6)  # dJv - a_des, weighted below
    # the position error is saturated at pos_err_max: a far reference is approached at a bounded speed
    en = math.sqrt((ref_pos[0] - pos[0]) ** 2 + (ref_pos[1] - pos[1]) ** 2 + (ref_pos[2] - pos[2]) ** 2)
    e_scale = params[_E_MAX] / en if en > params[_E_MAX] else 1.0
    # the TCP velocity the PD term steers toward, v_ref + kp/kd e, capped at _V_TCP (feed-forward scaled with it)
    vd = np.empty(3)
    for i in range(3):
        vd[i] = ref_vel[i] + params[_KP6 + i] / params[_KD6 + i] * (ref_pos[i] - pos[i]) * e_scale
    vn = math.sqrt(vd[0] * vd[0] + vd[1] * vd[1] + vd[2] * vd[2])
    v_scale = params[_V_TCP] / vn if vn > params[_V_TCP] else 1.0
    direct = params[_POS_DIRECT] > 0.0
    for i in range(3):
        if direct:
            r[i] = dJv[i] - ref_acc[i]
        else:
            e = (ref_pos[i] - pos[i]) * e_scale
            rv = vd[i] * v_scale - params[_KP6 + i] / params[_KD6 + i] * e if v_scale < 1.0 else ref_vel[i]
            v, a = rv - vel[i], ref_acc[i] * v_scale
            r[i] = dJv[i] - (a + params[_KP6 + i] * e + params[_KD6 + i] * v)
        e, v, a = e_rot[i], ref_w[i] - vel[3 + i], ref_dw[i]
        r[3 + i] = dJv[3 + i] - (a + params[_KP6 + 3 + i] * e + params[_KD6 + 3 + i] * v)
    # P = J^T W J + diag, g = (dJv - a_des)^T W J - w_post ddq_post
    k = 0
    for j in range(n):
        for i in range(j + 1):
            s = 0.0
            for t in range(6):
                s += J[t, i] * params[_W6 + t] * J[t, j]
            if i == j:
                s += params[_P_DIAG]
            P_x[k] = s
            k += 1
    kp, kd, wp = params[_KP_POST], params[_KD_POST], params[_W_POST]
    for j in range(n):
        s = 0.0
        for t in range(6):
            s += r[t] * params[_W6 + t] * J[t, j]
        g[j] = s - wp * (kp * (q_post[j] - q[j]) - kd * dq[j])
    # A = [M; I] column-major, bounds
    k = 0
    for j in range(n):
        for i in range(n):
            A_x[k] = M[i, j]
            k += 1
        A_x[k] = 1.0
        k += 1
    rate_box(tau_last, params[_TAU_LIM:_TAU_LIM + 7], params[_DTAU], lower[:n], upper[:n])
    for i in range(n):
        lower[i] -= h[i]
        upper[i] -= h[i]
    j_eff = np.empty(n)
    effective_jerk(M, params[_DDQ_STEP:_DDQ_STEP + 7], params[_DTAU], params[_DT], j_eff)
    accel_bounds(q, dq, params[_Q_HI:_Q_HI + 7], params[_Q_LO:_Q_LO + 7], params[_V_MAX:_V_MAX + 7],
                 params[_A_MAX:_A_MAX + 7], params[_DT], params[_INV_H], j_eff, lower[n:], upper[n:])
    jerk_box(ddq_last, params[_DDQ_STEP:_DDQ_STEP + 7], lower[n:], upper[n:])


@njit(cache=True, nogil=True)
def impedance_acc(M, J, pos, rot, vel, ref_pos, ref_vel, ref_acc, k3, d3, force_max, normal, out):
    """The impedance task's desired TCP acceleration (``ImpedanceTask.desired_acc``) into ``out`` (3,), m/s^2:
    ``Lambda^-1 sat(Lambda a_ref + R (K R'e + D R'e_dot))`` with ``Lambda^-1 = Jp M^-1 Jp'`` (``Jp`` the
    Jacobian's linear rows; ``M^-1 Jp'`` by Cholesky), ``K``, ``D`` (3,) per tool axis, ``sat`` scaling the force's
    magnitude down to ``force_max`` (N). With a measured contact ``normal`` (3,), unit, world frame (the direction the
    world pushes the TCP; zeros: none, or the magnitude is capped), ``sat`` caps only the force's component into the
    contact (``-f . normal``) at ``force_max`` (``ImpedanceTask.pressing_only``)."""
    n = M.shape[0]
    L = np.zeros((n, n))  # M = L L'
    for j in range(n):
        s = M[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        L[j, j] = math.sqrt(s)
        for i in range(j + 1, n):
            s = M[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / L[j, j]
    X = np.empty((n, 3))  # M^-1 Jp'
    for c in range(3):
        for i in range(n):  # forward: L y = Jp[c]
            s = J[c, i]
            for k in range(i):
                s -= L[i, k] * X[k, c]
            X[i, c] = s / L[i, i]
        for i in range(n - 1, -1, -1):  # back: L' x = y
            s = X[i, c]
            for k in range(i + 1, n):
                s -= L[k, i] * X[k, c]
            X[i, c] = s / L[i, i]
    li = np.empty((3, 3))  # Lambda^-1
    for a in range(3):
        for b in range(3):
            s = 0.0
            for k in range(n):
                s += J[a, k] * X[k, b]
            li[a, b] = s
    # Lambda a_ref = solve(Lambda^-1, a_ref): the adjugate of the symmetric positive 3 x 3
    c00 = li[1, 1] * li[2, 2] - li[1, 2] * li[2, 1]
    c01 = li[1, 2] * li[2, 0] - li[1, 0] * li[2, 2]
    c02 = li[1, 0] * li[2, 1] - li[1, 1] * li[2, 0]
    c10 = li[0, 2] * li[2, 1] - li[0, 1] * li[2, 2]
    c11 = li[0, 0] * li[2, 2] - li[0, 2] * li[2, 0]
    c12 = li[0, 1] * li[2, 0] - li[0, 0] * li[2, 1]
    c20 = li[0, 1] * li[1, 2] - li[0, 2] * li[1, 1]
    c21 = li[0, 2] * li[1, 0] - li[0, 0] * li[1, 2]
    c22 = li[0, 0] * li[1, 1] - li[0, 1] * li[1, 0]
    det = li[0, 0] * c00 + li[0, 1] * c01 + li[0, 2] * c02
    f = np.empty(3)
    f[0] = (c00 * ref_acc[0] + c10 * ref_acc[1] + c20 * ref_acc[2]) / det
    f[1] = (c01 * ref_acc[0] + c11 * ref_acc[1] + c21 * ref_acc[2]) / det
    f[2] = (c02 * ref_acc[0] + c12 * ref_acc[1] + c22 * ref_acc[2]) / det
    # the spring-damper in the tool frame, back to the world
    sd = np.empty(3)
    for a in range(3):
        e = 0.0
        ev = 0.0
        for b in range(3):
            e += rot[b, a] * (ref_pos[b] - pos[b])
            ev += rot[b, a] * (ref_vel[b] - vel[b])
        sd[a] = k3[a] * e + d3[a] * ev
    for a in range(3):
        f[a] += rot[a, 0] * sd[0] + rot[a, 1] * sd[1] + rot[a, 2] * sd[2]
    if normal[0] != 0.0 or normal[1] != 0.0 or normal[2] != 0.0:  # only the push into the contact is capped
        press = -(f[0] * normal[0] + f[1] * normal[1] + f[2] * normal[2])
        if press > force_max:
            for a in range(3):
                f[a] += (press - force_max) * normal[a]
        scale = 1.0
    else:
        norm = math.sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2])
        scale = force_max / norm if norm > force_max else 1.0
    for a in range(3):
        out[a] = (li[a, 0] * f[0] + li[a, 1] * f[1] + li[a, 2] * f[2]) * scale


@njit(cache=True, nogil=True)
def torque(M, h, ddq, out):
    """``out = M ddq + h``; returns whether ``ddq`` and ``out`` are all finite."""
    ok = True
    for j in range(ddq.shape[0]):
        ok = ok and math.isfinite(ddq[j])
    for i in range(M.shape[0]):
        s = h[i]
        for j in range(M.shape[1]):
            s += M[i, j] * ddq[j]
        out[i] = s
        ok = ok and math.isfinite(s)
    return ok


@njit(cache=True, nogil=True)
def clamp_rate(tau, tau_last, dtau_hard):
    """Clamp ``tau`` (in place) to ``tau_last +- dtau_hard``: the last guard against a solver's tolerance.
    Returns the largest correction it made, N m (0.0: the command was already inside)."""
    worst = 0.0
    for i in range(tau.shape[0]):
        lo, hi = tau_last[i] - dtau_hard, tau_last[i] + dtau_hard
        if tau[i] > hi:
            worst = max(worst, tau[i] - hi)
            tau[i] = hi
        elif tau[i] < lo:
            worst = max(worst, lo - tau[i])
            tau[i] = lo
    return worst


@njit(cache=True, nogil=True)
def sample_plan_task(t_s, t0_s, dt_s, q_knots, dq_knots, ddq, ee_pos0, jl, q_out, task_out):
    """``MPCPlan.sample`` + ``sample_task`` in one call: the joint reference ``q(t)`` into ``q_out`` (7,)
    and the linearized TCP (pos, vel, acc) into the rows of ``task_out`` (3, 3)."""
    n = ddq.shape[0]
    nj = q_knots.shape[1]
    tau = t_s - t0_s
    dq_t = np.zeros(nj)
    dd_t = np.zeros(nj)
    if tau >= n * dt_s:
        for i in range(nj):
            q_out[i] = q_knots[n, i]
    else:
        if tau < 0.0:
            tau = 0.0
        k = min(int(math.floor(tau / dt_s + 1e-9)), n - 1)
        s = max(tau - k * dt_s, 0.0)
        for i in range(nj):
            a = ddq[k, i]
            q_out[i] = q_knots[k, i] + dq_knots[k, i] * s + 0.5 * a * s * s
            dq_t[i] = dq_knots[k, i] + a * s
            dd_t[i] = a
    for r in range(3):
        p, v, a = ee_pos0[r], 0.0, 0.0
        for i in range(nj):
            p += jl[r, i] * (q_out[i] - q_knots[0, i])
            v += jl[r, i] * dq_t[i]
            a += jl[r, i] * dd_t[i]
        task_out[0, r], task_out[1, r], task_out[2, r] = p, v, a


@njit(cache=True, nogil=True)
def sample_plan_blend(t_s, t0_s, dt_s, q_knots, dq_knots, ddq, ee_pos0, jl, old_t0_s, old_dt_s, old_q_knots,
                      old_dq_knots, old_ddq, old_ee_pos0, old_jl, blend_from_s, blend_s, q_out, task_out):
    """The hand-over of ``PlanTracker._sample`` in one call: the new plan and the old one sampled at ``t_s``
    (:func:`sample_plan_task`), the old blended into the new with the smoothstep of ``(t_s - blend_from_s) /
    blend_s`` (``blend_from_s``: when the new plan was taken, its ``t0_s`` when solved inline):
    ``out = old + w (new - old)``, into ``q_out`` (7,) and ``task_out`` (3, 3)."""
    sample_plan_task(t_s, t0_s, dt_s, q_knots, dq_knots, ddq, ee_pos0, jl, q_out, task_out)
    q_old = np.empty(q_out.shape[0])
    task_old = np.empty((3, 3))
    sample_plan_task(t_s, old_t0_s, old_dt_s, old_q_knots, old_dq_knots, old_ddq, old_ee_pos0, old_jl, q_old, task_old)
    x = (t_s - blend_from_s) / blend_s
    w = x * x * (3.0 - 2.0 * x)
    for r in range(3):
        for c in range(3):
            task_out[r, c] = task_old[r, c] + w * (task_out[r, c] - task_old[r, c])
    for i in range(q_out.shape[0]):
        q_out[i] = q_old[i] + w * (q_out[i] - q_old[i])


@njit(cache=True, nogil=True)
def absorb_jump(offset, offset_vel, offset_acc, ref, ref_vel, prev_ref, prev_vel, dt_s, pass_pos, pass_vel,
                new_offset, new_offset_vel):
    """Relative Ruckig smoothing (``controllers.smoother``): the offset after absorbing this step's jump of
    the reference into ``new_offset``, ``new_offset_vel`` (3,); returns whether any offset is left to smooth
    (position > 1e-9 m, velocity > 1e-7, acceleration > 1e-5).

    The jump is what the constant-velocity prediction ``prev_ref + prev_vel dt``, ``prev_vel`` did not predict.
    Up to ``pass_pos`` (position, norm) and ``pass_vel`` (velocity, norm) of it passes through (a reference that
    accelerates within the limits does that much in one step); only the excess is absorbed (0, 0: all of it)."""
    jp0 = ref[0] - prev_ref[0] - prev_vel[0] * dt_s
    jp1 = ref[1] - prev_ref[1] - prev_vel[1] * dt_s
    jp2 = ref[2] - prev_ref[2] - prev_vel[2] * dt_s
    jv0 = ref_vel[0] - prev_vel[0]
    jv1 = ref_vel[1] - prev_vel[1]
    jv2 = ref_vel[2] - prev_vel[2]
    np_ = np.sqrt(jp0 * jp0 + jp1 * jp1 + jp2 * jp2)
    nv = np.sqrt(jv0 * jv0 + jv1 * jv1 + jv2 * jv2)
    kp = 0.0 if np_ <= pass_pos else 1.0 - pass_pos / np_  # the absorbed fraction
    kv = 0.0 if nv <= pass_vel else 1.0 - pass_vel / nv
    new_offset[0] = offset[0] - kp * jp0
    new_offset[1] = offset[1] - kp * jp1
    new_offset[2] = offset[2] - kp * jp2
    new_offset_vel[0] = offset_vel[0] - kv * jv0
    new_offset_vel[1] = offset_vel[1] - kv * jv1
    new_offset_vel[2] = offset_vel[2] - kv * jv2
    active = False
    for i in range(3):
        if abs(new_offset[i]) > 1e-9 or abs(new_offset_vel[i]) > 1e-7 or abs(offset_acc[i]) > 1e-5:
            active = True
    return active
