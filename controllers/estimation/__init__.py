"""Target estimation: a latency-aware 3-D target tracker (:class:`TargetEstimator`) for the 100 Hz target
measurements, predicting where the target is now (or at any later time) for the 1 kHz control layers.

1. **latency-aware fusion**: ``fuse(t_capture_s, z)`` takes a measurement of the target *as it was* at its capture
   time, however late it arrives, and re-fuses out-of-order ones in capture order (:mod:`.estimator`,
   :mod:`.history`, :mod:`.propagation`).
2. **a model that follows curving motion**: ``"ca"`` (constant acceleration, white jerk; :mod:`.linear_model`) or
   ``"imm"``, an interacting-multiple-model estimator of a constant-velocity and a constant-acceleration Kalman
   filter (:mod:`.imm_model`), whose CA prediction bends along a turn (:mod:`.turn_extrapolation`).
3. **a model of the turn itself**: ``"ct"``, a coordinated-turn EKF, and ``"imm-ct"``, the IMM of CV, CA and CT
   (:mod:`.turn_imm_model`; the CT model itself is :mod:`controllers.coordinated_turn`).

The gates (non-finite, frozen, outlier; :mod:`.gates`) and jumps (agreeing outliers re-initialise the estimator;
:mod:`.jumps`) are the fixed-step reference filter's (``tests/reference_target_filter.py``), with the same status
strings and counters, plus ``"dropped"`` (older than ``history_s``) and the counters ``dropped_old`` and
``reordered``. The configuration: :class:`EstimatorConfig` (:mod:`.config`).

With ``model="cv"`` and zero latency, ``step(t, z)`` reproduces the reference filter's ``step`` to rounding (1e-9)
on any 100 Hz stream, dropouts and gated measurements included: a gap longer than ``dt_s`` between fused captures is
propagated in sub-steps of at most ``dt_s`` (the piecewise-constant white-noise Q is defined per hold period: one Q
over a 0.3 s dropout would not be the tick-by-tick filter's). Where it deliberately differs from the reference:
``pos_m``/``vel_m_s``/``t_s`` are the estimate at the last *fused* capture time (the reference moves them to every
step's time; ``predict_pos(t)`` agrees), and the coast after ``coast_s`` without a fused measurement drops the
motion estimate exactly at ``t_s + coast_s`` (the reference: at the first step past it, up to one period later).
Model ``"ca"`` has a white jerk in m/s^3 as its process noise (:func:`.kalman_blocks.q_block`) and ``predict_pos``
extrapolates with the acceleration.

Imports numpy, filterpy and the standard library only (it runs on a real arm).
"""

from controllers.estimation.config import FILTER_MODELS, EstimatorConfig
from controllers.estimation.estimator import TargetEstimator
from controllers.estimation.turn_extrapolation import turn_extrapolate

__all__ = ["FILTER_MODELS", "EstimatorConfig", "TargetEstimator", "turn_extrapolate"]
