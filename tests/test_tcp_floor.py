"""The TCP floor: no mode asks the fingers into the table, whatever the chunk source aims at (MuJoCo in the loop)."""

from __future__ import annotations

import numpy as np
import pytest

from mmact_ctrl.chunk import ActionChunk, Observation
from mmact_ctrl.config import StackConfig
from mmact_ctrl.controller import HybridController
from mmact_ctrl.loop import run_episode
from scenarios.world.factory import make_world


class _IntoTheTable:
    """Chunks that end 5 cm below the table top, under the ball (a badly aimed policy)."""

    needs_image = False

    def plan(self, observation: Observation) -> ActionChunk:
        goal = np.array([observation.target_pos_m[0], observation.target_pos_m[1], -0.05])
        s = np.linspace(1.0 / 16, 1.0, 16)[:, None]
        pos = observation.ee_pos_m + s * (goal - observation.ee_pos_m)
        w = np.hstack([pos, np.zeros((16, 3)), np.full((16, 1), 0.08)])
        return ActionChunk(waypoints=w, dt_s=0.1, t0_s=observation.t0_s)


@pytest.mark.parametrize("mode", ["open_loop", "temporal_ensemble", "hybrid"])
def test_a_chunk_aimed_into_the_table_is_held_above_it(mode):
    world = make_world("static", n_objects=1)
    try:
        cfg = StackConfig(mode=mode, duration_s=3.0, replan_hz=1.0, latency_ms=0.0, bins=0)
        log = run_episode(world, _IntoTheTable(), HybridController(cfg), seed=3)
    finally:
        world.close()
    if mode != "hybrid":  # hybrid retargets the chunk onto the measured ball and never reaches the floor
        assert log.floor_clamps > 0
    assert np.nanmin(log.ref_pos_m[:, 2]) >= cfg.tcp_floor_m - 1e-9
    settled = log.t_s > 2.0  # the arm has come down to the floor and stays there, above the table
    assert np.min(log.ee_pos_m[:, 2]) > 0.02
    if mode != "hybrid":
        assert np.all(np.abs(log.ee_pos_m[settled, 2] - cfg.tcp_floor_m) < 0.02)
    assert sum(log.safety_counts.values()) == 0, log.safety_counts


def test_a_bad_tcp_floor_is_refused_by_name():
    with pytest.raises(ValueError, match="tcp_floor_m"):
        StackConfig(tcp_floor_m=float("nan"))
