"""The estimator's configuration: :class:`EstimatorConfig` (frozen) and the model names :data:`FILTER_MODELS`."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: the motion models: constant velocity, constant acceleration, their IMM, the coordinated turn, the IMM of all three
FILTER_MODELS = ("cv", "ca", "imm", "ct", "imm-ct")

_POSITIVE_FIELDS = ("dt_s", "meas_noise_m", "accel_noise_m_s2", "jerk_noise_m_s3", "imm_accel_noise_m_s2",
                    "init_vel_std_m_s", "init_acc_std_m_s2", "reset_gate", "jump_agree_m", "coast_s",
                    "ct_accel_noise_m_s2", "ct_turn_noise_rad_s2", "init_turn_std_rad_s")


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
    init_acc_std_m_s2: initial acceleration standard deviation (ca, imm), m/s^2.
    history_s: how far back (capture time, behind the newest processed measurement) an out-of-order measurement
        is still re-fused; older ones are dropped and counted. 0 drops every out-of-order measurement, s.
    reset_gate: squared Mahalanobis distance of an innovation above which a measurement is gated as an outlier
        (or counted towards a jump), dimensionless.
    reset_after: consecutive gated measurements, each agreeing with the previous, that confirm a jump and
        re-initialise the estimator on the last of them.
    jump_agree_m: how close consecutive gated measurements must be to count as one new position (a jump), m.
    frozen_gate: gate bit-identical repeats (a noisy sensor never repeats; a stalled driver re-sends its last
        value); switch it off for a noise-free simulated sensor, whose measurements of a static target repeat.
    coast_s: after this long without a fused measurement the motion estimate (velocity, acceleration, turn rate)
        is dropped: the target is taken to stand where it was last estimated instead of being extrapolated for
        seconds (a frozen or blinded sensor), s.
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
        for name in _POSITIVE_FIELDS:
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"EstimatorConfig.{name} must be a finite number > 0, got {value!r}")
        if not (isinstance(self.history_s, (int, float)) and math.isfinite(self.history_s) and self.history_s >= 0):
            raise ValueError(f"EstimatorConfig.history_s must be a finite number >= 0, got {self.history_s!r}")
        if not (isinstance(self.imm_ct_stay, (int, float)) and 1.0 / 3.0 < self.imm_ct_stay <= 1.0):
            raise ValueError(f"EstimatorConfig.imm_ct_stay must be a probability in (1/3, 1], got {self.imm_ct_stay!r}")
        if not isinstance(self.reset_after, int) or self.reset_after < 1:
            raise ValueError(f"EstimatorConfig.reset_after must be an integer >= 1, got {self.reset_after!r}")
        if not _is_two_mode_markov(self.imm_transition):
            raise ValueError("EstimatorConfig.imm_transition must be a 2x2 Markov matrix (rows summing to 1, "
                             f"stay probabilities summing to more than 1), got {self.imm_transition!r}")


def _is_two_mode_markov(matrix) -> bool:
    """A 2x2 row-stochastic matrix whose stay probabilities sum to more than 1 (its powers stay positive)."""
    try:
        m = np.asarray(matrix, dtype=float)
    except (TypeError, ValueError):
        return False
    return bool(m.shape == (2, 2) and np.all(np.isfinite(m)) and np.all(m >= 0) and np.all(m <= 1)
                and np.allclose(m.sum(axis=1), 1.0, atol=1e-9) and m[0, 0] + m[1, 1] > 1.0)
