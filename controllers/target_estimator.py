"""Latency-aware target estimator: :class:`~controllers.target_filter.TargetFilter`'s contract, plus

1. **latency-aware fusion**: ``fuse(t_capture_s, z)`` takes a measurement of the target *as it was* at its capture
   time, however late it arrives. The state lives at the last fused capture time ``t_s``; it is propagated to
   each new capture time with the real time difference (F and Q rebuilt for that dt) and updated there, and
   :meth:`TargetEstimator.predict_pos` extrapolates to *now* with the model. A measurement captured before the
   newest one already processed (out of order) but within ``history_s`` of it rolls the estimator back to the
   state stored just before it and re-fuses the later stored measurements in capture order, so the result does
   not depend on the arrival order; an older one is dropped (``dropped_old``).
2. **a model that follows curving motion**: ``"ca"`` (constant acceleration, white jerk) or ``"imm"``, an
   interacting-multiple-model estimator (filterpy ``IMMEstimator``) of a constant-velocity and a
   constant-acceleration Kalman filter sharing one 9-dim state ``[pos(3), vel(3), acc(3)]`` (the CV filter's F
   sets the acceleration to zero, so both states are compatible for mixing).

   What the IMM mode probabilities ``mode_probs = (p_cv, p_ca)`` do (measured, default configuration, 100 Hz,
   2 mm noise, 5 s): on a straight line at constant velocity the quiet CV mode explains the measurements best and
   p(ca) sinks to ~0.07 (median; 10-90 %: 0.06-0.10). It never reaches 0: the Markov matrix moves 1 % per step
   back to CA, which only the likelihood ratio offsets. The prediction is then close to a CV filter's, and
   better than the default CV filter's, since the IMM's CV mode has a quieter process noise
   (``imm_accel_noise_m_s2`` 0.5 vs 2 m/s^2): the CA mode takes the manoeuvres. On a circle (radius 0.08 m,
   0.4 m/s: 2 m/s^2 centripetal) the CV mode lags and its innovations grow: p(ca) rises to ~0.94 (10-90 %:
   0.88-0.97), and the prediction follows the CA filter's, which bends along the curve (a quadratic
   extrapolation: 200 ms ahead, i.e. one radian around the circle, it still misses by ~40 mm, against ~56 mm for
   CV).
3. **a model of the turn itself**: ``"ct"``, a coordinated-turn EKF (constant speed, constant turn rate omega
   about the vertical, constant vertical velocity; :mod:`controllers.coordinated_turn`), and ``"imm-ct"``, a
   filterpy ``IMMEstimator`` of the IMM's CV and CA filters and that CT filter on one 10-dim state
   ``[pos(3), vel(3), acc(3), omega]`` (CV and CA hold omega, CT's acceleration slot is its centripetal
   acceleration, so the states mix). The CT prediction follows the circle with the estimated turn rate instead
   of extrapolating a lagging acceleration. Measured offline (the scene's motions, 100 Hz, 2 mm noise, 10 %
   dropout, 10 seeds, mean error 0.1 / 0.2 / 0.4 s ahead, mm): circle 0.4 m/s imm 9.5 / 22.1 / 60.3, imm-ct
   2.0 / 3.3 / 6.9; linear 0.2 with wall bounces 5.1 / 11.3 / 30.0 vs 4.8 / 10.7 / 29.0; accelerating 6.9 / 16.0 /
   44.4 vs 7.0 / 16.3 / 45.1; jump 12.7 / 23.1 / 44.4 vs 12.0 / 21.8 / 42.0 (``docs/perception/circle_tracking.md``).
   ``mode_probs`` is then ``(p_cv, p_ca, p_ct)``: ~0.03 / 0.04 / 0.93 on the circle, ~0.88 / 0.04 / 0.08 on a line.
   ``"imm"`` keeps its meaning (CV + CA).

Same gates as ``TargetFilter`` (non-finite, frozen, outlier, jump re-initialisation when gated measurements
agree), same status strings, same counters, plus ``"dropped"`` (older than ``history_s``) and the counters
``dropped_old`` and ``reordered``.

With ``model="cv"`` and zero latency, ``step(t, z)`` reproduces ``TargetFilter.step`` to rounding (1e-9) on any
100 Hz stream, dropouts and gated measurements included: a gap longer than ``dt_s`` between fused captures is
propagated in sub-steps of at most ``dt_s`` (the piecewise-constant white-noise Q is defined per hold period: one
Q over a 0.3 s dropout would not be the tick-by-tick filter's). Where it deliberately differs from
``TargetFilter``: ``pos_m``/``vel_m_s``/``t_s`` are the estimate at the last *fused* capture time (``TargetFilter``
moves them to every step's time; ``predict_pos(t)`` agrees), and the coast after ``coast_s`` without a fused
measurement drops the motion estimate exactly at ``t_s + coast_s`` (``TargetFilter``: at the first step past it, up
to one period later). Model ``"ca"`` differs from ``TargetFilter``'s ca on purpose: its Q is a white jerk in m/s^3
(see ``_q_block``) and ``predict_pos`` extrapolates with the acceleration (``TargetFilter`` with the velocity only).

Imports numpy, filterpy and the standard library only (it runs on a real arm).
"""

