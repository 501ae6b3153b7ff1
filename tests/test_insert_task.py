"""The insert task and the contact-force guard: the peg seats in an aligned push at the default clearance (the
simulator's floor probe), the success predicate on hand-built states, the expert seats the peg in hybrid (with and
without compliance) within the contact-force limit, the guard keeps a stiff open-loop push under the limit, and the
sweep's contact cells leave reach's keys alone."""

from __future__ import annotations

import numpy as np
import pytest

from mmact_ctrl.config import StackConfig
from mmact_ctrl.control.force_guard import GUARD_FRACTION, ContactForceGuard
from mmact_ctrl.controller import HybridController
from mmact_ctrl.loop import run_episode
from mmact_ctrl.metrics import episode_metrics
from scenarios.insert_floor import aligned_push
from scenarios.world.factory import make_expert, make_world
from scenarios.world.tasks.insert import SEAT_M
from scenarios.world.tasks.insert_progress import JAM_S, InsertProgress
from scenarios.world.tasks.insert_scene import hole_half_m
from scenarios.world.tasks.registry import task_stack_settings


def test_the_peg_seats_in_an_aligned_push_at_the_default_clearance():
    aligned = aligned_push(1.0)
    assert aligned.seated and aligned.depth_m >= SEAT_M
    # a little misaligned (0.5 mm, 0.5 deg) the chamfer and the walls guide it in at 1 mm as well
    near = aligned_push(1.0, offset_mm=0.5, tilt_deg=0.5)
    assert near.seated, near
    # beside the hole (6 mm off: past the 1 mm clearance and the 3 mm chamfer) it cannot seat
    assert not aligned_push(1.0, offset_mm=3.9 + 2.0).seated


def test_the_success_predicate_on_hand_built_states():
    dt = 0.001
    mouth = np.array([0.5, 0.0, 0.025])
    p = InsertProgress(SEAT_M, hole_half_m(1.0), dt)
    p.reset(np.array([0.0, 0.0, -0.06]))
    for k in range(100):  # down the axis of the hole to 21 mm below the mouth
        bottom = mouth + np.array([0.0005, 0.0, 0.005 - 0.026 * k / 99])
        p.update(k * dt, bottom, np.array([0.0, 0.0, -0.06]), mouth, k > 10, 5.0)
    r = p.report()
    assert r["success"] and r["time_to_seat_s"] == pytest.approx(96 * dt) and r["depth_m"] >= SEAT_M
    assert r["lateral_error_at_contact_m"] == pytest.approx(0.0005)
    # as deep, but beside the hole (outside its walls): not seated
    q = InsertProgress(SEAT_M, hole_half_m(1.0), dt)
    q.reset(np.zeros(3))
    q.update(0.0, mouth + np.array([0.03, 0.0, -0.021]), np.zeros(3), mouth, False, 0.0)
    assert not q.report()["success"]
    # caught on the chamfer, not descending, for longer than JAM_S: one jam, then the slip and the peak force
    j = InsertProgress(SEAT_M, hole_half_m(1.0), dt)
    j.reset(np.zeros(3))
    for k in range(int(2 * JAM_S / dt)):
        j.update(k * dt, mouth + np.array([0.004, 0.0, -0.002]), np.array([0.0, 0.0, 0.003]), mouth, True, 12.0)
    r = j.report()
    assert r["jams"] == 1 and not r["success"]
    assert r["peg_slip_m"] == pytest.approx(0.003) and r["peak_contact_force_n"] == 12.0


def _peg_in_finger_m(world) -> np.ndarray:
    """The peg's centre in the left finger's frame, m."""
    import mujoco

    m, d = world.model, world.data
    finger = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "panda_leftfinger")
    peg = world.data.qpos[world._peg_q:world._peg_q + 3]
    return d.xmat[finger].reshape(3, 3).T @ (peg - d.xpos[finger])


def test_the_peg_does_not_slide_in_the_fingers_through_a_fast_arm_move():
    # a 1 s minimum-jerk joint move (about 0.25 m of the TCP) under a joint PD with the gravity and Coriolis terms,
    # the gripper squeezing: with MuJoCo's default contact stiffness the peg slid 3 mm along the fingers here
    world = make_world("static", 0.0, task="insert", clearance_mm=1.0)
    world.reset(0)
    d = world.data
    q0, dq_goal = d.qpos[:7].copy(), np.array([0.3, 0.4, 0.0, -0.4, 0.0, 0.3, 0.0])
    for _ in range(50):  # the squeeze settles
        world.step(d.qfrc_bias[:7] + 400.0 * (q0 - d.qpos[:7]) - 40.0 * d.qvel[:7], 0.0)
    start, tcp_start = _peg_in_finger_m(world), world.state().ee_pos_m
    for k in range(1500):
        s = min(k * world.dt_s / 1.0, 1.0)
        q_ref = q0 + (10 * s**3 - 15 * s**4 + 6 * s**5) * dq_goal
        world.step(d.qfrc_bias[:7] + 400.0 * (q_ref - d.qpos[:7]) - 40.0 * d.qvel[:7], 0.0)
    moved = np.linalg.norm(world.state().ee_pos_m - tcp_start)
    slip = _peg_in_finger_m(world) - start
    world.close()
    assert moved > 0.15
    assert np.linalg.norm(slip[[0, 2]]) < 0.001, slip  # along the finger's face (its y is the closing axis)


