"""The turn-aware models: ``"ct"``, a coordinated-turn EKF (constant speed, constant turn rate omega about the
vertical, constant vertical velocity; :mod:`controllers.coordinated_turn`), and ``"imm-ct"``, a filterpy
``IMMEstimator`` of the IMM's CV and CA filters and that CT filter on one 10-dim state
``[pos (3) m, vel (3) m/s, acc (3) m/s^2, omega rad/s]`` (CV and CA hold omega, CT's acceleration slot is its
centripetal acceleration, so the states mix). The CT prediction follows the circle with the estimated turn rate
instead of extrapolating a lagging acceleration.

Measured offline (the scene's motions, 100 Hz, 2 mm noise, 10 % dropout, 10 seeds, mean error 0.1 / 0.2 / 0.4 s
ahead, mm): circle 0.4 m/s imm 9.5 / 22.1 / 60.3, imm-ct 2.0 / 3.3 / 6.9; linear 0.2 with wall bounces 5.1 / 11.3 /
30.0 vs 4.8 / 10.7 / 29.0; accelerating 6.9 / 16.0 / 44.4 vs 7.0 / 16.3 / 45.1; jump 12.7 / 23.1 / 44.4 vs 12.0 /
21.8 / 42.0 (``docs/perception/circle_tracking.md``). The mode probabilities ``(p_cv, p_ca, p_ct)``: ~0.03 / 0.04 /
0.93 on the circle, ~0.88 / 0.04 / 0.08 on a line.
"""

from __future__ import annotations

import numpy as np
from filterpy.kalman import IMMEstimator

from controllers.coordinated_turn import DIM as _CT_DIM
from controllers.coordinated_turn import ct_extrapolate, ct_process_noise, ct_propagate
from controllers.estimation.config import EstimatorConfig
from controllers.estimation.kalman_blocks import (LogLikelihoodKF, Prediction, StepMatsCache, cv_in_ca_blocks,
                                                  f_block, initial_covariance, q_block)
from controllers.estimation.turn_extrapolation import turn_extrapolate


class CoordinatedTurnKF(LogLikelihoodKF):
    """The coordinated-turn EKF on filterpy's KalmanFilter: ``predict`` propagates the state through
    :func:`~controllers.coordinated_turn.ct_propagate` and the covariance through its Jacobian, over ``self.h`` s
    (set before each call: the IMM calls ``predict(u)``); the update is the linear one (the position is measured)."""

    h = 0.01

    def predict(self, u=None, B=None, F=None, Q=None):
        self.x, jac = ct_propagate(self.x, self.h)
        self.F = jac
        self.P = jac @ self.P @ jac.T + self.Q
        self.x_prior = self.x.copy()
        self.P_prior = self.P.copy()


