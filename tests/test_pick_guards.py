"""The guarded descent of the contact tasks: the descent governor, the closing gate, the force guard's halt and the
MPC's height weight, each on its own, and in the loop on the pick episodes where each was measured to be needed."""

from __future__ import annotations

import numpy as np
import pytest

from controllers.mpc import MPCConfig, TaskSpaceMPC
from controllers.robot_model import PandaModel
from mmact_ctrl.config import StackConfig
from mmact_ctrl.control.capture_gate import HYSTERESIS_M, RISE_M_S, CaptureGate
from mmact_ctrl.control.closing_gate import HOLD_S, ClosingGate
from mmact_ctrl.control.descent import BRAKE_M_S2, TCP_LEAD_S, TRACK_TAU_S, DescentGovernor
from mmact_ctrl.control.force_guard import GUARD_FRACTION, YIELD_M_S_PER_N, ContactForceGuard
from mmact_ctrl.controller import HybridController
from mmact_ctrl.metrics import episode_metrics
from scenarios.world.tasks.pick import (CAPTURE_CLEAR_M, CAPTURE_TOL_M, CLOSE_BELOW_M, CUBE_HALF_M, DESCENT_BAND_M,
                                        EMPTY_GRIP_BELOW_M, LANDING_SPEED_M_S, PickTask)
from scenarios.world.tasks.registry import task_stack_settings
from pick_episode import run_pick_episode

DT = 0.001


def _descend(gov: DescentGovernor, z_ref: np.ndarray) -> np.ndarray:
    """The governed heights of a reference ``z_ref`` (one per tick)."""
    return np.array([gov(np.array([0.5, 0.0, z]), np.array([0.0, 0.0, -0.3]), np.zeros(3))[0][2] for z in z_ref])


def test_the_governor_passes_the_band_at_its_speed_and_brakes_onto_the_floor():
    low, high, floor = 0.05, 0.06, 0.025
    gov = DescentGovernor((low, high), 0.05, floor, DT)
    z_ref = 0.2 - 0.3 * DT * np.arange(2000)  # 0.3 m/s straight down, far past the floor
    z = _descend(gov, z_ref)
    speed = -np.diff(z) / DT
    in_band = (z[:-1] > low + 1e-4) & (z[:-1] <= high)  # steps that start in the band
    assert in_band.sum() > 100 and speed[in_band].max() <= 0.05 + 1e-9  # the guarded move
    assert z.min() >= floor and z[-1] < floor + 1e-3  # onto the floor, never through it
    above = z[1:] > high + 0.05  # high above the band, a 0.3 m/s descent is not slowed
    assert np.allclose(z[1:][above], z_ref[1:][above])
    assert gov.governed_ticks > 0
    # the braking curve: never faster than a stop at BRAKE_M_S2 onto the band's speed allows
    start = z[:-1]
    band_curve = 0.05 + np.sqrt(2 * BRAKE_M_S2 * np.maximum(start - high, 0.0))
    floor_curve = np.sqrt(2 * BRAKE_M_S2 * np.maximum(start - floor, 0.0))
    allowed = np.where(start > low, np.minimum(band_curve, floor_curve), floor_curve)
    assert np.all(speed <= allowed + 1e-9)


def test_the_governor_leaves_a_rising_or_slow_reference_alone():
    gov = DescentGovernor((0.05, 0.06), 0.05, 0.025, DT)
    pos, vel, acc = np.array([0.5, 0.0, 0.055]), np.array([0.0, 0.0, 0.1]), np.zeros(3)
    assert gov(pos, vel, acc)[0] is pos
    up = np.array([0.5, 0.0, 0.056])
    assert gov(up, vel, acc)[0] is up  # going up: the same arrays
    slow = np.array([0.5, 0.0, 0.056 - 0.01 * DT])  # 0.01 m/s down in the band: under its speed
    assert gov(slow, vel, acc)[0] is slow and gov.governed_ticks == 0


