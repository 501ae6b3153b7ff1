"""``"imm"``: an interacting-multiple-model estimator (filterpy ``IMMEstimator``) of a constant-velocity and a
constant-acceleration Kalman filter sharing one 9-dim state ``[pos (3) m, vel (3) m/s, acc (3) m/s^2]`` (the CV
filter's F sets the acceleration to zero, so both states are compatible for mixing).

What the mode probabilities ``(p_cv, p_ca)`` do (measured, default configuration, 100 Hz, 2 mm noise, 5 s): on a
straight line at constant velocity the quiet CV mode explains the measurements best and p(ca) sinks to ~0.07
(median; 10-90 %: 0.06-0.10). It never reaches 0: the Markov matrix moves 1 % per step back to CA, which only the
likelihood ratio offsets. The prediction is then close to a CV filter's, and better than the default CV filter's,
since the IMM's CV mode has a quieter process noise (``imm_accel_noise_m_s2`` 0.5 vs 2 m/s^2): the CA mode takes
the manoeuvres. On a circle (radius 0.08 m, 0.4 m/s: 2 m/s^2 centripetal) the CV mode lags and its innovations
grow: p(ca) rises to ~0.94 (10-90 %: 0.88-0.97), and the prediction follows the CA filter's, which bends along the
curve (200 ms ahead, i.e. one radian around the circle, it still misses by ~40 mm, against ~56 mm for CV).
"""

from __future__ import annotations

import numpy as np
from filterpy.kalman import IMMEstimator

from controllers.estimation.config import EstimatorConfig
from controllers.estimation.kalman_blocks import (LogLikelihoodKF, Prediction, StepMatsCache, cv_in_ca_blocks,
                                                  f_block, initial_covariance, q_block)
from controllers.estimation.turn_extrapolation import turn_extrapolate


class CvCaIMM(StepMatsCache):
    """filterpy IMMEstimator over a CV and a CA KalmanFilter sharing a 9-dim state. State: (x_cv, P_cv, x_ca, P_ca,
    mu) with mu the mode probabilities (cv, ca)."""

    def __init__(self, config: EstimatorConfig) -> None:
        self.config = config
        R = np.eye(3) * config.meas_noise_m**2
        H = np.hstack([np.eye(3), np.zeros((3, 6))])
        filters = []
        for _ in range(2):
            kf = LogLikelihoodKF(dim_x=9, dim_z=3)
            kf.H, kf.R = H.copy(), R.copy()
            kf.x = np.zeros(9)  # 1-D states: the IMM sizes its mixing buffers on them
            filters.append(kf)
        self.M = np.asarray(config.imm_transition, dtype=float)
        p, q = self.M[0, 0], self.M[1, 1]
        self._lam = p + q - 1.0
        # stationary mode distribution: the mode probabilities on (re-)initialisation
        self.mu0 = np.array([0.5, 0.5]) if self._lam >= 1.0 else np.array([1.0 - q, 1.0 - p]) / (2.0 - p - q)
        self.imm = IMMEstimator(filters, self.mu0.copy(), self.M.copy())
        self.var_a = config.imm_accel_noise_m_s2**2
        self.var_j = config.jerk_noise_m_s3**2
        self._mats_cache = {}

    def _build_mats(self, h_s: float) -> tuple:
        """(F_cv, Q_cv, F_ca, Q_ca, M) over ``h_s``: M the Markov matrix per ``dt_s`` raised to ``h_s / dt_s``."""
        eye = np.eye(3)
        f_cv, q_cv = cv_in_ca_blocks(h_s, self.var_a)
        s = h_s / self.config.dt_s
        if abs(s - 1.0) < 1e-9:
            m = self.M.copy()
        else:  # M^s = 1 pi + lam^s (I - 1 pi), lam = p + q - 1 the second eigenvalue, pi the stationary row
            stationary = np.outer(np.ones(2), self.mu0)
            m = stationary + (self._lam**s if self._lam < 1.0 else 1.0) * (np.eye(2) - stationary)
        return (np.kron(f_cv, eye), np.kron(q_cv, eye), np.kron(f_block(3, h_s), eye),
                np.kron(q_block(3, h_s, self.var_j), eye), m)

    def init_state(self, z: np.ndarray) -> tuple:
        x = np.zeros(9)
        x[:3] = z
        P = initial_covariance(9, self.config, acc=True)
        return (x, P, x.copy(), P.copy(), self.mu0.copy())

    def _load(self, state: tuple) -> None:
        cv, ca = self.imm.filters
        cv.x, cv.P, ca.x, ca.P, mu = state
        self.imm.mu = mu.copy()

    def predict(self, state: tuple, steps: list[tuple[float, bool]]) -> Prediction:
        imm = self.imm
        cv, ca = imm.filters
        self._load(state)
        for h, drop_motion in steps:
            if drop_motion:
                for f in imm.filters:
                    f.x = np.concatenate([f.x[:3], np.zeros(6)])
            cv.F, cv.Q, ca.F, ca.Q, imm.M = self._mats(h)
            imm._compute_mixing_probabilities()  # omega and cbar for this step's M
            imm.predict()
            imm.mu = imm.cbar.copy()  # the predicted mode probabilities: the next sub-step mixes from them
        mu = imm.mu
        x = mu[0] * cv.x + mu[1] * ca.x
        dx0, dx1 = cv.x - x, ca.x - x
        P = mu[0] * (np.outer(dx0, dx0) + cv.P) + mu[1] * (np.outer(dx1, dx1) + ca.P)
        return Prediction((cv.x, cv.P, ca.x, ca.P, mu.copy()), x, P)

    def update(self, pred: Prediction, z: np.ndarray) -> tuple:
        imm = self.imm
        self._load(pred.state)
        imm.cbar = pred.state[4].copy()  # the update weighs the likelihoods with the predicted mode probabilities
        imm.update(z)
        cv, ca = imm.filters
        return (cv.x, cv.P, ca.x, ca.P, imm.mu.copy())

    def mean(self, state: tuple) -> np.ndarray:
        mu = state[4]
        return mu[0] * state[0] + mu[1] * state[2]

    def extrapolate(self, state: tuple, taus: np.ndarray) -> np.ndarray:
        """The mode-probability-weighted prediction: p(cv) * CV extrapolation + p(ca) * CA extrapolation (the modes
        are held over the horizon)."""
        x_cv, _, x_ca, _, mu = state
        pos_cv = x_cv[:3] + np.multiply.outer(taus, x_cv[3:6])
        pos_ca = turn_extrapolate(x_ca, taus)[0]
        return mu[0] * pos_cv + mu[1] * pos_ca

    def extrapolate_vel(self, state: tuple, taus: np.ndarray) -> np.ndarray:
        x_cv, _, x_ca, _, mu = state
        return mu[0] * np.broadcast_to(x_cv[3:6], (taus.size, 3)) + mu[1] * turn_extrapolate(x_ca, taus)[1]

    def mode_probs(self, state: tuple) -> np.ndarray | None:
        return state[4].copy()