from __future__ import annotations

import math
from bisect import bisect_right
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from filterpy.kalman import IMMEstimator, KalmanFilter

from controllers.coordinated_turn import DIM as _CT_DIM
from controllers.coordinated_turn import ct_extrapolate, ct_process_noise, ct_propagate

FILTER_MODELS = ("cv", "ca", "imm", "ct", "imm-ct")

_MAX_SUBSTEPS = 64  # a longer gap (a sensor blackout of seconds) is propagated in 64 equal steps
_LOG_2PI = math.log(2.0 * math.pi)


@dataclass(frozen=True)
class EstimatorConfig:
    """Attributes:
    model: "cv" (constant velocity), "ca" (constant acceleration), "imm" (IMM of both), "ct" (coordinated turn:
        constant speed and turn rate about the vertical, an EKF) or "imm-ct" (IMM of CV, CA and CT).
    dt_s: nominal measurement period (100 Hz perception): the hold period of the piecewise-constant process noise
        (gaps between fused measurements are propagated in steps of at most this) and the step of
        ``imm_transition``; also the tolerance of :meth:`TargetEstimator.estimate_at_observation`, s.
    meas_noise_m: measurement noise standard deviation, m.
    accel_noise_m_s2: cv process noise: standard deviation of the white (piecewise-constant) acceleration, m/s^2.
    jerk_noise_m_s3: ca (and the IMM's CA mode) process noise: standard deviation of the white jerk, m/s^3.
        Chosen by measurement on the 0.08 m / 0.4 m/s circle (2 m/s^2 turning at 5 rad/s: a 10 m/s^3 jerk), 100 Hz,
        2 mm noise: one-step RMS error 4.9 / 3.1 / 2.6 / 2.6 / 2.8 / 3.2 mm at 5 / 10 / 20 / 30 / 50 / 100; 20 is
        the best one-step and within 1 mm of the best 200 ms-ahead error (30: 41 vs 42 mm).
    imm_accel_noise_m_s2: process noise of the IMM's CV mode (white acceleration), m/s^2. Quieter than the cv
        model's: the CA mode covers the manoeuvres, so the CV mode can be the steady-motion hypothesis. Measured
        (200 ms ahead, line / circle): 2.0 -> 11 / 41 mm, 1.0 -> 6.6 / 41, 0.5 -> 4.5 / 41, 0.2 -> 3.1 / 41 mm;
        0.5 keeps some tolerance to a target that is not exactly at constant velocity.
    imm_transition: the IMM's Markov matrix per ``dt_s`` (rows: from cv, from ca; columns: to cv, to ca).
        Stay probabilities must sum to more than 1 (the per-dt matrix is raised to fractional powers for other
        steps). Measured (200 ms ahead, line / circle / 0.4 s after a line turns into the circle): stay 0.98 ->
        5.1 / 40.9 / 45.3 mm, 0.99 -> 4.5 / 41.4 / 46.1, 0.995 -> 4.1 / 41.7 / 46.7; 0.99 (a mode lasts ~1 s on
        average) trades a little manoeuvre onset for steadier straight lines.
    ct_accel_noise_m_s2: process noise of the coordinated-turn mode (``ct``, and the CT mode of ``imm-ct``): white
        acceleration on position and velocity around the turn, m/s^2 (see :mod:`controllers.coordinated_turn`).
        Measured (imm-ct, offline 0.4 s ahead circle / line / jump, mm): 1.0 -> 11.9 / 30.2 / 43.7, 0.5 -> 8.7 /
        30.6 / 43.4, 0.2 -> 6.9 / 29.0 / 42.0, 0.1 -> 6.3 / 28.4 / 41.4; in the loop (circle 0.4, 20 episodes,
        mean error after the first reach, seeds 0-19 / 100-119) 0.5 -> 17.3 / 14.7, 0.2 -> 13.8 / 14.3, 0.1 ->
        15.2 / 15.1 mm: 0.2 (the CV / CA modes take what is not a steady turn).
    ct_turn_noise_rad_s2: CT process noise on the turn rate: white turn-rate acceleration, rad/s^2 (offline, 0.5 to
        5 moves the circle's 0.4 s-ahead error by under 1 mm; the CV and CA modes hold omega with it too).
    imm_ct_stay: ``imm-ct``'s probability per ``dt_s`` of staying in a mode (CV, CA, CT); the rest is spread evenly
        over the other two. In (1/3, 1]. Offline 0.4 s ahead (circle / accelerating): 0.98 -> 12.9 / 43.8,
        0.99 -> 8.7 / 44.9, 0.995 -> 6.9 / 46.3 mm (at ct_accel_noise 0.5); 0.99 as the imm's.
    init_vel_std_m_s: initial velocity standard deviation, m/s.
    init_turn_std_rad_s: initial turn-rate standard deviation (ct, imm-ct), rad/s.
    init_acc_std_m_s2: initial acceleration standard deviation (ca, imm), m/s^2 (1 as in ``TargetFilter``'s ca).
    history_s: how far back (capture time, behind the newest processed measurement) an out-of-order measurement
        is still re-fused; older ones are dropped and counted. 0 drops every out-of-order measurement, s.
    reset_gate, reset_after, jump_agree_m, frozen_gate, coast_s: the gates of
        :class:`~controllers.target_filter.FilterConfig`, same meaning.
    """

    model: str = "cv"
    dt_s: float = 0.01
    meas_noise_m: float = 0.002
    accel_noise_m_s2: float = 2.0
    jerk_noise_m_s3: float = 20.0
    imm_accel_noise_m_s2: float = 0.5
    imm_transition: tuple[tuple[float, float], tuple[float, float]] = ((0.99, 0.01), (0.01, 0.99))
    ct_accel_noise_m_s2: float = 0.2
    ct_turn_noise_rad_s2: float = 2.0
    imm_ct_stay: float = 0.99
    init_vel_std_m_s: float = 0.5
    init_acc_std_m_s2: float = 1.0
    init_turn_std_rad_s: float = 3.0
    history_s: float = 0.5
    reset_gate: float = 60.0
    reset_after: int = 2
    jump_agree_m: float = 0.016
    frozen_gate: bool = True
    coast_s: float = 0.5

    def __post_init__(self) -> None:
        if self.model not in FILTER_MODELS:
            raise ValueError(f"EstimatorConfig.model must be one of {FILTER_MODELS}, got {self.model!r}")
        for name in ("dt_s", "meas_noise_m", "accel_noise_m_s2", "jerk_noise_m_s3", "imm_accel_noise_m_s2",
                     "init_vel_std_m_s", "init_acc_std_m_s2", "reset_gate", "jump_agree_m", "coast_s",
                     "ct_accel_noise_m_s2", "ct_turn_noise_rad_s2", "init_turn_std_rad_s"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"EstimatorConfig.{name} must be a finite number > 0, got {value!r}")
        if not (isinstance(self.history_s, (int, float)) and math.isfinite(self.history_s) and self.history_s >= 0):
            raise ValueError(f"EstimatorConfig.history_s must be a finite number >= 0, got {self.history_s!r}")
        if not (isinstance(self.imm_ct_stay, (int, float)) and 1.0 / 3.0 < self.imm_ct_stay <= 1.0):
            raise ValueError(f"EstimatorConfig.imm_ct_stay must be a probability in (1/3, 1], got {self.imm_ct_stay!r}")
        if not isinstance(self.reset_after, int) or self.reset_after < 1:
            raise ValueError(f"EstimatorConfig.reset_after must be an integer >= 1, got {self.reset_after!r}")
        try:
            m = np.asarray(self.imm_transition, dtype=float)
        except (TypeError, ValueError):
            m = np.zeros(0)
        if (m.shape != (2, 2) or not np.all(np.isfinite(m)) or np.any(m < 0) or np.any(m > 1)
                or not np.allclose(m.sum(axis=1), 1.0, atol=1e-9) or not m[0, 0] + m[1, 1] > 1.0):
            raise ValueError("EstimatorConfig.imm_transition must be a 2x2 Markov matrix (rows summing to 1, "
                             f"stay probabilities summing to more than 1), got {self.imm_transition!r}")