def test_the_governor_keeps_the_reference_within_its_lead_of_the_tcp_and_judges_the_tcps_speed_ahead():
    """A reference that has run far below the TCP (a chunk that starts at the grasp height) pulls the TCP down at the
    tracking's gain times the gap, whatever the reference's own descent: it is held at most ``TCP_LEAD_S`` of the
    speed allowed at the TCP's height below the TCP, coming down no faster than that speed, judged where the TCP will
    be ``TRACK_TAU_S`` later."""
    low, high, floor = 0.05, 0.06, 0.025
    gov = DescentGovernor((low, high), 0.12, floor, DT, follow_tcp=True)
    tcp_z = 0.15
    s_tcp = gov.allowed_speed_m_s(tcp_z)
    pos, vel, acc = gov(np.array([0.5, 0.0, 0.04]), np.array([0.0, 0.0, -2.0]), np.array([0.0, 0.0, -5.0]), tcp_z)
    assert pos[2] == pytest.approx(tcp_z - s_tcp * TCP_LEAD_S) and vel[2] == pytest.approx(-s_tcp) and acc[2] == 0.0
    assert gov.tcp_governed_ticks == 1
    # a TCP coming down fast is judged where it will be: a slower speed is allowed than at its height
    gov.reset()
    _, vel, _ = gov(np.array([0.5, 0.0, 0.07]), np.array([0.0, 0.0, -1.0]), np.zeros(3), 0.07, -0.4)
    assert vel[2] == pytest.approx(-gov.allowed_speed_m_s(0.07 - 0.4 * TRACK_TAU_S))
    assert -vel[2] < gov.allowed_speed_m_s(0.07)
    # a reference above the TCP's lead, no faster than allowed there, passes unchanged (the same arrays)
    gov.reset()
    p, v, a = np.array([0.5, 0.0, 0.149]), np.array([0.0, 0.0, -0.2]), np.zeros(3)
    assert gov(p, v, a, tcp_z, 0.0)[0] is p and gov.tcp_governed_ticks == 0
    # a governor that does not follow the TCP (a mode that reads the object) ignores it
    blind_to_tcp = DescentGovernor((low, high), 0.12, floor, DT)
    p = np.array([0.5, 0.0, 0.04])
    assert blind_to_tcp(p, np.zeros(3), np.zeros(3), tcp_z, -1.0)[0] is p and blind_to_tcp.tcp_governed_ticks == 0


def test_a_blind_hand_resting_on_something_under_the_band_leads_by_the_bands_speed_not_the_floor_curves():
    """Open loop, pick at 0.2 m/s, seed 1014 (published; read after its run): an open finger rested on a cube's top
    with the TCP just under the band's lower edge, where the speed allowed at the TCP jumps from the band's to the
    floor curve's (0.53 m/s): the reference led the TCP by 5 mm and pressed (30.8 N). While the robot touches
    something the lead is the band's speed's."""
    low, high, floor = 0.0535, 0.0635, 0.025
    gov = DescentGovernor((low, high), 0.12, floor, DT, follow_tcp=True)
    tcp_z = 0.053
    assert gov.allowed_speed_m_s(tcp_z) > 0.5  # under the band: the floor's curve
    ref = np.array([0.5, 0.0, 0.03]), np.array([0.0, 0.0, -0.3]), np.zeros(3)
    free = gov(*ref, tcp_z, 0.0)[0][2]
    gov.reset()
    pos, vel, _ = gov(*ref, tcp_z, 0.0, True)
    assert free == pytest.approx(tcp_z - gov.allowed_speed_m_s(tcp_z) * TCP_LEAD_S)
    assert pos[2] == pytest.approx(tcp_z - 0.12 * TCP_LEAD_S) and vel[2] == pytest.approx(-0.12)
    # a governor that reads the object (no TCP lead) is not changed by the touch
    seeing = DescentGovernor((low, high), 0.12, floor, DT)
    p = np.array([0.5, 0.0, 0.0529])
    assert seeing(np.array([0.5, 0.0, 0.053]), np.zeros(3), np.zeros(3), tcp_z, 0.0, True)[0][2] == 0.053
    assert seeing(p, np.zeros(3), np.zeros(3), tcp_z, 0.0, True)[0] is p


