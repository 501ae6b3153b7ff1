"""The empty-hand gate (``mmact_ctrl.control.empty_hand``): on hand-built states, and in the loop on the pick episode
where it was measured to be needed."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from mmact_ctrl.config import StackConfig
from mmact_ctrl.control.empty_hand import BETWEEN_XY_M, GLANCE_M, HORIZON_S, RISE_M_S, EmptyHandGate
from mmact_ctrl.control.fingers import OPENING_CLOSES_M_S
from mmact_ctrl.controller import HybridController
from mmact_ctrl.metrics import episode_metrics
from scenarios.world.tasks.pick import (CAPTURE_TOL_M, CUBE_HALF_M, DESCENT_BAND_M, EMPTY_HAND_AFTER_S,
                                        EMPTY_HAND_BESIDE_M, PickTask)
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
    assert pick.empty_hand_beside_m == PickTask.empty_hand_beside_m == EMPTY_HAND_BESIDE_M
    for task in ("reach", "insert"):
        assert StackConfig(**task_stack_settings(task)).empty_hand_after_s is None
        assert StackConfig(**task_stack_settings(task)).empty_hand_beside_m is None
    with pytest.raises(ValueError, match="empty_hand_after_s"):
        StackConfig(empty_hand_after_s=0.0)
    with pytest.raises(ValueError, match="empty_hand_beside_m"):
        StackConfig(empty_hand_beside_m=float("nan"))


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


def _opening_gate() -> EmptyHandGate:
    return EmptyHandGate(EMPTY_HAND_AFTER_S, SAFE_Z, DT, opening_tol_m=CAPTURE_TOL_M, beside_m=EMPTY_HAND_BESIDE_M)


ROT = np.eye(3)  # the hand's x axis across the fingers (b), its y axis along them (a)


def _at(a_m: float, b_m: float) -> np.ndarray:
    return TCP + np.array([b_m, a_m, 0.0])


def _toward(b_m: float, speed_m_s: float = 0.3, along_m_s: float = 0.0) -> np.ndarray:
    """A relative velocity (the object's less the TCP's) bringing an object at ``b_m`` across the axis closer."""
    return np.array([-np.sign(b_m) * speed_m_s, along_m_s, 0.0])


def test_the_opening_tells_a_miss_only_when_a_closing_object_beside_the_fingers_will_find_them_too_narrow():
    gate = _opening_gate()
    assert EMPTY_HAND_BESIDE_M == pytest.approx(CUBE_HALF_M + 0.010)
    # wide open: a cube centred on the axis 5 cm across it, coming at 0.3 m/s, finds the fingers 68 mm open
    assert not gate.missed_on_opening(TCP, ROT, _at(0.0, 0.05), 0.080, _toward(0.05))
    # 40 mm open: narrower than the cube, which will meet their side, from either side
    assert gate.missed_on_opening(TCP, ROT, _at(0.0, 0.04), 0.040, _toward(0.04))
    assert gate.missed_on_opening(TCP, ROT, _at(0.0, -0.04), 0.040, _toward(-0.04))
    # ... but not if it stands still or goes away (a cube sliding out between the pads), nor if it is already
    # between the pads across the axis (pinched, not missed), nor if it gets there only after the horizon
    assert not gate.missed_on_opening(TCP, ROT, _at(0.0, 0.04), 0.040, np.zeros(3))
    assert not gate.missed_on_opening(TCP, ROT, _at(0.0, 0.04), 0.040, -_toward(0.04))
    assert not gate.missed_on_opening(TCP, ROT, _at(0.0, 0.02), 0.040, _toward(0.02))
    far_b = EMPTY_HAND_BESIDE_M + 0.3 * (HORIZON_S + 0.01)
    assert not gate.missed_on_opening(TCP, ROT, _at(0.0, far_b), 0.040, _toward(far_b))
    # along the axis: 70 mm open, the cube 45 mm across coming at 0.3 m/s arrives in 42 ms, the fingers 61.7 mm
    # open then, so it passes within the tolerance less 9.2 mm, plus the glance
    arrives = (0.045 - EMPTY_HAND_BESIDE_M) / 0.3
    tol = CAPTURE_TOL_M - 0.5 * OPENING_CLOSES_M_S * arrives - 0.005 + GLANCE_M
    assert gate.missed_on_opening(TCP, ROT, _at(tol + 0.001, 0.045), 0.070, _toward(0.045))
    assert not gate.missed_on_opening(TCP, ROT, _at(tol - 0.001, 0.045), 0.070, _toward(0.045))
    # ... and where the relative velocity brings it onto the axis by then, it passes
    assert not gate.missed_on_opening(TCP, ROT, _at(tol + 0.003, 0.045), 0.070, _toward(0.045, along_m_s=-0.1))
    # the hand turned a quarter: the axes turn with it
    quarter = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    assert gate.missed_on_opening(TCP, quarter, TCP + np.array([0.0, 0.04, 0.0]), 0.040, np.array([0.0, -0.3, 0.0]))
    assert not gate.missed_on_opening(TCP, quarter, TCP + np.array([0.04, 0.0, 0.0]), 0.040,
                                      np.array([-0.3, 0.0, 0.0]))  # along the fingers' axis: not beside them
    # nothing measured, no velocity, or no tolerance: no verdict
    assert not gate.missed_on_opening(TCP, ROT, _at(0.0, 0.04), None, _toward(0.04))
    assert not gate.missed_on_opening(TCP, ROT, _at(0.0, 0.04), 0.040, None)
    assert not _gate().missed_on_opening(TCP, ROT, _at(0.0, 0.04), 0.040, _toward(0.04))


def test_a_closing_that_measures_a_miss_holds_the_hand_before_the_closing_time_has_run_out():
    gate = _opening_gate()
    beside, toward = _at(0.0, 0.045), _toward(0.045)
    pos, vel, acc = _ref()
    assert gate(pos, vel, acc, TCP, beside, 10, ROT, 0.075, toward)[0] is pos  # still wide enough to take it in
    assert gate(pos, vel, acc, TCP, beside, 10, ROT, None, toward)[0] is pos  # nothing measured: the time decides
    assert gate(pos, vel, acc, TCP, beside, 0, ROT, 0.040, toward)[0] is pos  # not closing
    p, v, a = gate(pos, vel, acc, TCP, beside, 10, ROT, 0.040, toward)
    assert gate.active and gate.missed == 1
    assert np.allclose(p[:2], TCP[:2]) and np.allclose(v[:2], 0.0) and v[2] >= RISE_M_S


@pytest.mark.parametrize("on_opening", [True, False])
def test_a_closing_beside_a_turned_cube_no_longer_sweeps_the_fingers_into_its_side(on_opening):
    """Pick, reversal at 0.2 m/s, hybrid, fresh seed 6110 (one of the 7 of 200 over the contact-force limit read as
    a closing beside the cube): the fingers closed on the chunk's clock with the cube 47 mm across their axis, and
    the correction, catching up at 0.25 m/s, swept the fingers, 38 mm open, into the cube's side (98 N at 3.05 s),
    before the 0.25 s of the closing time had run out. On the measured opening the gate holds the hand first; without
    it (the test's control) the same episode goes over the limit."""
    log, ctl, _ = run_pick_episode("reversal", "0.2", 6110, "3.3",
                                   **({} if on_opening else {"empty_hand_beside_m": None}))
    m = episode_metrics(log)
    if on_opening:
        assert ctl.empty_hand.missed >= 1 and ctl.empty_hand.held_ticks > 0
        assert m["contact_force_violations"] == 0 and m["limit_violations"] == 0, m
    else:
        assert m["contact_force_violations"] > 0, m
