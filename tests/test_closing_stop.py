"""``--close-at-grasp``: in a mode that reads the object the closing starts at the grasp height and stops the hand's
descent (``StackConfig.close_below_reading_m``, ``StackConfig.close_stops_descent_m``, ``ClosingGate``; README, Contact,
point 14): a pad that slides down a cube's side wedges it against the belt."""

from __future__ import annotations

import numpy as np
import pytest

from mmact_ctrl.config import StackConfig
from mmact_ctrl.control.closing_gate import HOLD_S, ClosingGate
from mmact_ctrl.metrics import episode_metrics
from mmact_ctrl.controller import HybridController
from scenarios.moving_target_args import build_parser, stack_config
from scenarios.world.tasks.pick import (CLOSE_AT_GRASP_M, CLOSE_BELOW_M, CLOSE_STOPS_DESCENT_M, CUBE_REST_Z_M,
                                        PickTask)
from scenarios.world.tasks.pick_expert import GRASP_ABOVE_CENTRE_M
from scenarios.world.tasks.registry import task_stack_settings
from pick_episode import run_pick_episode

DT = 0.001


def _descending(z_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return np.array([0.5, 0.0, z_m]), np.array([0.1, 0.0, -0.2]), np.array([0.0, 0.0, -3.0])


def test_once_the_fingers_close_the_reference_comes_down_no_further_than_the_stop():
    gate = ClosingGate(0.04, DT, stop_descent_m=0.002)
    ref = _descending(0.02)
    assert gate.hold(*ref)[0] is ref[0]  # open: nothing acts
    assert gate(0.0, 0.035) == 0.0  # the closing starts with the TCP at 35 mm: the stop is at 33 mm
    for k in range(int(2 * HOLD_S / DT)):  # through the hold and after it, while the gripper is commanded closed
        assert gate(0.0, 0.034) == 0.0
        pos, vel, acc = gate.hold(*ref)
        assert pos[2] == pytest.approx(0.033) and vel[2] == 0.0 and acc[2] == 0.0, k
        assert pos[0] == 0.5 and vel[0] == 0.1  # only the descent stops
    assert gate.stopped_ticks == int(2 * HOLD_S / DT)
    above = _descending(0.05)
    assert gate.hold(*above)[0] is above[0]  # a reference above the stop comes down to it
    assert gate(0.08, 0.034) == pytest.approx(0.08) and not gate.closing  # reopened: the stop is gone
    assert gate.hold(*ref)[0] is ref[0]


def test_without_the_stop_the_reference_goes_on_down_after_the_hold():
    gate = ClosingGate(0.04, DT)
    gate(0.0, 0.035)
    for _ in range(int(HOLD_S / DT)):
        gate.hold(*_descending(0.02))
    ref = _descending(0.02)
    assert gate.hold(*ref)[0] is ref[0] and gate.stopped_ticks == 0


def test_the_switch_asks_pick_for_the_stop_and_reach_and_insert_have_none():
    assert PickTask.close_stops_descent_m == CLOSE_STOPS_DESCENT_M
    assert PickTask.close_below_reading_m == CLOSE_AT_GRASP_M
    assert CLOSE_AT_GRASP_M == pytest.approx(CUBE_REST_Z_M + GRASP_ABOVE_CENTRE_M)  # the expert's grasp height
    cfg = StackConfig(**task_stack_settings("pick", close_at_grasp=True))
    assert cfg.close_stops_descent_m == CLOSE_STOPS_DESCENT_M and cfg.close_below_reading_m == CLOSE_AT_GRASP_M
    cfg = StackConfig(**task_stack_settings("pick"))  # the default: the closing as published
    assert cfg.close_stops_descent_m is None and cfg.close_below_reading_m is None
    for name in ("reach", "insert"):
        cfg = StackConfig(**task_stack_settings(name, close_at_grasp=True))
        assert cfg.close_stops_descent_m is None and cfg.close_below_reading_m is None
    args = build_parser().parse_args(["--task", "pick", "--close-at-grasp"])
    assert stack_config(args, "hybrid").close_below_reading_m == CLOSE_AT_GRASP_M
    assert stack_config(build_parser().parse_args(["--task", "pick"]), "hybrid").close_below_reading_m is None
    with pytest.raises(ValueError, match="close_stops_descent_m"):
        StackConfig(close_stops_descent_m=-0.001)
    with pytest.raises(ValueError, match="close_below_reading_m"):  # a stop with no closing height is a misreading
        StackConfig(close_stops_descent_m=0.002)
    with pytest.raises(ValueError, match="close_below_reading_m"):
        StackConfig(close_below_reading_m=float("nan"))


def test_only_the_modes_that_read_the_object_close_at_the_grasp_height_and_stop_there():
    """Open loop, blind, keeps the closing as it was measured (from 8 mm above the grasp height, the descent going on):
    closing later there cost it picks (tuning seeds, 0.4 m/s: 12 -> 10 of 50)."""
    settings = task_stack_settings("pick", close_at_grasp=True)
    hybrid = HybridController(StackConfig(mode="hybrid", **settings)).closing_gate
    blind = HybridController(StackConfig(mode="open_loop", **settings)).closing_gate
    assert hybrid.close_below_m == CLOSE_AT_GRASP_M and hybrid.stop_descent_m == CLOSE_STOPS_DESCENT_M
    assert blind.close_below_m == CLOSE_BELOW_M and blind.stop_descent_m is None
    default = HybridController(StackConfig(mode="hybrid", **task_stack_settings("pick"))).closing_gate
    assert default.close_below_m == CLOSE_BELOW_M and default.stop_descent_m is None


@pytest.mark.parametrize("point_14", [True, False])
def test_a_pad_no_longer_wedges_the_cube_it_closes_on_against_the_belt(point_14):
    """Pick, reversal at 0.2 m/s, hybrid, fresh seed 6058 (one of the 5 of 200 read as a wedge): the carrier turned
    while the fingers closed, the hand went on along the fingers' axis at 0.19 m/s and down at 0.17 m/s past its
    grasp height, and a pad met the cube's side and pressed it into the belt (20 N along the axis, 22 N up on the
    hand, 34 N). With ``--close-at-grasp`` the closing starts at the grasp height and the descent stops there, and
    the pad pushes the cube along the belt instead; the control, the default closing (from 8 mm above the grasp
    height, the hand going on down), goes over the contact-force limit."""
    switch = {"close_below_reading_m": CLOSE_AT_GRASP_M, "close_stops_descent_m": CLOSE_STOPS_DESCENT_M}
    log, ctl, _ = run_pick_episode("reversal", "0.2", 6058, "4.9", **(switch if point_14 else {}))
    m = episode_metrics(log)
    if point_14:
        assert ctl.closing_gate.stopped_ticks > 0
        assert m["contact_force_violations"] == 0 and m["limit_violations"] == 0, m
    else:
        assert m["contact_force_violations"] > 0, m