def test_a_blind_finger_resting_on_a_cubes_top_is_not_pressed_over_the_limit():
    """The loop of the case above (open loop, pick at 0.2 m/s, seed 1014): under the limit throughout."""
    log, ctl, _ = run_pick_episode("linear", "0.2", 1014, "6", mode="open_loop")
    m = episode_metrics(log)
    assert ctl.descent.follow_tcp and ctl.descent.tcp_governed_ticks > 0
    assert m["limit_violations"] == 0, m


def test_the_closing_gate_holds_the_fingers_open_until_the_hand_is_down_and_the_hand_down_while_they_close():
    gate = ClosingGate(0.04, DT)
    assert gate(0.0, 0.08) == pytest.approx(0.08) and gate.held_ticks == 1  # too high: held open
    assert gate(0.06, 0.08) == pytest.approx(0.08)  # a partial closing up high is held too
    assert gate(0.0, 0.035) == 0.0  # down: it closes
    assert gate(0.0, 0.2) == 0.0  # closing: it goes on, however high the hand goes (a held cube is not let go)
    lifted = np.array([0.5, 0.0, 0.06])  # the chunk lifts on its own clock while the fingers close
    first = gate.hold(np.array([0.5, 0.0, 0.035]), np.zeros(3), np.zeros(3))[0]
    held = [gate.hold(lifted, np.array([0.0, 0.0, 0.2]), np.ones(3)) for _ in range(int(HOLD_S / DT) - 1)]
    assert all(p[2] == first[2] and v[2] == 0.0 and a[2] == 0.0 for p, v, a in held)
    assert gate.hold(lifted, np.zeros(3), np.zeros(3))[0] is lifted  # after HOLD_S the lift goes on
    assert gate(0.08, 0.2) == pytest.approx(0.08) and not gate.closing  # opened: the next closing is gated again
    assert ClosingGate(None)(0.0, 1.0) == 0.0  # none: the command passes


def test_the_force_guard_stops_the_reference_going_into_the_contact():
    g = ContactForceGuard(limit_n=30.0, dt_s=DT)
    vel, acc = np.array([0.1, 0.0, -0.25]), np.array([0.0, 0.0, -2.0])
    assert g.halt(vel, acc)[0] is vel  # no contact: unchanged
    g.update(np.array([0.0, 0.0, 25.0]))  # pressed from below
    v, a = g.halt(vel, acc)
    assert v[2] == 0.0 and a[2] == 0.0 and v[0] == 0.1  # no more down, sideways unchanged
    v, a = g.halt(np.array([0.0, 0.0, 0.2]), np.zeros(3))
    assert v[2] == 0.2  # away from the contact: unchanged
    g.update(np.zeros(3))
    assert g.halt(vel, acc)[0] is vel  # released: unchanged


@pytest.mark.parametrize("rate", [YIELD_M_S_PER_N, 3.0 * YIELD_M_S_PER_N])
def test_the_force_guard_yields_along_the_force_at_its_rate_per_newton_over_the_threshold(rate):
    g = ContactForceGuard(limit_n=30.0, dt_s=DT, yield_m_s_per_n=rate)
    for _ in range(50):
        g.update(np.array([0.0, 0.0, 40.0]))  # pressed from below, 25 N over the threshold
    over_n = 40.0 - GUARD_FRACTION * 30.0
    assert g.offset_m[:2].tolist() == [0.0, 0.0] and g.offset_m[2] == pytest.approx(50 * DT * rate * over_n)
    assert g.apply(np.array([0.5, 0.0, 0.1]))[2] == pytest.approx(0.1 + 50 * DT * rate * over_n)


