"""The MPC's joint model: the exact double-integrator rollout (compiled: it runs after every MPC solve) and maximal
braking."""

from __future__ import annotations

import numpy as np
from numba import njit


def rollout(q0: np.ndarray, dq0: np.ndarray, ddq: np.ndarray, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact double-integrator rollout of piecewise-constant accelerations.

    Args:
        q0, dq0: start positions (rad) and velocities (rad/s), (7,).
        ddq: accelerations over each interval, rad/s^2, (N, 7).
        dt_s: interval length, s.

    Returns:
        Positions (rad) and velocities (rad/s) at the N+1 knots, each (N+1, 7).
    """
    ddq = np.ascontiguousarray(ddq, dtype=np.float64)
    n, nj = ddq.shape[0], np.size(q0)
    q = np.empty((n + 1, nj))
    dq = np.empty((n + 1, nj))
    _rollout(np.ascontiguousarray(q0, dtype=np.float64).reshape(nj), np.ascontiguousarray(dq0, dtype=np.float64).reshape(nj),
             ddq.reshape(n, nj), float(dt_s), q, dq)
    return q, dq


@njit(cache=True, nogil=True)
def _rollout(q0, dq0, ddq, dt_s, q, dq):
    """:func:`rollout` into ``q``, ``dq`` (N+1, 7), each knot from the last as numpy would compute it row by row:
    ``dq[k+1] = dq[k] + dt ddq[k]``, ``q[k+1] = q[k] + dt dq[k] + (0.5 dt dt) ddq[k]`` (bit for bit: no fused
    multiply-add)."""
    half_dt2 = 0.5 * dt_s * dt_s
    for i in range(q0.shape[0]):
        q[0, i] = q0[i]
        dq[0, i] = dq0[i]
    for k in range(ddq.shape[0]):
        for i in range(q0.shape[0]):
            dq[k + 1, i] = dq[k, i] + dt_s * ddq[k, i]
            q[k + 1, i] = q[k, i] + dt_s * dq[k, i] + half_dt2 * ddq[k, i]


def braking_accelerations(dq0_rad_s: np.ndarray, a_max_rad_s2: np.ndarray, n_steps: int, dt_s: float) -> np.ndarray:
    """Per-joint accelerations (n_steps, 7), rad/s^2, that bring ``dq0`` to rest as fast as ``a_max`` allows."""
    out = np.zeros((n_steps, dq0_rad_s.size))
    v = np.asarray(dq0_rad_s, dtype=float).copy()
    for k in range(n_steps):
        a = -np.sign(v) * np.minimum(a_max_rad_s2, np.abs(v) / dt_s)
        out[k] = a
        v = v + dt_s * a
    return out
