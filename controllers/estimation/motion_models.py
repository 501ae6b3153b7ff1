"""What a motion model is to the estimator (:class:`MotionModel`), and the one per configuration
(:func:`make_motion_model`).

A model owns no estimate: it turns states into states. A state is an opaque tuple of arrays (the model's filters'
means and covariances, and the IMMs' mode probabilities) that the estimator stores, snapshots into its history and
hands back; the model's filterpy objects are scratch space loaded from it on every call.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from controllers.estimation.config import EstimatorConfig
from controllers.estimation.imm_model import CvCaIMM
from controllers.estimation.kalman_blocks import Prediction
from controllers.estimation.linear_model import LinearModel
from controllers.estimation.turn_imm_model import TurnIMM


class MotionModel(Protocol):
    """The interface of :class:`~controllers.estimation.linear_model.LinearModel` (cv, ca),
    :class:`~controllers.estimation.imm_model.CvCaIMM` (imm) and
    :class:`~controllers.estimation.turn_imm_model.TurnIMM` (ct, imm-ct)."""

    def init_state(self, z: np.ndarray) -> tuple:
        """The state on one measured position ``z`` (3,) m: there, at rest, with the initial uncertainty."""

    def predict(self, state: tuple, steps: list[tuple[float, bool]]) -> Prediction:
        """``state`` propagated over ``steps``: (step length s, drop the motion estimate before it) each."""

    def update(self, pred: Prediction, z: np.ndarray) -> tuple:
        """The predicted state updated with a measured position ``z`` (3,) m."""

    def mean(self, state: tuple) -> np.ndarray:
        """The (mode-probability-weighted) mean: [pos m, vel m/s, ...]."""

    def extrapolate(self, state: tuple, taus: np.ndarray) -> np.ndarray:
        """Positions (N, 3) m ``taus`` (N,) s after the state's time (mean only)."""

    def extrapolate_vel(self, state: tuple, taus: np.ndarray) -> np.ndarray:
        """Velocities (N, 3) m/s ``taus`` (N,) s after the state's time."""

    def mode_probs(self, state: tuple) -> np.ndarray | None:
        """The IMM mode probabilities, or None for a single model."""


def make_motion_model(config: EstimatorConfig) -> MotionModel:
    """The model ``config.model`` names."""
    if config.model == "imm":
        return CvCaIMM(config)
    if config.model in ("ct", "imm-ct"):
        return TurnIMM(config)
    return LinearModel(config)
