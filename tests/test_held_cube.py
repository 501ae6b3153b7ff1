"""A cube the fingers have closed on stays held when it sits off the TCP's centre across the fingers: the expert does
not take it for a miss and reopen, and the grasp latch keeps the correction held. On the published reversal run
(hybrid, seeds 1008 and 1028) the expert reopened the gripper over a cube held 2-3 cm across the fingers' axis,
lifted 12 cm, and dropped it."""

from __future__ import annotations

import numpy as np
import pytest

from mmact_ctrl.chunk import Observation
from mmact_ctrl.control.grasp_reflex import BETWEEN_Z_M, HOLD_XY_M, GraspReflex
from mmact_ctrl.metrics import episode_metrics
from scenarios.world.tasks.pick_expert import CLOSED_ON_CUBE_M, ON_CUBE_ABOVE_M, PickExpert, PickExpertConfig
from scenarios.world.tasks.pick_scene import CUBE_HALF_M, CUBE_REST_Z_M
from pick_episode import run_pick_episode

TCP = np.array([0.5, 0.0, CUBE_REST_Z_M + 0.12])


@pytest.mark.parametrize("off_m,dz_m,held", [(0.025, 0.0, True), (HOLD_XY_M + 0.005, 0.0, False),
                                              (0.025, BETWEEN_Z_M + 0.005, False)])
def test_the_stack_keeps_an_object_in_the_grip_within_its_radius(off_m, dz_m, held):
    assert GraspReflex.holding(TCP, TCP + np.array([0.0, off_m, -dz_m])) is held
    assert not GraspReflex.between(TCP, TCP + np.array([0.0, 0.025, 0.0]))  # the closing's test stays tight


def _gripper_channel(opening_m: float, off_m: float) -> np.ndarray:
    """The expert's gripper channel for a cube ``off_m`` across the fingers from the TCP, lifted with the hand, the
    fingers measuring ``opening_m``."""
    cube = TCP + np.array([0.0, off_m, -0.004])
    obs = Observation(t0_s=3.0, q_rad=np.zeros(7), dq_rad_s=np.zeros(7), ee_pos_m=TCP, ee_rotvec_rad=np.zeros(3),
                      gripper_m=opening_m, target_pos_m=cube, target_prev_pos_m=cube, frame_gap_s=0.1)
    return PickExpert(PickExpertConfig()).plan(obs).waypoints[:, 6]


def test_the_expert_keeps_holding_a_cube_its_fingers_measure_off_the_centre():
    on_cube = 2 * CUBE_HALF_M  # the fingers stopped on the cube's faces
    assert ON_CUBE_ABOVE_M < on_cube < CLOSED_ON_CUBE_M
    assert np.all(_gripper_channel(on_cube, 0.025) < 0.01)  # held: closed throughout
    assert np.all(_gripper_channel(0.002, 0.025) > 0.07)  # fingers closed on nothing: a miss, reopen
    assert np.all(_gripper_channel(on_cube, 0.04) > 0.07)  # out of the pads' reach: a miss


def test_a_cube_held_off_centre_is_not_dropped_in_the_loop():
    """Published reversal seed 1008, hybrid: the success no longer ends in a reopen and a drop."""
    log, _, _ = run_pick_episode("reversal", "0.2", 1008, "6")
    m = episode_metrics(log)
    assert log.task["success"] and m["drops"] == 0, m