class TurnIMM(StepMatsCache):
    """The turn-aware models on one 10-dim state ``[pos(3), vel(3), acc(3), omega]`` (see
    :mod:`controllers.coordinated_turn`): ``"imm-ct"``, a filterpy IMMEstimator over a CV, a CA and a CT filter
    (CV as the IMM's, with the acceleration set to zero; CA as the IMM's; both hold omega, which they do not
    model), or ``"ct"``, the CT EKF alone. State: (xs, Ps, mu), tuples over the modes.

    Why a third mode and not a better CA extrapolation: on a circle the CA filter's acceleration lags the rotating
    true one (0.45 rad at 0.4 m/s on 8 cm), so any extrapolation of a CA state is off by tens of mm 0.4 s ahead;
    the CT state has the turn rate itself, which is constant on a circle, and its prediction follows the circle."""

    def __init__(self, config: EstimatorConfig) -> None:
        self.config = config
        self.modes = ("ct",) if config.model == "ct" else ("cv", "ca", "ct")
        R = np.eye(3) * config.meas_noise_m**2
        H = np.hstack([np.eye(3), np.zeros((3, _CT_DIM - 3))])
        filters = []
        for mode in self.modes:
            kf = CoordinatedTurnKF(dim_x=_CT_DIM, dim_z=3) if mode == "ct" else LogLikelihoodKF(dim_x=_CT_DIM, dim_z=3)
            kf.H, kf.R = H.copy(), R.copy()
            kf.x = np.zeros(_CT_DIM)
            filters.append(kf)
        self.filters = filters
        n = len(self.modes)
        self.mu0 = np.full(n, 1.0 / n)
        # even switching: M = lam I + (1 - lam) / n 11', stay = lam + (1 - lam) / n; M^s = lam^s I + (1 - lam^s) ...
        self._lam = (n * config.imm_ct_stay - 1.0) / (n - 1.0) if n > 1 else 1.0
        self.M = self._markov(1.0)
        self.imm = IMMEstimator(filters, self.mu0.copy(), self.M.copy()) if n > 1 else None
        self.var_a = config.imm_accel_noise_m_s2**2
        self.var_j = config.jerk_noise_m_s3**2
        self.var_ct = config.ct_accel_noise_m_s2**2
        self.var_w = config.ct_turn_noise_rad_s2**2
        self._mats_cache = {}

    def _markov(self, s: float) -> np.ndarray:
        """The Markov matrix over ``s`` periods ``dt_s``."""
        n = len(self.modes)
        lam_s = self._lam**s if self._lam < 1.0 else 1.0
        return lam_s * np.eye(n) + (1.0 - lam_s) / n * np.ones((n, n))

    def _build_mats(self, h_s: float) -> tuple:
        """Per mode (F, Q) for ``h_s`` (F None for the CT EKF: it has its own), and the Markov matrix for ``h_s``."""
        q_w = h_s * h_s * self.var_w
        per_mode = tuple(self._mode_mats(mode, h_s, q_w) for mode in self.modes)
        return (per_mode, self._markov(h_s / self.config.dt_s))

    def _mode_mats(self, mode: str, h_s: float, q_w: float) -> tuple[np.ndarray | None, np.ndarray]:
        """One mode's (F, Q) (10, 10) over ``h_s``; ``q_w``: the CV / CA modes' turn-rate variance, (rad/s)^2."""
        if mode == "ct":
            return None, ct_process_noise(h_s, self.var_ct, self.var_w)
        eye = np.eye(3)
        F, Q = np.eye(_CT_DIM), np.zeros((_CT_DIM, _CT_DIM))
        if mode == "cv":
            f, q = cv_in_ca_blocks(h_s, self.var_a)  # acceleration -> 0
            F[:9, :9], Q[:9, :9] = np.kron(f, eye), np.kron(q, eye)
        else:
            F[:9, :9], Q[:9, :9] = np.kron(f_block(3, h_s), eye), np.kron(q_block(3, h_s, self.var_j), eye)
        Q[9, 9] = q_w
        return F, Q

    def init_state(self, z: np.ndarray) -> tuple:
        x = np.zeros(_CT_DIM)
        x[:3] = z
        P = initial_covariance(_CT_DIM, self.config, acc=True, turn=True)
        n = len(self.modes)
        return (tuple(x.copy() for _ in range(n)), tuple(P.copy() for _ in range(n)), self.mu0.copy())

    def _load(self, state: tuple) -> None:
        xs, Ps, mu = state
        for f, x, P in zip(self.filters, xs, Ps):
            f.x, f.P = x, P
        if self.imm is not None:
            self.imm.mu = mu.copy()

    def _forget(self, x: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The state after a coast: position kept, motion zero with the initial uncertainty (velocity, acceleration,
        turn rate), uncorrelated with the position. Unlike the cv / ca / imm models (which zero the motion and keep
        its covariance), the turn rate's covariance does not grow much over a coast (``ct_turn_noise_rad_s2``): kept,
        a converged omega reset to 0 would stay confidently 0 when the target reappears and the CT mode would not
        win back a circle (camera, circle, seed 3: 0.4 s-ahead error 40-70 mm for 2 s after a 0.63 s occlusion)."""
        c = self.config
        x = np.concatenate([x[:3], np.zeros(_CT_DIM - 3)])
        P_new = np.zeros((_CT_DIM, _CT_DIM))
        P_new[:3, :3] = P[:3, :3]
        P_new[3:6, 3:6] = np.eye(3) * c.init_vel_std_m_s**2
        P_new[6:9, 6:9] = np.eye(3) * c.init_acc_std_m_s2**2
        P_new[9, 9] = c.init_turn_std_rad_s**2
        return x, P_new

    def _set_step(self, h_s: float) -> np.ndarray:
        per_mode, m = self._mats(h_s)
        for f, (F, Q) in zip(self.filters, per_mode):
            if F is None:
                f.h = h_s
            else:
                f.F = F
            f.Q = Q
        return m

    def _combined(self, xs, Ps, mu) -> tuple[np.ndarray, np.ndarray]:
        x = sum(w * xi for w, xi in zip(mu, xs))
        P = sum(w * (np.outer(xi - x, xi - x) + Pi) for w, xi, Pi in zip(mu, xs, Ps))
        return x, P

    def predict(self, state: tuple, steps: list[tuple[float, bool]]) -> Prediction:
        self._load(state)
        imm, filters = self.imm, self.filters
        for h, drop_motion in steps:
            if drop_motion:  # the motion estimate is forgotten: zero, with its initial uncertainty (see _forget)
                for f in filters:
                    f.x, f.P = self._forget(f.x, f.P)
            m = self._set_step(h)
            if imm is None:
                filters[0].predict()
                continue
            imm.M = m
            imm._compute_mixing_probabilities()  # omega and cbar for this step's M
            imm.predict()
            imm.mu = imm.cbar.copy()  # the predicted mode probabilities: the next sub-step mixes from them
        xs, Ps = tuple(f.x for f in filters), tuple(f.P for f in filters)
        mu = imm.mu.copy() if imm is not None else self.mu0.copy()
        x, P = self._combined(xs, Ps, mu)
        return Prediction((xs, Ps, mu), x, P)

    def update(self, pred: Prediction, z: np.ndarray) -> tuple:
        self._load(pred.state)
        if self.imm is None:
            f = self.filters[0]
            f.update(z)
            return ((f.x,), (f.P,), self.mu0.copy())
        self.imm.cbar = pred.state[2].copy()  # the update weighs the likelihoods with the predicted probabilities
        self.imm.update(z)
        return (tuple(f.x for f in self.filters), tuple(f.P for f in self.filters), self.imm.mu.copy())

    def mean(self, state: tuple) -> np.ndarray:
        xs, _, mu = state
        return sum(w * x for w, x in zip(mu, xs))

    def _extrapolate(self, state: tuple, taus: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The mode-probability-weighted positions and velocities (N, 3) (the modes are held over the horizon): CV
        a line, CA :func:`turn_extrapolate`, CT :func:`~controllers.coordinated_turn.ct_extrapolate`."""
        xs, _, mu = state
        pos, vel = np.zeros((taus.size, 3)), np.zeros((taus.size, 3))
        for mode, x, w in zip(self.modes, xs, mu):
            if mode == "cv":
                p_i, v_i = x[:3] + np.multiply.outer(taus, x[3:6]), np.broadcast_to(x[3:6], (taus.size, 3))
            elif mode == "ca":
                p_i, v_i = turn_extrapolate(x[:9], taus)
            else:
                p_i, v_i = ct_extrapolate(x, taus)
            pos += w * p_i
            vel += w * v_i
        return pos, vel

    def extrapolate(self, state: tuple, taus: np.ndarray) -> np.ndarray:
        return self._extrapolate(state, taus)[0]

    def extrapolate_vel(self, state: tuple, taus: np.ndarray) -> np.ndarray:
        return self._extrapolate(state, taus)[1]

    def mode_probs(self, state: tuple) -> np.ndarray | None:
        return state[2].copy() if self.imm is not None else None
