"""Kalman filter on the target position (filterpy), from noisy, sometimes missing measurements.

Constant-velocity (default) or constant-acceleration model per axis. A measurement whose
innovation is far outside the filter's belief (squared Mahalanobis distance above
``reset_gate`` for ``reset_after`` measurements in a row) means the target jumped: the
filter re-initialises on it instead of slowly gliding over.
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
    model: "cv" (constant velocity) or "ca" (constant acceleration).
    meas_noise_m: measurement noise standard deviation, m.
    accel_noise_m_s2: process noise: standard deviation of the unmodelled acceleration (cv) or jerk (ca).
    init_vel_std_m_s: initial velocity standard deviation, m/s.
    reset_gate: squared Mahalanobis distance of an innovation treated as a jump.
    reset_after: consecutive gated measurements before re-initialising.
    """

    dt_s: float = 0.01
    model: str = "cv"
    meas_noise_m: float = 0.002
    accel_noise_m_s2: float = 2.0
    init_vel_std_m_s: float = 0.5
    reset_gate: float = 60.0
    reset_after: int = 2

    def __post_init__(self) -> None:
        if self.model not in ("cv", "ca"):
            raise ValueError(f"FilterConfig.model must be 'cv' or 'ca', got {self.model!r}")
        for name in ("dt_s", "meas_noise_m", "accel_noise_m_s2", "init_vel_std_m_s", "reset_gate"):
            if not getattr(self, name) > 0:
                raise ValueError(f"FilterConfig.{name} must be > 0, got {getattr(self, name)}")
        if self.reset_after < 1:
            raise ValueError(f"FilterConfig.reset_after must be >= 1, got {self.reset_after}")


class TargetFilter:
    """3-D target tracker. ``step(t, z)`` once per perception tick; ``predict_pos(t)`` any time."""

    def __init__(self, config: FilterConfig = FilterConfig()) -> None:
        self.config = config
        order = 2 if config.model == "cv" else 3
        self._order = order
        dim = 3 * order
        kf = KalmanFilter(dim_x=dim, dim_z=3)
        dt = config.dt_s
        block = np.eye(order)
        for i in range(1, order):
            for j in range(order - i):
                block[j, j + i] = dt**i / np.prod(np.arange(1, i + 1))
        kf.F = np.kron(block, np.eye(3))  # state [pos(3), vel(3), (acc(3))]
        kf.H = np.hstack([np.eye(3), np.zeros((3, dim - 3))])
        kf.R = np.eye(3) * config.meas_noise_m**2
        kf.Q = Q_discrete_white_noise(dim=order, dt=dt, var=config.accel_noise_m_s2**2, block_size=3, order_by_dim=False)
        self.kf = kf
        self.initialized = False
        self.t_s = 0.0
        self.resets = 0
        self.missed = 0
        self._gated = 0

    def _init_on(self, t_s: float, z: np.ndarray) -> None:
        kf = self.kf
        kf.x = np.zeros(3 * self._order)
        kf.x[:3] = z
        kf.P = np.eye(3 * self._order)
        kf.P[:3, :3] *= self.config.meas_noise_m**2
        kf.P[3:6, 3:6] *= self.config.init_vel_std_m_s**2
        self.t_s = t_s
        self.initialized = True
        self._gated = 0

    def step(self, t_s: float, z_m: np.ndarray | None) -> None:
        """Predict to ``t_s`` (one perception period after the last step) and fuse ``z_m`` if present."""
        if z_m is not None:
            z_m = np.asarray(z_m, dtype=np.float64)
            if z_m.shape != (3,) or not np.all(np.isfinite(z_m)):
                raise ValueError(f"target measurement must be 3 finite numbers, got {z_m!r}")
        if not self.initialized:
            if z_m is not None:
                self._init_on(t_s, z_m)
            return
        self.kf.predict()
        self.t_s = t_s
        if z_m is None:
            self.missed += 1
            return
        y = z_m - self.kf.H @ self.kf.x
        S = self.kf.H @ self.kf.P @ self.kf.H.T + self.kf.R
        d2 = float(y @ np.linalg.solve(S, y))
        if d2 > self.config.reset_gate:
            self._gated += 1
            if self._gated >= self.config.reset_after:
                self.resets += 1
                self._init_on(t_s, z_m)
            return
        self._gated = 0
        self.kf.update(z_m)

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