def test_the_capture_gate_keeps_the_open_hand_over_an_object_that_would_not_pass_between_the_fingers():
    rot = np.diag([1.0, -1.0, -1.0])  # the nominal grasp: the fingers open along the world's y axis
    safe = 0.06
    gate = CaptureGate(0.015, 0.037, safe, DT)
    tcp = np.array([0.5, 0.0, 0.03])
    low = np.array([0.5, 0.0, 0.03])
    vel, acc = np.array([0.2, 0.0, -0.1]), np.array([0.0, 0.0, -1.0])

    def run(obj, ref=low):
        return gate(ref, vel, acc, tcp, rot, obj)

    between = np.array([0.52, 0.01, 0.024])  # 2 cm ahead, 1 cm off the axis: it passes between the open fingers
    assert run(between)[0] is low and not gate.closed
    assert gate.off_axis_m(tcp, rot, between) == pytest.approx(-0.01)  # the hand's y is the world's -y
    clear = np.array([0.56, 0.03, 0.024])  # 3 cm off the axis but 6 cm ahead: clear of the fingers' width
    assert run(clear)[0] is low and not gate.closed
    beside = np.array([0.52, 0.02, 0.024])  # 2 cm off the axis, within the fingers' width: a finger would strike it
    heights = []
    for _ in range(400):
        p, v, a = run(beside)
        heights.append(p[2])
    rise = np.diff(heights) / DT
    assert gate.closed and heights[-1] == pytest.approx(safe)  # raised to the safe height ...
    assert rise.max() <= RISE_M_S + 1e-9 and heights[0] == pytest.approx(low[2] + RISE_M_S * DT)  # ... at its speed
    assert v[2] == 0.0 and a[2] == 0.0 and v[0] == 0.2  # held there, sideways unchanged
    high = np.array([0.5, 0.0, 0.08])
    assert run(beside, ref=high)[0] is high  # above the safe height: unchanged
    edge = np.array([0.52, 0.015 - HYSTERESIS_M / 2, 0.024])  # inside the tolerance, not by the hysteresis
    assert run(edge)[0][2] == pytest.approx(safe)
    assert run(between)[0] is low and not gate.closed  # let go: back down
    assert run(None)[0] is low  # nothing measured yet: nothing to avoid


def test_the_force_guards_yield_is_not_undone_by_the_closing_gates_hold():
    """The closing gate keeps the hand from rising while the fingers close; a force pushing the hand up (a finger on
    a cube's edge, wedged against the belt) must still move the reference the QP tracks up: the guard acts after it."""
    ctl = HybridController(StackConfig(mode="open_loop", use_mpc=False, **task_stack_settings("pick")))
    q = np.array(ctl.model.home_q_rad)
    ctl.reset(q)
    tracked = []
    solve = ctl.qp.solve
    ctl.qp.solve = lambda terms, q_rad, dq_rad_s, ref: (tracked.append(ref.pos_m.copy()), solve(terms, q_rad, dq_rad_s,
                                                                                                  ref))[1]
    ctl.tick(0.0, q, np.zeros(7))
    z_free = tracked[-1][2]
    ctl.closing_gate._hold_left, ctl.closing_gate._hold_z_m = 100, z_free - 0.001  # closing: no rise above z - 1 mm
    ctl.tick(0.001, q, np.zeros(7))
    assert tracked[-1][2] == pytest.approx(z_free - 0.001)  # the hold
    for _ in range(50):
        ctl.sense_wrench(np.array([0.0, 0.0, 40.0, 0.0, 0.0, 0.0]))  # pushed up, over the guard's threshold
    ctl.tick(0.002, q, np.zeros(7))
    assert tracked[-1][2] > z_free - 0.001 + 0.5 * float(ctl.force_guard.offset_m[2]) > z_free - 0.001  # it yields