def test_the_squeeze_on_the_peg_is_held_until_the_first_chunk():
    # the controller holds the gripper's command, not its measured opening: holding the opening let go of the peg
    # for the first chunk's 0.2 s (the fingers opened to the peg's faces, it dropped 2 mm)
    world = make_world("static", 0.0, task="insert", clearance_mm=1.0)
    state = world.reset(3)
    assert state.gripper_cmd_m == 0.0 and state.gripper_hold_m() == 0.0 < state.gripper_m
    reach = make_world("static", 0.0)
    reach_state = reach.reset(3)
    assert reach_state.gripper_cmd_m is None and reach_state.gripper_hold_m() == reach_state.gripper_m
    reach.close()
    source = make_expert(lead="velocity", world=world)
    cfg = StackConfig(mode="hybrid", duration_s=0.25, **task_stack_settings("insert", False))  # the first chunk at 0.2 s
    start = _peg_in_finger_m(world)
    log = run_episode(world, source, HybridController(cfg), seed=3, record=True)
    drop, cmd_m = _peg_in_finger_m(world) - start, world.gripper_command_m()
    world.close()
    assert len(log.t_s) >= 240 and cmd_m < 0.001
    assert abs(drop[2]) < 0.0003, drop


def _insert_episode(mode: str, seed: int, compliance: bool = False, noise_m: float = 0.002):
    world = make_world("static", 0.0, noise_m=noise_m, task="insert", clearance_mm=1.0)
    source = make_expert(lead="velocity", world=world)
    cfg = StackConfig(mode=mode, duration_s=6.0, **task_stack_settings("insert", compliance))
    log = run_episode(world, source, HybridController(cfg), seed=seed)
    world.close()
    return episode_metrics(log)


@pytest.mark.parametrize("seed", [1, 2])
def test_the_expert_seats_the_peg_in_hybrid_within_the_limits(seed):
    m = _insert_episode("hybrid", seed)
    assert m["success"], {k: m[k] for k in ("depth_m", "lateral_error_at_contact_m", "jams", "peg_slip_m")}
    assert m["limit_violations"] == 0 and m["contact_force_violations"] == 0
    assert m["peak_contact_force_n"] < 30.0
    assert m["peg_slip_m"] < 0.01  # held by friction through the approach and the push


def test_the_guard_keeps_a_stiff_open_loop_push_under_the_limit():
    # open loop, stiff: the peg catches on the chamfer and the reference goes on down; without the guard this
    # episode pressed 35 N for 1.8 s (measured before the guard)
    m = _insert_episode("open_loop", 0)
    assert m["contact_force_violations"] == 0 and m["peak_contact_force_n"] < 30.0
    assert m["success"]


def test_the_guard_yields_along_the_force_and_relaxes_back():
    g = ContactForceGuard(limit_n=30.0, dt_s=0.001)
    pos = np.array([0.5, 0.0, 0.1])
    assert g.apply(pos) is pos  # idle: the reference passes unchanged (reach's bits)
    g.update(None)
    assert not g.active
    g.update(np.array([0.0, 0.0, GUARD_FRACTION * 30.0 - 1.0]))  # under the threshold: nothing
    assert not g.active
    for _ in range(100):  # 25 N up on the robot for 0.1 s: the reference yields upward
        g.update(np.array([0.0, 0.0, 25.0]))
    assert g.active and g.offset_m[2] > 0.005 and abs(g.offset_m[0]) < 1e-12
    lifted = g.offset_m[2]
    for _ in range(3000):  # contact gone: back to the reference
        g.update(np.zeros(3))
    assert g.offset_m[2] < 0.01 * lifted


def test_contact_cells_of_the_sweep_leave_reach_keys_alone():
    from scenarios.sweep.study import Study, cell_key, task_grid

    reach = Study("lead", ("hybrid",), (1.0,), (200.0,), ("linear",), (0.2,), (2048,), (0,)).cells()
    assert all("task" not in c for c in reach)
    key = cell_key(reach[0], 6.0)
    assert cell_key({**reach[0], "task": "reach"}, 6.0) == key  # the same key as before tasks existed
    insert = [c for s in task_grid("insert") for c in s.cells()]
    assert {c["clearance_mm"] for c in insert} == {3.0, 1.0, 0.5, 0.25}
    assert {c["bins"] for c in insert} == {256, 1024, 2048, 8192}
    assert {c["noise_m"] for c in insert} == {0.0, 0.002} and {c["compliance"] for c in insert} == {False, True}
    assert len({cell_key(c, 6.0) for c in insert}) == len(insert)
    with pytest.raises(ValueError, match="unknown task"):
        Study("x", ("hybrid",), (1.0,), (200.0,), ("static",), (0.0,), (2048,), (0,), task="screw")
