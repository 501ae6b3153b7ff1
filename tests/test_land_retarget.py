"""``land`` retargeting in the loop: a chunk source that aims beside the ball and keeps heading there, replanned at
5 Hz with 200 ms latency, does not push the arm off the ball (MuJoCo in the loop)."""

from __future__ import annotations

import numpy as np
import pytest

from controllers.retarget import RetargetConfig
from mmact_ctrl.chunk import ActionChunk, Observation
from mmact_ctrl.config import StackConfig
from mmact_ctrl.controller import HybridController
from mmact_ctrl.loop import run_episode
from mmact_ctrl.metrics import episode_metrics
from scenarios.factory import make_world

AIM_ERROR_M = np.array([0.0, 0.06, 0.0])


class _AimsBeside:
    """Chunks from the TCP to 6 cm beside the ball, coming to rest there (smoothstep): a badly aimed policy."""

    needs_image = False

    def plan(self, observation: Observation) -> ActionChunk:
        goal = np.asarray(observation.target_pos_m) + AIM_ERROR_M
        u = np.linspace(1.0 / 16, 1.0, 16)[:, None]
        s = 3 * u**2 - 2 * u**3
        pos = observation.ee_pos_m + s * (goal - observation.ee_pos_m)
        w = np.hstack([pos, np.zeros((16, 3)), np.full((16, 1), 0.08)])
        return ActionChunk(waypoints=w, dt_s=0.1, t0_s=observation.t0_s)


def _run(rule: str) -> dict:
    world = make_world("static", n_objects=1)
    try:
        cfg = StackConfig(mode="hybrid", duration_s=4.0, replan_hz=5.0, latency_ms=200.0, bins=0,
                          retarget=RetargetConfig(rule=rule))
        return episode_metrics(run_episode(world, _AimsBeside(), HybridController(cfg), seed=2))
    finally:
        world.close()


def test_land_holds_the_ball_where_snap_leaves_the_rest_of_a_wrong_approach_in_the_reference():
    land, snap = _run("land"), _run("snap")
    assert land["success"] and land["final_error_m"] < 0.015, land["final_error_m"]
    assert land["tracking_ratio"] > 0.6, land["tracking_ratio"]
    # snap keeps the chunk's remaining path to its (wrong) aim at every 5 Hz replan: pushed off the ball
    assert snap["final_error_m"] > 0.03, snap["final_error_m"]
    assert land["tracking_ratio"] > snap["tracking_ratio"] + 0.2
    for m in (land, snap):
        assert m["limit_violations"] == 0 and m["qp_failures"] == 0


def test_an_unknown_rule_is_refused_by_name():
    with pytest.raises(ValueError, match="teleport"):
        RetargetConfig(rule="teleport")