def test_the_mpc_keeps_its_height_while_catching_up_sideways_when_height_weighs_more():
    model = PandaModel()
    q = np.array(model.home_q_rad)
    pos, _, jac = model.kinematics(q)
    ref = pos + np.array([0.0, 0.3, 0.0])  # far to the side, at the same height
    drops = {}
    for scale in (1.0, 4.0):
        mpc = TaskSpaceMPC(MPCConfig(w_pos_z_scale=scale, max_solve_ms=np.inf), q_nominal_rad=model.home_q_rad)
        plan = mpc.solve(0.0, q, np.zeros(7), pos, jac, ref)
        assert plan.ok
        drops[scale] = float(np.max(np.abs(plan.ee_pos_m[:, 2] - pos[2])))
    assert drops[4.0] < 0.5 * drops[1.0], drops
    with pytest.raises(ValueError, match="w_pos_z_scale"):
        MPCConfig(w_pos_z_scale=0.0)


def test_the_pick_task_asks_for_its_guards_and_reach_for_none():
    s = task_stack_settings("pick")
    assert s["descent_band_m"] == DESCENT_BAND_M and s["close_below_m"] == CLOSE_BELOW_M
    assert s["capture_tol_m"] == CAPTURE_TOL_M and 0.0 < CAPTURE_TOL_M < 0.019  # under a pad's touch
    assert s["capture_clear_m"] == CAPTURE_CLEAR_M > CUBE_HALF_M + 0.01  # beyond a finger's half-width
    assert s["mpc"].w_pos_z_scale == PickTask.mpc_z_weight > 1.0
    assert task_stack_settings("reach") == {}
    assert "descent_band_m" not in task_stack_settings("insert") and "mpc" not in task_stack_settings("insert")
    assert "capture_tol_m" not in task_stack_settings("insert")
    assert s["guard_yield_m_s_per_n"] == PickTask.guard_yield_m_s_per_n == 3.0 * YIELD_M_S_PER_N
    assert "guard_yield_m_s_per_n" not in task_stack_settings("insert")  # insert's guard as its figures were made
    with pytest.raises(ValueError, match="guard_yield_m_s_per_n"):
        StackConfig(guard_yield_m_s_per_n=0.0)
    with pytest.raises(ValueError, match="descent_band_m"):
        StackConfig(descent_band_m=(0.06, 0.05))
    with pytest.raises(ValueError, match="capture_tol_m"):
        StackConfig(capture_tol_m=-0.01)
    with pytest.raises(ValueError, match="capture_clear_m"):
        StackConfig(capture_clear_m=float("nan"))
    assert s["landing_speed_m_s"] == PickTask.landing_speed_m_s == LANDING_SPEED_M_S
    assert s["empty_grip_below_m"] == PickTask.empty_grip_below_m == EMPTY_GRIP_BELOW_M < 2 * CUBE_HALF_M
    assert not {"landing_speed_m_s", "empty_grip_below_m"} & set(task_stack_settings("insert"))
    with pytest.raises(ValueError, match="landing_speed_m_s"):
        StackConfig(landing_speed_m_s=0.0)
    with pytest.raises(ValueError, match="empty_grip_below_m"):
        StackConfig(empty_grip_below_m=-0.01)


def test_the_band_is_a_guarded_move_where_the_hand_reads_the_object_and_a_landing_speed_where_it_does_not():
    settings = task_stack_settings("pick")
    hybrid = HybridController(StackConfig(mode="hybrid", **settings))
    blind = HybridController(StackConfig(mode="open_loop", **settings))
    assert hybrid.descent.low_m == blind.descent.low_m == DESCENT_BAND_M[0]
    assert hybrid.descent.speed_m_s == StackConfig().descent_speed_m_s < blind.descent.speed_m_s == LANDING_SPEED_M_S
    no_landing = HybridController(StackConfig(mode="open_loop", **{**settings, "landing_speed_m_s": None}))
    assert no_landing.descent.low_m == np.inf  # the floor's braking curve only
    assert blind.empty_grip.below_m == EMPTY_GRIP_BELOW_M and hybrid.empty_grip is None  # hybrid: the empty-hand gate
    assert blind.descent.follow_tcp and not hybrid.descent.follow_tcp  # hybrid's descent as it was measured
    assert hybrid.capture.safe_z_m == DESCENT_BAND_M[1] and blind.capture is None  # the gate reads the object
    assert hybrid.closing_gate.close_below_m == blind.closing_gate.close_below_m == CLOSE_BELOW_M
    reach = HybridController(StackConfig(mode="hybrid"))
    assert reach.descent is None and reach.closing_gate.close_below_m is None and reach.capture is None


