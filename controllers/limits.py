"""Joint limits as acceleration bounds for one control step (a mink-style limit: a constraint builder)."""

from __future__ import annotations

import numpy as np

from controllers.robot_description import JointLimits


class JointAccelerationBounds:
    """Turns joint position, velocity and acceleration limits into ``lb <= ddq <= ub`` (rad/s^2).

    - acceleration: ``|ddq| <= a_max * a_margin``;
    - velocity after one step: ``|dq + ddq dt| <= v_max * v_margin``;
    - position viability: the velocity after one step must still allow braking to rest at
      ``a_max`` before the (margined) position limit, ``dq_next <= sqrt(2 a_max d)``, and may not
      reach the limit within ``brake_horizon_s`` at constant speed (``dq_next <= d / brake_horizon_s``),
      ``d`` being the distance to the limit left after the step.

    When the bounds cross (a state already outside the viable set) the velocity/position bound
    wins: the joint decelerates toward the nearest viable velocity as hard as ``a_max`` allows.
    Constants are precomputed; ``__call__`` is the 1 kHz path.
    """

    def __init__(
        self,
        limits: JointLimits,
        dt_s: float,
        brake_horizon_s: float = 0.05,
        q_margin_rad: float = 0.05,
        v_margin: float = 0.95,
        a_margin: float = 1.0,
    ) -> None:
        if not dt_s > 0 or not brake_horizon_s > 0:
            raise ValueError(f"dt_s and brake_horizon_s must be > 0, got {dt_s}, {brake_horizon_s}")
        lim = limits.arrays()
        self.q_hi = lim["q_max_rad"] - q_margin_rad
        self.q_lo = lim["q_min_rad"] + q_margin_rad
        if np.any(self.q_hi <= self.q_lo):
            raise ValueError(f"q_margin_rad={q_margin_rad} leaves no room between the joint limits")
        self.v_max = lim["v_max_rad_s"] * v_margin
        if not 0 < a_margin <= 1:
            raise ValueError(f"a_margin must be in (0, 1], got {a_margin}")
        self.a_max = lim["a_max_rad_s2"] * a_margin
        self.two_a = 2.0 * self.a_max
        self.dt_s = dt_s
        self.inv_dt = 1.0 / dt_s
        self.inv_h = 1.0 / brake_horizon_s

    def __call__(self, q_rad: np.ndarray, dq_rad_s: np.ndarray,
                 j_eff_rad_s3: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Bounds ``(lb, ub)`` (7,) rad/s^2. ``j_eff_rad_s3`` (7,): how fast each joint's acceleration can change
        (None: instantly); with it, the velocity bound leaves room for the velocity still gained while the
        acceleration ramps down (``a dt + a^2 / (2 j) <= v_lim - dq``) and the braking speed for the ramp time
        before full deceleration (see ``controllers.tick_kernels.ramp_speed``)."""
        j = np.full(7, np.inf) if j_eff_rad_s3 is None else np.asarray(j_eff_rad_s3, dtype=float)
        t_ramp = np.where(j < 1e15, self.a_max / np.where(j < 1e15, j, 1.0), 0.0)
        q_next = q_rad + dq_rad_s * self.dt_s

        def ramp(d):
            return self.a_max * (-t_ramp + np.sqrt(t_ramp**2 + 2.0 * d / self.a_max))

        def rise(dv):
            finite = (dv > 0) & (j < 1e15)
            jj = np.where(finite, j, 1.0)
            root = jj * (-self.dt_s + np.sqrt(self.dt_s**2 + 2.0 * np.maximum(dv, 0.0) / jj))
            return np.where(finite, root, dv * self.inv_dt)

        d_hi = np.maximum(self.q_hi - q_next, 0.0)
        d_lo = np.maximum(q_next - self.q_lo, 0.0)
        v_hi = np.minimum(np.minimum(self.v_max, ramp(d_hi)), d_hi * self.inv_h)
        v_lo = -np.minimum(np.minimum(self.v_max, ramp(d_lo)), d_lo * self.inv_h)
        ub = np.minimum(self.a_max, rise(v_hi - dq_rad_s))
        lb = np.maximum(-self.a_max, -rise(dq_rad_s - v_lo))
        crossed = lb > ub
        if crossed.any():
            v_near = np.clip(dq_rad_s, v_lo, v_hi)
            brake = np.clip((v_near - dq_rad_s) * self.inv_dt, -self.a_max, self.a_max)
            lb = np.where(crossed, brake, lb)
            ub = np.where(crossed, brake, ub)
        return lb, ub
