"""A contact task's fast layer predicts its object reflected at the walls of the carrier's box, as the task's expert's
lead is: the prediction turns where a constant-velocity one runs through the wall; an object the estimate puts outside
the box is not mirrored back in; reach has no box (its stack is as published)."""

from __future__ import annotations

import numpy as np
import pytest

from controllers.estimation.box import BoxedPrediction, fold
from controllers.target_estimator import EstimatorConfig, TargetEstimator
from mmact_ctrl.config import StackConfig
from scenarios.moving_target_args import build_parser, stack_config

LOW, HIGH = (0.35, -0.3, 0.024), (0.6, 0.3, 0.024 + 1e-6)


def _estimator(x0_m: float, vx_m_s: float) -> TargetEstimator:
    est = TargetEstimator(EstimatorConfig())
    for k in range(40):  # 0.4 s of exact 100 Hz measurements
        est.fuse(0.01 * k, np.array([x0_m + vx_m_s * 0.01 * k, 0.0, 0.024]))
    return est


def test_fold_is_a_triangle_wave_with_the_velocitys_sign():
    x, sign = fold(np.array([0.5, 0.65, 0.9, 0.3]), np.array(0.35), np.array(0.6))
    np.testing.assert_allclose(x, [0.5, 0.55, 0.4, 0.4])
    np.testing.assert_array_equal(sign, [1, -1, 1, -1])


def test_the_prediction_turns_at_the_wall_and_the_velocity_with_it():
    est = _estimator(0.5, 0.2)  # at 0.578 m at 0.39 s, heading for the wall at 0.6
    boxed = BoxedPrediction(est, LOW, HIGH)
    t = 0.39 + 0.5
    assert est.predict_pos(t)[0] == pytest.approx(0.678, abs=1e-3)  # through the wall
    assert boxed.predict_pos(t)[0] == pytest.approx(0.522, abs=1e-3)  # turned at it
    assert boxed.predict_vel(t)[0] == pytest.approx(-0.2, abs=1e-3)
    assert boxed.predict_pos(t)[2] == pytest.approx(est.predict_pos(t)[2])  # the box's thin axis is left alone
    many = boxed.predict_pos_many(np.array([0.5, 0.8, 1.0]))
    assert np.all(many[:, 0] <= 0.6 + 1e-12)
    assert boxed.initialized and boxed.gated == est.gated  # the rest is the estimator's


def test_an_object_outside_the_box_is_not_mirrored_back_in():
    est = _estimator(0.7, 0.0)  # pushed off its carrier, resting at 0.7 m
    boxed = BoxedPrediction(est, LOW, HIGH)
    assert boxed.predict_pos(0.5)[0] == pytest.approx(0.7, abs=1e-3)


def test_contact_tasks_give_the_stack_their_box_and_reach_none():
    for task, boxed in (("reach", False), ("pick", True), ("insert", True)):
        cfg = stack_config(build_parser().parse_args(["--task", task]), "hybrid")
        assert (cfg.target_box_m is not None) == boxed
    with pytest.raises(ValueError, match="target_box_m"):
        StackConfig(target_box_m=((0.0, 0.0, 0.0), (0.0, 1.0, 1.0)))
