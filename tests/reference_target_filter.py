"""The fixed-step reference filter the target estimator is tested against (moved here from
``controllers/target_filter.py``: the stack runs :class:`controllers.target_estimator.TargetEstimator`).

A constant-velocity Kalman filter (filterpy) on the target position, stepped once per perception period: with model
cv and zero latency the estimator reproduces it to rounding, which ``tests/test_target_estimator.py`` holds.

Every measurement passes a gate before it may touch the filter; what is gated is counted, never fused:
- non-finite (NaN, inf) or wrongly shaped: ``gated_nonfinite``;
- frozen: bit-for-bit the value of the previous measurement (a real sensor's noise never repeats; a
  stalled driver re-sends its last value): ``gated_frozen``;
- outlier: innovation far outside the filter's belief (squared Mahalanobis distance above ``reset_gate``):
  ``gated_outlier``. If ``reset_after`` such measurements in a row *agree with each other* (each within
  ``jump_agree_m`` of the previous one) the target really jumped, and the filter re-initialises on the
  last of them instead of slowly gliding over; isolated or scattered outliers never move it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from filterpy.common import Q_discrete_white_noise
from filterpy.kalman import KalmanFilter


@dataclass(frozen=True)
class FilterConfig:
    """Attributes:
    dt_s: measurement period, s (100 Hz perception by default).
    meas_noise_m: measurement noise standard deviation, m.
    accel_noise_m_s2: process noise: standard deviation of the unmodelled acceleration, m/s^2.
    init_vel_std_m_s: initial velocity standard deviation, m/s.
    reset_gate: squared Mahalanobis distance of an innovation treated as a jump.
    reset_after: consecutive gated measurements, each agreeing with the previous, before re-initialising.
    jump_agree_m: how close consecutive gated measurements must be to count as one new position (a jump), m.
    frozen_gate: gate bit-identical repeats (a noisy sensor never repeats).
    coast_s: after this long without a fused measurement the velocity estimate is dropped, s.
    """

    dt_s: float = 0.01
    meas_noise_m: float = 0.002
    accel_noise_m_s2: float = 2.0
    init_vel_std_m_s: float = 0.5
    reset_gate: float = 60.0
    reset_after: int = 2
    jump_agree_m: float = 0.016
    frozen_gate: bool = True
    coast_s: float = 0.5


class TargetFilter:
    """3-D target tracker. ``step(t, z)`` once per perception tick; ``predict_pos(t)`` any time."""

    def __init__(self, config: FilterConfig = FilterConfig()) -> None:
        self.config = config
        kf = KalmanFilter(dim_x=6, dim_z=3)
        dt = config.dt_s
        kf.F = np.kron(np.array([[1.0, dt], [0.0, 1.0]]), np.eye(3))  # state [pos(3), vel(3)]
        kf.H = np.hstack([np.eye(3), np.zeros((3, 3))])
        kf.R = np.eye(3) * config.meas_noise_m**2
        kf.Q = Q_discrete_white_noise(dim=2, dt=dt, var=config.accel_noise_m_s2**2, block_size=3, order_by_dim=False)
        self.kf = kf
        self.initialized = False
        self.t_s = 0.0
        self.resets = 0
        self.missed = 0
        self.fused = 0
        self.gated_nonfinite = 0
        self.gated_frozen = 0
        self.gated_outlier = 0
        self.coasts = 0
        self._gated = 0
        self._last_z: np.ndarray | None = None
        self._last_gated: np.ndarray | None = None
        self._gated_since_s = 0.0
        self._last_fused_s = 0.0
        #: the last confirmed jump: when its first measurement arrived, when the filter re-initialised, and where
        self.jump_started_s: float | None = None
        self.reset_at_s: float | None = None
        self.reset_pos_m: np.ndarray | None = None

    @property
    def gated(self) -> int:
        """Measurements rejected by the gate (non-finite, frozen, outlier)."""
        return self.gated_nonfinite + self.gated_frozen + self.gated_outlier

    def _init_on(self, t_s: float, z: np.ndarray) -> None:
        kf = self.kf
        kf.x = np.zeros(6)
        kf.x[:3] = z
        kf.P = np.eye(6)
        kf.P[:3, :3] *= self.config.meas_noise_m**2
        kf.P[3:6, 3:6] *= self.config.init_vel_std_m_s**2
        self.t_s = t_s
        self.initialized = True
        self._gated = 0
        self._last_gated = None
        self._last_fused_s = t_s

    def _screen(self, z_m) -> np.ndarray | None:
        """The measurement as a (3,) array if it passes the non-finite and frozen gates, else None (counted)."""
        try:
            z = np.asarray(z_m, dtype=np.float64)
        except (TypeError, ValueError):
            self.gated_nonfinite += 1
            return None
        if z.shape != (3,) or not np.all(np.isfinite(z)):
            self.gated_nonfinite += 1
            return None
        if self.config.frozen_gate and self._last_z is not None and np.array_equal(z, self._last_z):
            self.gated_frozen += 1
            return None
        self._last_z = z
        return z

    def step(self, t_s: float, z_m: np.ndarray | None) -> str:
        """Predict to ``t_s`` (one perception period after the last step) and fuse ``z_m`` if it passes the gate.

        Returns what happened: ``"missed"`` (None), ``"nonfinite"``/``"frozen"``/``"outlier"`` (gated, counted),
        ``"reset"`` (a confirmed jump: re-initialised), ``"init"`` or ``"fused"``. Never raises on a bad value."""
        if z_m is not None:
            before = self.gated_nonfinite
            z_m = self._screen(z_m)
            if z_m is None:
                gated = "nonfinite" if self.gated_nonfinite > before else "frozen"
                if self.initialized:
                    self._predict(t_s)
                return gated
        if not self.initialized:
            if z_m is None:
                return "missed"
            self._init_on(t_s, z_m)
            return "init"
        self._predict(t_s)
        if z_m is None:
            self.missed += 1
            return "missed"
        y = z_m - self.kf.H @ self.kf.x
        S = self.kf.H @ self.kf.P @ self.kf.H.T + self.kf.R
        if float(y @ np.linalg.solve(S, y)) > self.config.reset_gate:
            return self._gated_or_reset(t_s, z_m)
        self._gated = 0
        self._last_gated = None
        self.kf.update(z_m)
        self.fused += 1
        self._last_fused_s = t_s
        return "fused"

    def _gated_or_reset(self, t_s: float, z_m: np.ndarray) -> str:
        agrees = self._last_gated is not None and np.linalg.norm(z_m - self._last_gated) <= self.config.jump_agree_m
        self._gated = self._gated + 1 if (agrees or self._gated == 0) else 1
        if self._gated == 1:
            self._gated_since_s = t_s
        self._last_gated = z_m
        if self._gated >= self.config.reset_after:
            self.resets += 1
            self.jump_started_s, self.reset_at_s = self._gated_since_s, t_s
            self._init_on(t_s, z_m)
            self.reset_pos_m = z_m.copy()
            return "reset"
        self.gated_outlier += 1
        return "outlier"

    def _predict(self, t_s: float) -> None:
        """One period ahead; past ``coast_s`` without a fused measurement the motion estimate is dropped (once)."""
        self.kf.predict()
        self.t_s = t_s
        if t_s - self._last_fused_s > self.config.coast_s and np.any(self.kf.x[3:]):
            self.kf.x[3:] = 0.0
            self.coasts += 1

    @property
    def pos_m(self) -> np.ndarray:
        return self.kf.x[:3].copy()

    @property
    def vel_m_s(self) -> np.ndarray:
        return self.kf.x[3:6].copy()

    def predict_pos(self, t_s: float) -> np.ndarray:
        """Predicted position at ``t_s`` (constant-velocity extrapolation from the last estimate)."""
        x = self.kf.x
        return x[:3] + x[3:6] * (t_s - self.t_s)

    def predict_pos_many(self, times_s: np.ndarray) -> np.ndarray:
        """Predicted positions (N, 3) at ``times_s`` (N,): :meth:`predict_pos`, vectorized."""
        x = self.kf.x
        return x[:3] + np.multiply.outer(np.asarray(times_s, dtype=float) - self.t_s, x[3:6])
