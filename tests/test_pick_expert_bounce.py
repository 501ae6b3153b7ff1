"""The pick expert's course prediction at the carrier's walls, and the descent it times around a predicted bounce."""

from __future__ import annotations

import numpy as np
import pytest

from mmact_ctrl.chunk import Observation
from scenarios.world.tasks.pick_expert import (BOUNCE_CLEAR_S, CLOSE_S, DESCEND_S, MAX_WAIT_S, PickExpert,
                                               PickExpertConfig, bounce_times_s, descent_wait_s, predicted_course_m)
from scenarios.world.tasks.pick_scene import CUBE_REST_Z_M

BOX = dict(workspace_low_m=(0.35, -0.3, CUBE_REST_Z_M), workspace_high_m=(0.65, 0.3, CUBE_REST_Z_M + 1e-6))


def test_the_predicted_course_reflects_at_the_walls_and_is_unbounded_without_a_box():
    cube, vel = np.array([0.6, 0.0, CUBE_REST_Z_M]), np.array([0.2, 0.0, 0.0])
    times = np.array([0.1, 0.25, 0.5])
    bounded = predicted_course_m(PickExpertConfig(**BOX), cube, vel, times)
    np.testing.assert_allclose(bounded[:, 0], [0.62, 0.65, 0.6], atol=1e-12)  # turns at x = 0.65 at 0.25 s
    free = predicted_course_m(PickExpertConfig(), cube, vel, times)
    np.testing.assert_allclose(free[:, 0], [0.62, 0.65, 0.7], atol=1e-12)


def test_the_bounce_times_are_where_the_course_turns():
    cfg = PickExpertConfig(**BOX)
    cube = np.array([0.6, 0.0, CUBE_REST_Z_M])
    bounces = bounce_times_s(cfg, cube, np.array([0.2, 0.0, 0.0]), 1.6)
    assert len(bounces) == 1 and abs(bounces[0] - 0.25) <= 0.011  # 5 cm to the wall at 0.2 m/s, on a 10 ms grid
    assert len(bounce_times_s(cfg, cube, np.array([-0.2, 0.0, 0.0]), 1.2)) == 0  # away from the wall: none in 1.2 s
    assert len(bounce_times_s(cfg, cube, np.zeros(3), 1.6)) == 0
    assert len(bounce_times_s(PickExpertConfig(), cube, np.array([0.2, 0.0, 0.0]), 1.6)) == 0  # no box: no walls


@pytest.mark.parametrize("bounce_s", [0.25, 0.5, 0.75, 1.0])
def test_the_descent_waits_until_the_closing_clears_the_bounce(bounce_s):
    cfg = PickExpertConfig(**BOX)
    wait = descent_wait_s(cfg, np.array([bounce_s]))
    if wait is None:  # no start within MAX_WAIT_S clears it: every candidate closes too near the bounce
        for w in np.arange(0.0, MAX_WAIT_S + 1e-9, cfg.dt_s):
            assert w + DESCEND_S - BOUNCE_CLEAR_S < bounce_s < w + DESCEND_S + CLOSE_S
        return
    close = wait + DESCEND_S
    assert not (close - BOUNCE_CLEAR_S < bounce_s < close + CLOSE_S)
    if wait > 0:  # the shortest wait: the one before it did not clear
        earlier = wait - cfg.dt_s + DESCEND_S
        assert earlier - BOUNCE_CLEAR_S < bounce_s < earlier + CLOSE_S
    assert descent_wait_s(cfg, np.zeros(0)) == 0.0


def test_the_expert_hovers_over_a_cube_about_to_turn_and_descends_over_one_that_is_not():
    expert = PickExpert(PickExpertConfig(**BOX))
    tcp = np.array([0.62, 0.0, CUBE_REST_Z_M + 0.07])

    def chunk_for(cube_x: float, vx: float):
        cube = np.array([cube_x, 0.0, CUBE_REST_Z_M])
        obs = Observation(t0_s=1.0, q_rad=np.zeros(7), dq_rad_s=np.zeros(7), ee_pos_m=tcp, ee_rotvec_rad=np.zeros(3),
                          gripper_m=0.08, target_pos_m=cube, target_prev_pos_m=cube - 0.1 * np.array([vx, 0.0, 0.0]),
                          frame_gap_s=0.1)
        return expert.plan(obs).waypoints

    turning = chunk_for(0.62, 0.2)  # bounces 0.15 s from now: the closing must wait until 0.55 s past the bounce
    steady = chunk_for(0.62, -0.2)  # moving away from the wall
    t_close_steady = np.argmax(steady[:, 6] < 0.04)
    assert t_close_steady == int(round(DESCEND_S / 0.1)) - 1  # closes at DESCEND_S
    closes = turning[:, 6] < 0.04
    assert closes.any() and np.argmax(closes) > t_close_steady  # waits, then closes
    assert turning[0, 2] > steady[0, 2] + 0.001  # it stays up while it waits
