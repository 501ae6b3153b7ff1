"""Kalman filter on the target position (filterpy), from noisy, sometimes missing measurements.

The stack runs ``controllers.target_estimator.TargetEstimator`` (capture-time fusion, cv/ca/imm); this fixed-step
filter stays as its zero-latency reference: with model cv the estimator reproduces it to rounding, which
``tests/test_target_estimator.py`` holds.

Constant-velocity (default) or constant-acceleration model per axis.

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
    model: "cv" (constant velocity) or "ca" (constant acceleration).
    meas_noise_m: measurement noise standard deviation, m.
    accel_noise_m_s2: process noise: standard deviation of the unmodelled acceleration (cv) or jerk (ca).
    init_vel_std_m_s: initial velocity standard deviation, m/s.
    reset_gate: squared Mahalanobis distance of an innovation treated as a jump.
    reset_after: consecutive gated measurements, each agreeing with the previous, before re-initialising.
    jump_agree_m: how close consecutive gated measurements must be to count as one new position (a jump), m.
    frozen_gate: gate bit-identical repeats (a noisy sensor never repeats); switch it off for a noise-free
        simulated sensor, whose measurements of a static target repeat legitimately.
    coast_s: after this long without a fused measurement the velocity (and acceleration) estimate is dropped:
        the target is taken to stand where it was last estimated instead of being extrapolated for seconds
        (a frozen or blinded sensor), s.
    """

    dt_s: float = 0.01
    model: str = "cv"
    meas_noise_m: float = 0.002
    accel_noise_m_s2: float = 2.0
    init_vel_std_m_s: float = 0.5
    reset_gate: float = 60.0
    reset_after: int = 2
    jump_agree_m: float = 0.016
    frozen_gate: bool = True
    coast_s: float = 0.5

    def __post_init__(self) -> None:
        if self.model not in ("cv", "ca"):
            raise ValueError(f"FilterConfig.model must be 'cv' or 'ca', got {self.model!r}")
        for name in ("dt_s", "meas_noise_m", "accel_noise_m_s2", "init_vel_std_m_s", "reset_gate", "jump_agree_m",
                     "coast_s"):
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
        self.fused = 0
        self.gated_nonfinite = 0
        self.gated_frozen = 0
        self.gated_outlier = 0
        self._gated = 0
        self._last_z: np.ndarray | None = None
        self._last_gated: np.ndarray | None = None
        self._gated_since_s = 0.0
        #: the last confirmed jump: when its first measurement arrived, when the filter re-initialised, and where
        self.coasts = 0
        self._last_fused_s = 0.0
        self.jump_started_s: float | None = None
        self.reset_at_s: float | None = None
        self.reset_pos_m: np.ndarray | None = None

    @property
    def gated(self) -> int:
        """Measurements rejected by the gate (non-finite, frozen, outlier)."""
        return self.gated_nonfinite + self.gated_frozen + self.gated_outlier

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
        d2 = float(y @ np.linalg.solve(S, y))
        if d2 > self.config.reset_gate:
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
        self._gated = 0
        self._last_gated = None
        self.kf.update(z_m)
        self.fused += 1
        self._last_fused_s = t_s
        return "fused"

    def _predict(self, t_s: float) -> None:
        """One period ahead; past ``coast_s`` without a fused measurement the motion estimate is dropped (once)."""
        self.kf.predict()
        self.t_s = t_s
        if t_s - self._last_fused_s > self.config.coast_s and np.any(self.kf.x[3:]):
            self.kf.x[3:] = 0.0
            self.coasts += 1

    def estimate_at_observation(self, t0_s: float, recorded_m: np.ndarray | None) -> np.ndarray | None:
        """The best estimate of where the target was at an observation time ``t0_s``, given what is known now.

        ``recorded_m`` is the estimate taken at ``t0_s``. If a jump confirmed since then had already begun at
        ``t0_s`` (its first measurement arrived at or before it), the recorded estimate predates the filter's
        knowledge of a jump the observation already saw: the post-jump position is returned instead (a chunk
        planned on the new position must not be shifted by the jump a second time)."""
        if (recorded_m is None or self.jump_started_s is None or self.reset_at_s is None
                or not (self.jump_started_s - 0.5 * self.config.dt_s <= t0_s < self.reset_at_s)):
            return recorded_m
        return self.reset_pos_m.copy()

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
