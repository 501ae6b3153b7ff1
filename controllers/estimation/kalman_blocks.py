"""The discrete-time pieces the motion models share: per-axis transition and process-noise blocks of a chain of
integrators, a Kalman filter with a closed-form log-likelihood, the initial covariance, the per-step matrix cache,
and :class:`Prediction` (a state propagated to a measurement's capture time).

State layout of every model: ``[pos (3) m, vel (3) m/s, acc (3) m/s^2, omega rad/s]``, as long as the model needs
(cv 6, ca / imm 9, ct / imm-ct 10); a block of one axis is expanded to three with ``np.kron(block, eye(3))``.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from filterpy.kalman import KalmanFilter

_LOG_2PI = math.log(2.0 * math.pi)
_CACHE_MAX = 256  # step lengths kept per model before the cache is cleared (a jittered stream has many)


def f_block(order: int, h_s: float) -> np.ndarray:
    """Per-axis transition over ``h_s`` seconds of a chain of ``order`` integrators (pos, vel[, acc])."""
    block = np.eye(order)
    for i in range(1, order):
        for j in range(order - i):
            block[j, j + i] = h_s**i / math.factorial(i)
    return block


def q_block(order: int, h_s: float, var: float) -> np.ndarray:
    """Per-axis process noise over ``h_s`` seconds: the highest derivative's derivative is white and held over the
    step (piecewise constant), variance ``var`` ((m/s^2)^2 for order 2, (m/s^3)^2 for order 3). Order 2 (cv: white
    acceleration, G = [h^2/2, h]) is filterpy's ``Q_discrete_white_noise(dim=2)``, bit for bit (the fixed-step
    reference filter's cv). Order 3 (ca: white jerk, G = [h^3/6, h^2/2, h]) is *not* filterpy's ``dim=3``, whose
    noise is an acceleration increment per step (var * 1 on the acceleration whatever h: it would not scale with a
    variable dt, and a 2 m/s^2 increment per 10 ms step is a 200 m/s^3 jerk)."""
    if order == 2:  # the exact expressions of Q_discrete_white_noise(dim=2): the reference filter's Q to the bit
        return np.array([[0.25 * h_s**4, 0.5 * h_s**3], [0.5 * h_s**3, h_s**2]]) * var
    g = np.array([h_s**3 / 6.0, h_s**2 / 2.0, h_s])
    return np.outer(g, g) * var


def cv_in_ca_blocks(h_s: float, var_a: float) -> tuple[np.ndarray, np.ndarray]:
    """Per-axis (F, Q) (3, 3) over ``h_s`` of the constant-velocity hypothesis on a [pos, vel, acc] state: the
    acceleration is set to zero (so a CV state mixes with a CA one); ``var_a``: white acceleration, (m/s^2)^2."""
    f = np.zeros((3, 3))
    f[:2, :2] = f_block(2, h_s)  # acceleration -> 0: the CV hypothesis
    q = np.zeros((3, 3))
    q[:2, :2] = q_block(2, h_s, var_a)
    return f, q


def initial_covariance(dim: int, config, acc: bool = False, turn: bool = False) -> np.ndarray:
    """The covariance (dim, dim) of a state initialised on one measurement: the measurement noise on the position,
    the initial velocity (and, with ``acc`` / ``turn``, acceleration / turn-rate) uncertainty of ``config``
    (an :class:`~controllers.estimation.config.EstimatorConfig`), uncorrelated."""
    P = np.eye(dim)
    P[:3, :3] *= config.meas_noise_m**2
    P[3:6, 3:6] *= config.init_vel_std_m_s**2
    if acc:
        P[6:9, 6:9] *= config.init_acc_std_m_s2**2
    if turn:
        P[9, 9] = config.init_turn_std_rad_s**2
    return P


class StepMatsCache:
    """The per-step matrices of a model, built once per step length by ``self._build_mats(h_s)`` and looked up by
    ``_mats(h_s)`` (keyed to the picosecond: regular stamps, k * dt float-jittered, share one entry)."""

    _mats_cache: dict[int, tuple]

    def _build_mats(self, h_s: float) -> tuple:
        raise NotImplementedError

    def _mats(self, h_s: float) -> tuple:
        key = round(h_s * 1e12)
        got = self._mats_cache.get(key)
        if got is None:
            if len(self._mats_cache) > _CACHE_MAX:
                self._mats_cache.clear()
            got = self._build_mats(h_s)
            self._mats_cache[key] = got
        return got


class LogLikelihoodKF(KalmanFilter):
    """filterpy's KalmanFilter with a closed-form log-likelihood (its update already has S and S^-1; the stock
    property calls scipy's multivariate_normal, ~10x slower). Used by the IMMs' mode updates."""

    @property
    def log_likelihood(self):
        if self._log_likelihood is None:
            y = self.y.ravel()
            _, logdet = np.linalg.slogdet(self.S)
            self._log_likelihood = -0.5 * (float(y @ self.SI @ y) + logdet + y.size * _LOG_2PI)
        return self._log_likelihood


class Prediction(NamedTuple):
    """A state propagated to a measurement's capture time: the model's own state (what its ``update`` takes) and
    the combined mean (m, m/s, ...) and covariance the gates test the measurement against."""

    state: tuple
    x: np.ndarray
    P: np.ndarray
