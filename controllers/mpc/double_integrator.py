"""The MPC's joint model in numpy: the exact double-integrator rollout and maximal braking."""

from __future__ import annotations

import numpy as np


def rollout(q0: np.ndarray, dq0: np.ndarray, ddq: np.ndarray, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact double-integrator rollout of piecewise-constant accelerations.

    Args:
        q0, dq0: start positions (rad) and velocities (rad/s), (7,).
        ddq: accelerations over each interval, rad/s^2, (N, 7).
        dt_s: interval length, s.

    Returns:
        Positions (rad) and velocities (rad/s) at the N+1 knots, each (N+1, 7).
    """
    n = ddq.shape[0]
    q = np.empty((n + 1, q0.size))
    dq = np.empty((n + 1, q0.size))
    q[0], dq[0] = q0, dq0
    for k in range(n):
        dq[k + 1] = dq[k] + dt_s * ddq[k]
        q[k + 1] = q[k] + dt_s * dq[k] + 0.5 * dt_s * dt_s * ddq[k]
    return q, dq


def braking_accelerations(dq0_rad_s: np.ndarray, a_max_rad_s2: np.ndarray, n_steps: int, dt_s: float) -> np.ndarray:
    """Per-joint accelerations (n_steps, 7), rad/s^2, that bring ``dq0`` to rest as fast as ``a_max`` allows."""
    out = np.zeros((n_steps, dq0_rad_s.size))
    v = np.asarray(dq0_rad_s, dtype=float).copy()
    for k in range(n_steps):
        a = -np.sign(v) * np.minimum(a_max_rad_s2, np.abs(v) / dt_s)
        out[k] = a
        v = v + dt_s * a
    return out