def _f_block(order: int, h: float) -> np.ndarray:
    """Per-axis transition over ``h`` of a chain of ``order`` integrators (pos, vel[, acc])."""
    block = np.eye(order)
    for i in range(1, order):
        for j in range(order - i):
            block[j, j + i] = h**i / math.factorial(i)
    return block


def _q_block(order: int, h: float, var: float) -> np.ndarray:
    """Per-axis process noise over ``h``: the highest derivative's derivative is white and held over the step
    (piecewise constant), variance ``var``. Order 2 (cv: white acceleration, G = [h^2/2, h]) is filterpy's
    ``Q_discrete_white_noise(dim=2)``, bit for bit (``TargetFilter``'s cv). Order 3 (ca: white jerk, G = [h^3/6,
    h^2/2, h]) is *not* filterpy's ``dim=3``, whose noise is an acceleration increment per step (var * 1 on the
    acceleration whatever h: it would not scale with a variable dt, and ``TargetFilter``'s ca with 2 m/s^2 per
    10 ms step is a 200 m/s^3 jerk)."""
    if order == 2:  # the exact expressions of Q_discrete_white_noise(dim=2): TargetFilter's Q to the bit
        return np.array([[0.25 * h**4, 0.5 * h**3], [0.5 * h**3, h**2]]) * var
    g = np.array([h**3 / 6.0, h**2 / 2.0, h])
    return np.outer(g, g) * var