@pytest.mark.parametrize("seed", [1006, 1015])
def test_the_hand_no_longer_dives_into_the_belt_at_a_carriers_turn(seed):
    """Pick at 0.4 m/s, hybrid, the main job's settings: on these seeds the MPC's plan, catching up after the cube
    turned at the belt's end, drove the TCP 14-16 mm under its floor and the open fingers into the belt (160 N, 122 N)."""
    log, _, _ = run_pick_episode("linear", "0.4", seed, "4")
    m = episode_metrics(log)
    assert m["contact_force_violations"] == 0 and m["limit_violations"] == 0, m
    # the reference is held on the floor; the tracked TCP stays within a few mm of it (fingertips 1 cm over the belt)
    assert log.ee_pos_m[:, 2].min() > PickTask.tcp_floor_m - 0.005


def test_an_open_finger_dragged_on_a_cube_no_longer_winds_the_arm_past_its_joint_limits():
    """Pick, reversal at 0.2 m/s, open loop, tuning seed 6033: an open finger landed on the other cube at 0.3 m/s and
    rode it on the belt, pressed on at 35-50 N; with the guard yielding at the default rate the arm wound up past its
    joint velocity (200 ticks) and position (62) limits at 5.6 s. Pick's guard yields 3x faster."""
    log, ctl, cfg = run_pick_episode("reversal", "0.2", 6033, "6", mode="open_loop")
    assert cfg.guard_yield_m_s_per_n == PickTask.guard_yield_m_s_per_n
    m = episode_metrics(log)
    assert ctl.force_guard.yield_ticks > 0  # the finger pressed on the cube and the guard yielded
    assert m["position_violations"] == 0 and m["velocity_violations"] == 0, m
    assert m["limit_violations"] == m["contact_force_violations"], m


@pytest.mark.parametrize("target,speed,seed,duration_s", [("reversal", "0.2", 1018, "3"), ("linear", "0.4", 1032, "5")])
def test_a_finger_no_longer_strikes_the_cube_beside_it(target, speed, seed, duration_s):
    """Pick, hybrid, the main job's settings: on these seeds the hand, catching up, came down with the cube 2 cm off
    the fingers' axis, and a finger struck its side (50 N at the reversal's turn, 45 N at 0.4 m/s). The capture gate
    keeps the hand over the cubes' top until the cube will pass between the fingers."""
    log, ctl, _ = run_pick_episode(target, speed, seed, duration_s)
    m = episode_metrics(log)
    assert ctl.capture.raised_ticks > 0  # the gate acted
    assert m["contact_force_violations"] == 0 and m["limit_violations"] == 0, m


def test_a_blind_hand_is_not_pulled_down_by_a_reference_far_below_it():
    """Pick at 0.4 m/s, open loop, tuning seed 6001: a new chunk put the reference 10 cm below the TCP, at the grasp
    height; the tracking pulled the open hand down at 0.7 m/s, 16 mm through its floor and into the belt (70 N).
    The governor holds the reference within its lead of the TCP and judges the TCP's speed where it will be."""
    log, ctl, _ = run_pick_episode("linear", "0.4", 6001, "5.5", mode="open_loop")
    m = episode_metrics(log)
    assert ctl.descent.tcp_governed_ticks > 0
    assert m["contact_force_violations"] == 0 and m["limit_violations"] == 0, m
    assert log.ee_pos_m[:, 2].min() > PickTask.tcp_floor_m - 0.005
