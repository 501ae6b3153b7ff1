"""The single linear models: ``"cv"`` (constant velocity, white acceleration) and ``"ca"`` (constant acceleration,
white jerk), one filterpy KalmanFilter each."""

from __future__ import annotations

import numpy as np
from filterpy.kalman import KalmanFilter

from controllers.estimation.config import EstimatorConfig
from controllers.estimation.kalman_blocks import Prediction, StepMatsCache, f_block, initial_covariance, q_block
from controllers.estimation.turn_extrapolation import turn_extrapolate


class LinearModel(StepMatsCache):
    """One filterpy KalmanFilter, cv (6 states: pos m, vel m/s) or ca (9: and acc m/s^2). State: (x, P)."""

    def __init__(self, config: EstimatorConfig) -> None:
        self.config = config
        self.order = 2 if config.model == "cv" else 3
        dim = 3 * self.order
        kf = KalmanFilter(dim_x=dim, dim_z=3)
        kf.H = np.hstack([np.eye(3), np.zeros((3, dim - 3))])
        kf.R = np.eye(3) * config.meas_noise_m**2
        self.kf = kf
        self.var = (config.accel_noise_m_s2 if self.order == 2 else config.jerk_noise_m_s3) ** 2
        self._mats_cache = {}

    def _build_mats(self, h_s: float) -> tuple[np.ndarray, np.ndarray]:
        """(F, Q) over ``h_s``."""
        eye = np.eye(3)
        return np.kron(f_block(self.order, h_s), eye), np.kron(q_block(self.order, h_s, self.var), eye)

    def init_state(self, z: np.ndarray) -> tuple:
        x = np.zeros(3 * self.order)
        x[:3] = z
        return (x, initial_covariance(3 * self.order, self.config, acc=self.order == 3))

    def predict(self, state: tuple, steps: list[tuple[float, bool]]) -> Prediction:
        kf = self.kf
        kf.x, kf.P = state
        for h, drop_motion in steps:
            if drop_motion:
                kf.x = np.concatenate([kf.x[:3], np.zeros(kf.x.size - 3)])
            F, Q = self._mats(h)
            kf.predict(F=F, Q=Q)
        return Prediction((kf.x, kf.P), kf.x, kf.P)

    def update(self, pred: Prediction, z: np.ndarray) -> tuple:
        kf = self.kf
        kf.x, kf.P = pred.state
        kf.update(z)
        return (kf.x, kf.P)

    def mean(self, state: tuple) -> np.ndarray:
        return state[0]

    def extrapolate(self, state: tuple, taus: np.ndarray) -> np.ndarray:
        """Positions (N, 3) ``taus`` (N,) after the state's time (mean only)."""
        x = state[0]
        if self.order == 3:
            return turn_extrapolate(x, taus)[0]
        return x[:3] + np.multiply.outer(taus, x[3:6])

    def extrapolate_vel(self, state: tuple, taus: np.ndarray) -> np.ndarray:
        x = state[0]
        if self.order == 3:
            return turn_extrapolate(x, taus)[1]
        return np.broadcast_to(x[3:6], (taus.size, 3)).copy()

    def mode_probs(self, state: tuple) -> np.ndarray | None:
        return None
