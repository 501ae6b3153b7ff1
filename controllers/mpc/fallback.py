"""The plan the MPC returns when a solve fails or is late: the previous plan re-timed, or braking to rest."""

from __future__ import annotations

import time

import numpy as np

from controllers.mpc.config import N_JOINTS
from controllers.mpc.double_integrator import braking_accelerations, rollout
from controllers.mpc.plan import MPCPlan

#: Knot-time tolerance, s (a knot this close to the end of the previous plan counts as past it).
_KNOT_TOL_S = 1e-9


def _retimed_accelerations(prev: MPCPlan, t_s: float, q_rad: np.ndarray, dq_rad_s: np.ndarray,
                           a_max_rad_s2: np.ndarray, n: int, dt_s: float) -> np.ndarray:
    """(n, 7) accelerations, rad/s^2: ``prev``'s from ``t_s`` on while it lasts, then maximal braking from where it
    leaves the arm (``q_rad``, ``dq_rad_s``: ``prev`` at ``t_s``)."""
    u = np.zeros((n, N_JOINTS))
    k_in = 0
    for k in range(n):
        tk = t_s + k * dt_s
        if tk >= prev.t_end_s - _KNOT_TOL_S:
            break
        u[k] = prev.sample(tk + _KNOT_TOL_S)[2]
        k_in = k + 1
    if k_in < n:
        _, dq_mid = rollout(q_rad, dq_rad_s, u[:k_in], dt_s)
        u[k_in:] = braking_accelerations(dq_mid[-1], a_max_rad_s2, n - k_in, dt_s)
    return u


def fallback_plan(prev: MPCPlan | None, t_s: float, q0: np.ndarray, dq0: np.ndarray, p0: np.ndarray,
                  jac: np.ndarray, a_max_rad_s2: np.ndarray, n: int, dt_s: float, t_start: float) -> MPCPlan:
    """Previous plan re-timed to start at ``t_s`` (braking to rest after its end), or, with no previous plan
    covering ``t_s``, a plan braking to rest from the current state (``q0`` rad, ``dq0`` rad/s, TCP at ``p0`` m,
    6x7 Jacobian ``jac``).  ``ok`` is False; ``solve_us`` counts from ``t_start`` (``time.perf_counter()``, s)."""
    if prev is not None and prev.t0_s <= t_s < prev.t_end_s:
        qs, dqs, _ = prev.sample(t_s)
        u = _retimed_accelerations(prev, t_s, qs, dqs, a_max_rad_s2, n, dt_s)
        u = np.clip(u, -a_max_rad_s2, a_max_rad_s2)
        q, dq = rollout(qs, dqs, u, dt_s)
        jl = prev.ee_jacobian_lin
        ee = prev.ee_pos_m[0] + (q - prev.q_rad[0]) @ jl.T
    else:
        u = braking_accelerations(dq0, a_max_rad_s2, n, dt_s)
        q, dq = rollout(q0, dq0, u, dt_s)
        jl = jac[0:3].copy()
        ee = p0 + (q - q0) @ jl.T
    return MPCPlan(t_s, dt_s, q, dq, u, ee, False, (time.perf_counter() - t_start) * 1e6, jl)
