"""The grasp latch waits until the fingers are on the object (README, Contact, point 12).

Latched from the closing command, the hand went on along the chunk's course for the 0.175 s the fingers take to
close, while the object on a turning carrier did not: on the published reversal run (hybrid, seed 1024) the cube,
centred when the closing began, was 14 mm off the fingers' axis when a pad met it, and the belt dragged it against
that finger (36 N)."""

from __future__ import annotations

import pytest

from mmact_ctrl.control.chunk_stage import GRIPPER_OPEN_M
from mmact_ctrl.control.fingers import FREE_CLOSING_M_S, FingerWatch
from mmact_ctrl.metrics import episode_metrics
from pick_episode import run_pick_episode

DT_S = 0.001


def _watch(*openings_m: float | None) -> FingerWatch:
    w = FingerWatch(DT_S)
    for o in openings_m:
        w.update(o)
    return w


def test_fingers_are_on_nothing_while_open_or_closing_freely():
    assert _watch(GRIPPER_OPEN_M).on_nothing_yet  # a closing command has not moved them yet
    free = 2 * FREE_CLOSING_M_S * DT_S  # the Franka Hand's free closing: 0.2 m/s of opening
    assert _watch(0.070, 0.070 - free).on_nothing_yet
    assert not _watch(0.045, 0.045 - 0.02 * DT_S).on_nothing_yet  # stopped on a 4.5 cm cube (a slow creep)
    assert not _watch(0.068, 0.0685).on_nothing_yet  # a pad pushed back open by the object
    assert not _watch(0.070, 0.069, None).on_nothing_yet  # nothing measured (reach): the latch's own test decides


@pytest.mark.parametrize("latch_on_grip", [True, False])
def test_the_hand_follows_a_turning_cube_while_the_fingers_close(latch_on_grip):
    """Published reversal seed 1024, hybrid: with the latch on the grip the pads meet the cube centred (no force over
    the limit); latched from the command (the control) the belt drags the cube against one finger."""
    log, _, cfg = run_pick_episode("reversal", "0.2", 1024, "6", latch_on_grip=latch_on_grip)
    m = episode_metrics(log)
    if latch_on_grip:
        assert log.task["success"] and m["contact_force_violations"] == 0, m
        assert m["peak_contact_force_n"] < 0.5 * cfg.contact_force_limit_n, m
    else:
        assert m["contact_force_violations"] > 0, m
