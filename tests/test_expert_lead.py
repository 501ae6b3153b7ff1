"""The leading expert: two frames, a velocity estimate, each waypoint aimed where the target will be."""

from __future__ import annotations

import numpy as np
import pytest

from mmact_ctrl.chunk import Observation
from mmact_ctrl.config import StackConfig
from mmact_ctrl.controller import HybridController
from mmact_ctrl.loop import run_episode
from mmact_ctrl.metrics import episode_metrics
from mmact_ctrl.reference import ChunkReference
from scenarios.world.expert import ExpertConfig, ScriptedExpert
from scenarios.world.factory import make_expert, make_world


def _obs(target, prev, gap=0.1, ee=(0.3, 0.0, 0.5)):
    z = np.zeros(7)
    return Observation(t0_s=1.0, q_rad=z, dq_rad_s=z, ee_pos_m=np.array(ee), ee_rotvec_rad=np.zeros(3), gripper_m=0.08,
                       target_pos_m=np.array(target), target_prev_pos_m=None if prev is None else np.array(prev),
                       frame_gap_s=gap)


def test_the_tail_of_a_leading_chunk_runs_on_the_targets_course():
    expert = ScriptedExpert(ExpertConfig(lead="velocity"))
    chunk = expert.plan(_obs([0.5, 0.0, 0.3], [0.48, 0.0, 0.3]))  # 0.2 m/s along x
    times = chunk.times_s - chunk.t0_s
    course = np.array([0.5, 0.0, 0.3]) + times[:, None] * np.array([0.2, 0.0, 0.0])
    np.testing.assert_allclose(chunk.waypoints[-4:, :3], course[-4:], atol=1e-6)  # the approach is over: on course
    assert not ChunkReference(chunk, 1.2, None).at_rest  # hybrid treats it as a leading chunk
    rest = ScriptedExpert(ExpertConfig(lead="none")).plan(_obs([0.5, 0.0, 0.3], [0.48, 0.0, 0.3]))
    np.testing.assert_allclose(rest.waypoints[-1, :3], [0.5, 0.0, 0.3], atol=1e-9)
    assert ChunkReference(rest, 1.2, None).at_rest


def test_a_jump_between_the_frames_is_not_a_velocity_and_walls_reflect_the_lead():
    expert = ScriptedExpert(ExpertConfig(lead="velocity"))
    jumped = expert.plan(_obs([0.5, 0.0, 0.3], [0.35, 0.0, 0.3]))  # 1.5 m/s: a teleport, not a motion
    np.testing.assert_allclose(jumped.waypoints[-1, :3], [0.5, 0.0, 0.3], atol=1e-9)
    boxed = ScriptedExpert(ExpertConfig(lead="velocity", workspace_low_m=(0.35, -0.3, 0.15),
                                        workspace_high_m=(0.65, 0.3, 0.45)))
    chunk = boxed.plan(_obs([0.6, 0.0, 0.3], [0.58, 0.0, 0.3]))  # 0.2 m/s toward the wall at x = 0.65
    assert np.all(chunk.waypoints[:, 0] <= 0.65 + 1e-9)
    np.testing.assert_allclose(chunk.waypoints[-1, 0], 0.65 - (0.6 + 0.2 * 1.6 - 0.65), atol=1e-6)  # bounced back
    with pytest.raises(ValueError, match="lead"):
        ExpertConfig(lead="psychic")


def test_leading_expert_intercepts_a_constant_velocity_target_in_open_loop():
    """Open loop, 1 Hz, 200 ms: the leading chunks end on the target; the single-frame ones trail it."""
    world = make_world(target="linear", speed_m_s=0.2)
    err = {}
    for lead in ("velocity", "none"):
        finals = []
        for seed in range(3):
            ctrl = HybridController(StackConfig(mode="open_loop", duration_s=5.0))
            log = run_episode(world, make_expert(lead=lead, world=world), ctrl, seed=seed)
            finals.append(episode_metrics(log)["final_error_m"])
        err[lead] = float(np.mean(finals))
    assert err["velocity"] < 0.015, err  # stated: within 15 mm of a 0.2 m/s target at the episode's end
    assert err["none"] > 0.05, err
