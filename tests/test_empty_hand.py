"""The empty-hand gate (``mmact_ctrl.control.empty_hand``): on hand-built states, and in the loop on the pick episode
where it was measured to be needed."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from mmact_ctrl.config import StackConfig
from mmact_ctrl.control.empty_hand import BETWEEN_XY_M, RISE_M_S, EmptyHandGate
from mmact_ctrl.controller import HybridController
from mmact_ctrl.metrics import episode_metrics
from scenarios.world.tasks.pick import DESCENT_BAND_M, EMPTY_HAND_AFTER_S, PickTask
from scenarios.world.tasks.registry import task_stack_settings
from pick_episode import run_pick_episode

DT = 0.001
SAFE_Z = DESCENT_BAND_M[1]
AFTER_TICKS = int(round(EMPTY_HAND_AFTER_S / DT))


def _gate() -> EmptyHandGate:
    return EmptyHandGate(EMPTY_HAND_AFTER_S, SAFE_Z, DT)


def _ref(z_m: float = 0.03):
    return np.array([0.50, 0.10, z_m]), np.array([-0.5, 0.1, -0.05]), np.array([1.0, 0.0, -1.0])


TCP = np.array([0.48, 0.09, 0.03])


def test_an_open_or_a_young_closing_or_a_hand_around_its_object_passes_unchanged():
    gate = _gate()
    far = TCP + np.array([0.04, 0.0, 0.0])
    for ticks, obj in [(0, far), (AFTER_TICKS - 1, far), (AFTER_TICKS + 5, TCP + np.array([0.01, 0.01, 0.0])),
                       (AFTER_TICKS + 5, None)]:
        pos, vel, acc = _ref()
        out = gate(pos, vel, acc, TCP, obj, ticks)
        assert out[0] is pos and out[1] is vel and out[2] is acc, (ticks, obj)
    assert gate.held_ticks == 0 and gate.missed == 0


def test_a_closed_hand_that_missed_holds_its_place_and_rises_to_the_band_top():
    gate = _gate()
    obj = TCP + np.array([-BETWEEN_XY_M - 0.01, 0.0, 0.0])  # beside the closed fingers
    zs = []
    for k in range(50):
        pos, vel, acc = _ref()
        p, v, a = gate(pos, vel, acc, TCP, obj, AFTER_TICKS + k)
        assert np.allclose(p[:2], TCP[:2]) and np.allclose(v[:2], 0.0) and np.allclose(a[:2], 0.0)  # not sideways
        assert v[2] >= RISE_M_S and a[2] >= 0.0
        zs.append(p[2])
    assert np.allclose(np.diff(zs), RISE_M_S * DT)  # up at its rate
    assert zs[-1] <= SAFE_Z and gate.missed == 1 and gate.held_ticks == 50
    pos, vel, acc = _ref()
    assert gate(pos, vel, acc, np.array([TCP[0], TCP[1], SAFE_Z + 0.001]), obj, AFTER_TICKS + 60)[0] is pos  # up: lets go
    moved = TCP + np.array([0.05, 0.0, 0.0])  # down again elsewhere, still closed and empty: held there, not where it was
    p = gate(pos, vel, acc, moved, obj, AFTER_TICKS + 70)[0]
    assert np.allclose(p[:2], moved[:2]) and gate.missed == 2
    p = gate(pos, vel, acc, moved, obj, 0)[0]  # the gripper opens: still held (its fingers are still nearly closed)
    assert np.allclose(p[:2], moved[:2]) and gate.active
    up = np.array([moved[0], moved[1], SAFE_Z])
    assert gate(pos, vel, acc, up, obj, 0)[0] is pos and not gate.active  # up: lets go
    assert gate(pos, vel, acc, TCP, obj, 0)[0] is pos  # open and low: nothing to hold


def test_a_closed_hand_above_the_band_is_left_alone():
    gate = _gate()
    pos, vel, acc = _ref(0.1)
    high = np.array([TCP[0], TCP[1], SAFE_Z + 0.01])
    assert gate(pos, vel, acc, high, TCP + np.array([0.05, 0.0, 0.0]), AFTER_TICKS + 1)[0] is pos


def test_only_pick_in_a_mode_that_reads_the_object_has_the_gate():
    pick = StackConfig(**task_stack_settings("pick"))
    assert pick.empty_hand_after_s == PickTask.empty_hand_after_s == EMPTY_HAND_AFTER_S
    assert HybridController(dataclasses.replace(pick, mode="hybrid")).empty_hand is not None
    assert HybridController(dataclasses.replace(pick, mode="open_loop")).empty_hand is None
    for task in ("reach", "insert"):
        assert StackConfig(**task_stack_settings(task)).empty_hand_after_s is None
    with pytest.raises(ValueError, match="empty_hand_after_s"):
        StackConfig(empty_hand_after_s=0.0)


@pytest.mark.parametrize("gate_on", [True, False])
def test_a_missed_closing_no_longer_sweeps_the_closed_hand_into_the_cube(gate_on):
    """Pick, reversal at 0.2 m/s, hybrid, tuning seed 6010: the fingers closed beside the cube, and the hybrid layer's
    correction pulled the closed hand, at the grasp height, into it (pushed along at 0.57 m/s, 35 N at 3.95 s). With
    the gate the hand rises first; without it the same episode goes over the contact-force limit (the test's control).
    Replayed with the MPC's preview as it was then (``mpc_preview_governed`` False): with the bound (point 10) the
    hand comes down centred and this closing no longer misses."""
    log, ctl, _ = run_pick_episode("reversal", "0.2", 6010, "4.2", mpc_preview_governed=False,
                                   **({} if gate_on else {"empty_hand_after_s": None}))
    m = episode_metrics(log)
    if gate_on:
        assert ctl.empty_hand.missed >= 1 and ctl.empty_hand.held_ticks > 0  # the gate caught the missed closing
        assert m["contact_force_violations"] == 0 and m["limit_violations"] == 0, m
    else:
        assert m["contact_force_violations"] > 0, m