class _KF(KalmanFilter):
    """filterpy's KalmanFilter with a closed-form log-likelihood (its update already has S and S^-1; the stock
    property calls scipy's multivariate_normal, ~10x slower). Used by the IMM's mode update."""

    @property
    def log_likelihood(self):
        if self._log_likelihood is None:
            y = self.y.ravel()
            _, logdet = np.linalg.slogdet(self.S)
            self._log_likelihood = -0.5 * (float(y @ self.SI @ y) + logdet + y.size * _LOG_2PI)
        return self._log_likelihood


class _Pred(NamedTuple):
    """A state propagated to a measurement time: the model's state and the combined mean / covariance (gate)."""

    state: tuple
    x: np.ndarray
    P: np.ndarray


def turn_extrapolate(x: np.ndarray, taus: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions and velocities (N, 3) ``taus`` (N,) ahead of a [pos, vel, acc] state, as a *coordinated turn*:
    the acceleration's part across the velocity turns the velocity at ``omega = |a_perp| / |v|`` about
    ``v x a_perp`` (a circle), the part along it speeds the target up or down (a parabola; weighted by how much of
    the acceleration is along the velocity, see the comment in the body). For a target on a circle
    the polynomial ``p + v t + a t^2 / 2`` leaves the circle along a parabola (40 mm off after 200 ms at 0.4 m/s on
    an 8 cm circle); this stays on it. Below 2 cm/s, or when the turn rate would exceed 20 rad/s, the polynomial."""
    p, v, a = x[:3], x[3:6], x[6:9]
    taus = np.asarray(taus, dtype=float)
    speed = float(np.linalg.norm(v))
    if speed < 0.02:
        return (p + np.multiply.outer(taus, v) + np.multiply.outer(0.5 * taus**2, a),
                v + np.multiply.outer(taus, a))
    v_hat = v / speed
    a_along = float(a @ v_hat)
    a_perp = a - a_along * v_hat
    # On a turn, the CA filter's acceleration lags the true (rotating) one by a phase phi (0.45 rad on the 0.4 m/s,
    # 8 cm circle at 100 Hz): its along-track part, |a| sin(phi), is mostly that lag, not a speed change, and as a
    # parabola it left the circle by 60 mm in 0.4 s (the MPC's preview). It is trusted as far as the acceleration
    # is along the velocity: scaled by cos^2 of their angle (a speeding-up line keeps it, a circle drops ~80 %).
    a_sq = float(a @ a)
    a_par = (a_along * (a_along * a_along / a_sq) if a_sq > 0.0 else 0.0) * v_hat
    omega = float(np.linalg.norm(a_perp)) / speed
    if omega < 1e-6 or omega > 20.0:
        return (p + np.multiply.outer(taus, v) + np.multiply.outer(0.5 * taus**2, a),
                v + np.multiply.outer(taus, a))
    wt = omega * taus
    sin_w, cos_w = np.sin(wt), np.cos(wt)
    pos = (p + np.multiply.outer(sin_w / omega, v) + np.multiply.outer((1.0 - cos_w) / omega**2, a_perp)
           + np.multiply.outer(0.5 * taus**2, a_par))
    vel = np.multiply.outer(cos_w, v) + np.multiply.outer(sin_w / omega, a_perp) + np.multiply.outer(taus, a_par)
    return pos, vel


class _Linear:
    """One filterpy KalmanFilter, cv (6 states) or ca (9). State: (x, P)."""

    def __init__(self, config: EstimatorConfig) -> None:
        self.config = config
        self.order = 2 if config.model == "cv" else 3
        dim = 3 * self.order
        kf = KalmanFilter(dim_x=dim, dim_z=3)
        kf.H = np.hstack([np.eye(3), np.zeros((3, dim - 3))])
        kf.R = np.eye(3) * config.meas_noise_m**2
        self.kf = kf
        self.var = (config.accel_noise_m_s2 if self.order == 2 else config.jerk_noise_m_s3) ** 2
        self._fq: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def _mats(self, h: float) -> tuple[np.ndarray, np.ndarray]:
        key = round(h * 1e12)  # h to the picosecond: regular stamps (k * dt, float-jittered) share one entry
        got = self._fq.get(key)
        if got is None:
            if len(self._fq) > 256:
                self._fq.clear()
            eye = np.eye(3)
            got = (np.kron(_f_block(self.order, h), eye), np.kron(_q_block(self.order, h, self.var), eye))
            self._fq[key] = got
        return got

    def init_state(self, z: np.ndarray) -> tuple:
        c = self.config
        dim = 3 * self.order
        x = np.zeros(dim)
        x[:3] = z
        P = np.eye(dim)
        P[:3, :3] *= c.meas_noise_m**2
        P[3:6, 3:6] *= c.init_vel_std_m_s**2
        if self.order == 3:
            P[6:9, 6:9] *= c.init_acc_std_m_s2**2
        return (x, P)

    def predict(self, state: tuple, steps: list[tuple[float, bool]]) -> _Pred:
        kf = self.kf
        kf.x, kf.P = state
        for h, drop_motion in steps:
            if drop_motion:
                kf.x = np.concatenate([kf.x[:3], np.zeros(kf.x.size - 3)])
            F, Q = self._mats(h)
            kf.predict(F=F, Q=Q)
        return _Pred((kf.x, kf.P), kf.x, kf.P)

    def update(self, pred: _Pred, z: np.ndarray) -> tuple:
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


class _IMM:
    """filterpy IMMEstimator over a CV and a CA KalmanFilter sharing a 9-dim state. State: (x_cv, P_cv, x_ca, P_ca,
    mu) with mu the mode probabilities (cv, ca)."""

    def __init__(self, config: EstimatorConfig) -> None:
        self.config = config
        R = np.eye(3) * config.meas_noise_m**2
        H = np.hstack([np.eye(3), np.zeros((3, 6))])
        filters = []
        for _ in range(2):
            kf = _KF(dim_x=9, dim_z=3)
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
        self._mats_cache: dict[int, tuple] = {}

    def _mats(self, h: float) -> tuple:
        key = round(h * 1e12)
        got = self._mats_cache.get(key)
        if got is None:
            if len(self._mats_cache) > 256:
                self._mats_cache.clear()
            eye = np.eye(3)
            f_cv = np.zeros((3, 3))
            f_cv[:2, :2] = _f_block(2, h)  # acceleration -> 0: the CV hypothesis
            q_cv = np.zeros((3, 3))
            q_cv[:2, :2] = _q_block(2, h, self.var_a)
            s = h / self.config.dt_s  # the Markov matrix per dt_s, raised to the power h / dt_s
            if abs(s - 1.0) < 1e-9:
                m = self.M.copy()
            else:  # M^s = 1 pi + lam^s (I - 1 pi), lam = p + q - 1 the second eigenvalue, pi the stationary row
                stationary = np.outer(np.ones(2), self.mu0)
                m = stationary + (self._lam**s if self._lam < 1.0 else 1.0) * (np.eye(2) - stationary)
            got = (np.kron(f_cv, eye), np.kron(q_cv, eye), np.kron(_f_block(3, h), eye),
                   np.kron(_q_block(3, h, self.var_j), eye), m)
            self._mats_cache[key] = got
        return got

    def init_state(self, z: np.ndarray) -> tuple:
        c = self.config
        x = np.zeros(9)
        x[:3] = z
        P = np.eye(9)
        P[:3, :3] *= c.meas_noise_m**2
        P[3:6, 3:6] *= c.init_vel_std_m_s**2
        P[6:9, 6:9] *= c.init_acc_std_m_s2**2
        return (x, P, x.copy(), P.copy(), self.mu0.copy())

    def _load(self, state: tuple) -> None:
        cv, ca = self.imm.filters
        cv.x, cv.P, ca.x, ca.P, mu = state
        self.imm.mu = mu.copy()

    def predict(self, state: tuple, steps: list[tuple[float, bool]]) -> _Pred:
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
        return _Pred((cv.x, cv.P, ca.x, ca.P, mu.copy()), x, P)

    def update(self, pred: _Pred, z: np.ndarray) -> tuple:
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


class _CTKF(_KF):
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


class _TurnIMM:
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
            kf = _CTKF(dim_x=_CT_DIM, dim_z=3) if mode == "ct" else _KF(dim_x=_CT_DIM, dim_z=3)
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
        self._mats_cache: dict[int, tuple] = {}

    def _markov(self, s: float) -> np.ndarray:
        n = len(self.modes)
        lam_s = self._lam**s if self._lam < 1.0 else 1.0
        return lam_s * np.eye(n) + (1.0 - lam_s) / n * np.ones((n, n))

    def _mats(self, h: float) -> tuple:
        """Per mode (F, Q) for ``h`` (F None for the CT EKF: it has its own), and the Markov matrix for ``h``."""
        key = round(h * 1e12)
        got = self._mats_cache.get(key)
        if got is None:
            if len(self._mats_cache) > 256:
                self._mats_cache.clear()
            eye = np.eye(3)
            q_w = h * h * self.var_w
            per_mode = []
            for mode in self.modes:
                F, Q = np.eye(_CT_DIM), np.zeros((_CT_DIM, _CT_DIM))
                if mode == "cv":
                    f = np.zeros((3, 3))
                    f[:2, :2] = _f_block(2, h)  # acceleration -> 0
                    q = np.zeros((3, 3))
                    q[:2, :2] = _q_block(2, h, self.var_a)
                    F[:9, :9], Q[:9, :9] = np.kron(f, eye), np.kron(q, eye)
                    Q[9, 9] = q_w
                elif mode == "ca":
                    F[:9, :9], Q[:9, :9] = np.kron(_f_block(3, h), eye), np.kron(_q_block(3, h, self.var_j), eye)
                    Q[9, 9] = q_w
                else:
                    F, Q = None, ct_process_noise(h, self.var_ct, self.var_w)
                per_mode.append((F, Q))
            got = (tuple(per_mode), self._markov(h / self.config.dt_s))
            self._mats_cache[key] = got
        return got

    def init_state(self, z: np.ndarray) -> tuple:
        c = self.config
        x = np.zeros(_CT_DIM)
        x[:3] = z
        P = np.eye(_CT_DIM)
        P[:3, :3] *= c.meas_noise_m**2
        P[3:6, 3:6] *= c.init_vel_std_m_s**2
        P[6:9, 6:9] *= c.init_acc_std_m_s2**2
        P[9, 9] = c.init_turn_std_rad_s**2
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

    def _set_step(self, h: float) -> np.ndarray:
        per_mode, m = self._mats(h)
        for f, (F, Q) in zip(self.filters, per_mode):
            if F is None:
                f.h = h
            else:
                f.F = F
            f.Q = Q
        return m

    def _combined(self, xs, Ps, mu) -> tuple[np.ndarray, np.ndarray]:
        x = sum(w * xi for w, xi in zip(mu, xs))
        P = sum(w * (np.outer(xi - x, xi - x) + Pi) for w, xi, Pi in zip(mu, xs, Ps))
        return x, P

    def predict(self, state: tuple, steps: list[tuple[float, bool]]) -> _Pred:
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
        return _Pred((xs, Ps, mu), x, P)

    def update(self, pred: _Pred, z: np.ndarray) -> tuple:
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


class _Entry(NamedTuple):
    """A processed measurement in the history: capture time, value, the estimator just before it, and the capture
    time of the measurement processed before it (a roll-back to this entry is valid only for later captures)."""

    t_s: float
    z: np.ndarray
    before: tuple
    t_prev_s: float


class TargetEstimator:
    """3-D target tracker with latency-aware, out-of-order-safe fusion.

    ``fuse(t_capture, z)`` whenever a measurement arrives (stamped with its capture time); ``step(t, z)`` is the
    zero-latency ``TargetFilter`` contract; ``predict_pos(t)`` any time."""

    def __init__(self, config: EstimatorConfig = EstimatorConfig()) -> None:
        self.config = config
        if config.model == "imm":
            self._model = _IMM(config)
        elif config.model in ("ct", "imm-ct"):
            self._model = _TurnIMM(config)
        else:
            self._model = _Linear(config)
        self._state: tuple | None = None
        self._R = np.eye(3) * config.meas_noise_m**2
        self.initialized = False
        self.t_s = 0.0  # the last fused capture time: the time of the state
        self.resets = 0
        self.missed = 0
        self.fused = 0
        self.gated_nonfinite = 0
        self.gated_frozen = 0
        self.gated_outlier = 0
        self.coasts = 0
        self.dropped_old = 0  # out-of-order measurements older than history_s (or than the stored history)
        self.reordered = 0  # out-of-order measurements re-fused in capture order
        self._gated = 0
        self._last_gated: np.ndarray | None = None
        self._gated_since_s = 0.0
        self._last_z: np.ndarray | None = None
        self._clock_s = -math.inf  # the newest time seen (fused, gated or missed): decides the coast
        self._coast_counted_for: float | None = None
        self._history: list[_Entry] = []
        #: the last confirmed jump: capture time of its first measurement, of the re-initialisation, and where
        self.jump_started_s: float | None = None
        self.reset_at_s: float | None = None
        self.reset_pos_m: np.ndarray | None = None

    # ---- counters and estimates --------------------------------------------------------
    @property
    def gated(self) -> int:
        """Measurements rejected by the gate (non-finite, frozen, outlier)."""
        return self.gated_nonfinite + self.gated_frozen + self.gated_outlier

    @property
    def pos_m(self) -> np.ndarray:
        """Position estimate at the last fused capture time ``t_s``."""
        return self._model.mean(self._state)[:3].copy() if self._state is not None else np.zeros(3)

    @property
    def vel_m_s(self) -> np.ndarray:
        """Velocity estimate at ``t_s`` (zero while coasting)."""
        if self._state is None or self._coasting():
            return np.zeros(3)
        return self._model.mean(self._state)[3:6].copy()

    @property
    def mode_probs(self) -> np.ndarray | None:
        """IMM mode probabilities at ``t_s``: (p_cv, p_ca) for imm, (p_cv, p_ca, p_ct) for imm-ct; None for the
        single models."""
        return None if self._state is None else self._model.mode_probs(self._state)

    @property
    def history_len(self) -> int:
        return len(self._history)

    # ---- fusion ------------------------------------------------------------------------
    def step(self, t_s: float, z_m: np.ndarray | None) -> str:
        """The zero-latency ``TargetFilter.step`` contract: ``fuse(t_s, z_m)``."""
        return self.fuse(t_s, z_m)

    def fuse(self, t_capture_s: float, z_m: np.ndarray | None) -> str:
        """Fuse a measurement of the target as it was at ``t_capture_s`` (it may arrive late).

        Returns what happened: ``"missed"`` (None), ``"nonfinite"``/``"frozen"``/``"outlier"`` (gated, counted),
        ``"dropped"`` (out of order and older than ``history_s``: counted in ``dropped_old``), ``"reset"`` (a
        confirmed jump: re-initialised), ``"init"`` or ``"fused"``. An out-of-order measurement within
        ``history_s`` returns its own outcome after the later ones were re-fused. Never raises on a bad value."""
        try:
            t = float(t_capture_s)
        except (TypeError, ValueError):
            t = math.nan
        if not math.isfinite(t):
            self.gated_nonfinite += 1
            return "nonfinite"
        self._advance_clock(t)
        if z_m is None:
            if self.initialized:
                self.missed += 1
            return "missed"
        before = self.gated_nonfinite
        z = self._screen(z_m)
        if z is None:
            return "nonfinite" if self.gated_nonfinite > before else "frozen"
        hist = self._history
        if not hist or t >= hist[-1].t_s:
            return self._record_and_process(t, z)
        # out of order: roll back to the state before the first later measurement, re-fuse in capture order
        k = bisect_right([e.t_s for e in hist], t)
        if hist[-1].t_s - t > self.config.history_s or hist[k].t_prev_s > t:
            self.dropped_old += 1
            return "dropped"
        self.reordered += 1
        later = hist[k:]
        del hist[k:]
        self._restore(later[0].before)
        status = self._record_and_process(t, z)
        for e in later:
            self._record_and_process(e.t_s, e.z)
        return status

    def _screen(self, z_m) -> np.ndarray | None:
        """The measurement as a (3,) array if it passes the non-finite and frozen gates, else None (counted).
        The frozen gate compares with the previous measurement in arrival order (a stalled driver re-sends)."""
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
        self._last_z = z.copy()
        return self._last_z

    def _advance_clock(self, t: float) -> None:
        if t > self._clock_s:
            self._clock_s = t
        if self._coasting() and self._coast_counted_for != self.t_s:
            mean = self._model.mean(self._state)
            if np.any(mean[3:]):  # as TargetFilter: a coast of an estimate that has motion
                self.coasts += 1
            self._coast_counted_for = self.t_s

    def _coasting(self) -> bool:
        return self.initialized and self._clock_s - self.t_s > self.config.coast_s

    def _record_and_process(self, t: float, z: np.ndarray) -> str:
        hist = self._history
        hist.append(_Entry(t, z, self._save(), hist[-1].t_s if hist else -math.inf))
        status = self._process(t, z)
        horizon = t - self.config.history_s
        drop = 0
        while drop < len(hist) - 1 and hist[drop].t_s < horizon:
            drop += 1
        if drop:
            del hist[:drop]
        return status

    def _save(self) -> tuple:
        return (self._state, self.initialized, self.t_s, self._gated, self._last_gated, self._gated_since_s,
                self.fused, self.gated_outlier, self.resets, self.jump_started_s, self.reset_at_s, self.reset_pos_m)

    def _restore(self, snap: tuple) -> None:
        (self._state, self.initialized, self.t_s, self._gated, self._last_gated, self._gated_since_s, self.fused,
         self.gated_outlier, self.resets, self.jump_started_s, self.reset_at_s, self.reset_pos_m) = snap

    def _init_on(self, t: float, z: np.ndarray) -> None:
        self._state = self._model.init_state(z)
        self.t_s = t
        self.initialized = True
        self._gated = 0
        self._last_gated = None

    def _steps(self, t: float) -> list[tuple[float, bool]]:
        """The propagation from ``t_s`` to ``t``: (dt, drop the motion estimate first) per step. Past ``coast_s``
        without a fused measurement the motion estimate is dropped at ``t_s + coast_s``."""
        gap = t - self.t_s
        coast = self.config.coast_s
        if gap <= coast:
            return [(h, False) for h in self._split(gap)]
        steps = [(h, False) for h in self._split(coast)]
        rest = self._split(gap - coast)
        return steps + [(rest[0], True)] + [(h, False) for h in rest[1:]]

    def _split(self, gap: float) -> list[float]:
        """``gap`` in steps of at most ``dt_s``: one step up to dt_s, whole periods plus a remainder beyond (a
        regular stream's multiple of dt_s: equal steps, as a tick-by-tick filter would take)."""
        dt = self.config.dt_s
        n = int(gap / dt + 1e-6)
        if n <= 1 and gap <= dt * (1 + 1e-6):
            return [gap]
        if n >= _MAX_SUBSTEPS:
            return [gap / _MAX_SUBSTEPS] * _MAX_SUBSTEPS
        rem = gap - n * dt
        if rem <= 1e-6 * dt:
            return [gap / n] * n
        return [dt] * n + [rem]

    def _process(self, t: float, z: np.ndarray) -> str:
        """``TargetFilter.step``'s gate and update for a screened measurement, in capture order."""
        if not self.initialized:
            self._init_on(t, z)
            return "init"
        c = self.config
        pred = self._model.predict(self._state, self._steps(t))
        y = z - pred.x[:3]
        S = pred.P[:3, :3] + self._R
        d2 = float(y @ np.linalg.solve(S, y))
        if d2 > c.reset_gate:
            agrees = self._last_gated is not None and np.linalg.norm(z - self._last_gated) <= c.jump_agree_m
            self._gated = self._gated + 1 if (agrees or self._gated == 0) else 1
            if self._gated == 1:
                self._gated_since_s = t
            self._last_gated = z
            if self._gated >= c.reset_after:
                self.resets += 1
                self.jump_started_s, self.reset_at_s = self._gated_since_s, t
                self._init_on(t, z)
                self.reset_pos_m = z.copy()
                return "reset"
            self.gated_outlier += 1
            return "outlier"
        self._gated = 0
        self._last_gated = None
        self._state = self._model.update(pred, z)
        self.t_s = t
        self.fused += 1
        return "fused"

    # ---- prediction --------------------------------------------------------------------
    def _taus(self, times_s) -> np.ndarray:
        taus = np.asarray(times_s, dtype=float) - self.t_s
        if self._coasting():  # the motion estimate was dropped at t_s + coast_s: the target stands there
            taus = np.minimum(taus, self.config.coast_s)
        return taus

    def predict_pos(self, t_s: float) -> np.ndarray:
        """Predicted position at ``t_s`` (normally >= ``t_s`` of the state: now, or later), with the model (imm: the
        mode-probability-weighted extrapolation)."""
        if self._state is None:
            return np.zeros(3)
        return self._model.extrapolate(self._state, self._taus(np.array([t_s])))[0]

    def predict_pos_many(self, times_s: np.ndarray) -> np.ndarray:
        """Predicted positions (N, 3) at ``times_s`` (N,): :meth:`predict_pos`, vectorized."""
        times = np.asarray(times_s, dtype=float).reshape(-1)
        if self._state is None:
            return np.zeros((times.size, 3))
        return self._model.extrapolate(self._state, self._taus(times))

    def predict_vel(self, t_s: float) -> np.ndarray:
        """Predicted velocity at ``t_s`` (ca/imm: with the acceleration; zero while coasting)."""
        if self._state is None or self._coasting():
            return np.zeros(3)
        return self._model.extrapolate_vel(self._state, np.array([float(t_s) - self.t_s]))[0]

    def filtered_at(self, t_s: float) -> np.ndarray | None:
        """The estimate of the position at ``t_s`` from the measurements *captured* up to ``t_s`` only, as known now:
        with a sensor latency, the estimate taken at ``t_s`` itself had to extrapolate over the latency, this one
        (from the history) did not. None when the history does not reach back to ``t_s`` or no estimate existed then;
        the current estimate extrapolated when every stored capture is at or before ``t_s``."""
        for entry in self._history:
            if entry.t_s > t_s:
                state, initialized, t_state = entry.before[0], entry.before[1], entry.before[2]
                if not initialized or state is None or t_state > t_s:
                    return None
                return self._model.extrapolate(state, np.array([t_s - t_state]))[0]
        return self.predict_pos(t_s) if self.initialized else None

    def estimate_at_observation(self, t0_s: float, recorded_m: np.ndarray | None) -> np.ndarray | None:
        """The best estimate of where the target was at an observation time ``t0_s``, given what is known now
        (``TargetFilter.estimate_at_observation``'s semantics, on capture times).

        ``recorded_m`` is the estimate taken at ``t0_s``. If a jump confirmed since then had already begun at
        ``t0_s`` (its first measurement was captured at or before it), the recorded estimate predates the
        estimator's knowledge of a jump the observation already saw: the post-jump position is returned instead."""
        if (recorded_m is None or self.jump_started_s is None or self.reset_at_s is None
                or not (self.jump_started_s - 0.5 * self.config.dt_s <= t0_s < self.reset_at_s)):
            return recorded_m
        return self.reset_pos_m.copy()
