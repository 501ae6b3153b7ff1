"""The target estimator's public names, where the rest of the stack imports them from; the code lives in
:mod:`controllers.estimation` (one file per job: config, motion models, fusion with latency, gates, jumps)."""

from controllers.estimation import FILTER_MODELS, EstimatorConfig, TargetEstimator, turn_extrapolate

__all__ = ["FILTER_MODELS", "EstimatorConfig", "TargetEstimator", "turn_extrapolate"]
