"""Tests of the simulated world: target motions, the MuJoCo scene, SimWorld, video output."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from scenarios.world.sim_world import SimWorld  # first: sets MUJOCO_GL before mujoco is imported

import mujoco  # noqa: E402

from controllers.robot_description import HOME_Q_RAD, JointLimits  # noqa: E402
from scenarios.world.panda_scene import (  # noqa: E402
    GRIPPER_MAX_M,
    SceneConfig,
    arm_dof_adr,
    build_panda_model,
    home_tcp_pos_m,
    tcp_site_id,
)
from scenarios.world.targets import HOME_TCP_POS_M, KINDS, TargetSpec, make_motion  # noqa: E402
from scenarios.world.video import write_mp4  # noqa: E402

SEEDS = range(6)


# ------------------------------------------------------------------ targets


def _sample(motion, t_end_s: float = 20.0, dt_s: float = 1e-3) -> tuple[np.ndarray, np.ndarray]:
    times = np.arange(0.0, t_end_s, dt_s)
    return times, np.array([motion.pos_m(t) for t in times])


@pytest.mark.parametrize("kind", KINDS)
def test_targets_stay_in_workspace_and_are_deterministic(kind):
    spec = TargetSpec(kind=kind)
    for seed in SEEDS:
        _, pos = _sample(make_motion(spec, seed), t_end_s=12.0, dt_s=5e-3)
        assert np.all(pos >= spec.low - 1e-9) and np.all(pos <= spec.high + 1e-9), (kind, seed)
        _, again = _sample(make_motion(spec, seed), t_end_s=12.0, dt_s=5e-3)
        np.testing.assert_array_equal(pos, again)
    a = make_motion(spec, 0).pos_m(0.0)
    b = make_motion(spec, 1).pos_m(0.0)
    assert not np.allclose(a, b)


@pytest.mark.parametrize("kind", KINDS)
def test_targets_start_away_from_home_tcp(kind):
    spec = TargetSpec(kind=kind)
    home = home_tcp_pos_m()
    for seed in range(40):
        assert np.linalg.norm(make_motion(spec, seed).pos_m(0.0) - home) >= spec.min_start_dist_m - 1e-3


def test_home_tcp_constant_matches_model():
    np.testing.assert_allclose(HOME_TCP_POS_M, home_tcp_pos_m(), atol=1e-3)


@pytest.mark.parametrize("kind", ["linear", "circle", "random_walk"])
@pytest.mark.parametrize("speed_m_s", [0.1, 0.3])
def test_targets_move_at_the_asked_speed(kind, speed_m_s):
    spec = TargetSpec(kind=kind, speed_m_s=speed_m_s)
    for seed in SEEDS[:3]:
        times, pos = _sample(make_motion(spec, seed), t_end_s=10.0, dt_s=1e-3)
        speed = np.linalg.norm(np.diff(pos, axis=0), axis=1) / np.diff(times)
        # wall bounces (and random-walk grid corners) shorten a few finite differences, never lengthen them
        assert np.max(speed) <= speed_m_s * (1 + 1e-6), (kind, seed)
        assert np.median(speed) == pytest.approx(speed_m_s, rel=1e-3), (kind, seed)
        assert np.mean(np.abs(speed - speed_m_s) < 1e-3 * speed_m_s) > 0.9, (kind, seed)


def test_static_target_does_not_move():
    motion = make_motion(TargetSpec(kind="static"), 3)
    np.testing.assert_array_equal(motion.pos_m(0.0), motion.pos_m(7.3))
    assert motion.jump_times_s == ()


def test_circle_is_horizontal_with_the_asked_radius():
    spec = TargetSpec(kind="circle", circle_radius_m=0.06)
    _, pos = _sample(make_motion(spec, 2), t_end_s=5.0, dt_s=1e-2)
    assert np.ptp(pos[:, 2]) < 1e-12
    centre = 0.5 * (pos.min(0) + pos.max(0))
    np.testing.assert_allclose(np.linalg.norm(pos[:, :2] - centre[:2], axis=1), 0.06, atol=2e-4)


def test_jump_times_and_distances():
    spec = TargetSpec(kind="jump", jump_dist_m=0.12, jump_period_s=1.5, horizon_s=20.0)
    for seed in SEEDS:
        motion = make_motion(spec, seed)
        times = np.asarray(motion.jump_times_s)
        assert 1.0 <= times[0] <= 2.0
        np.testing.assert_allclose(np.diff(times), 1.5)
        assert times[-1] < 20.0 and times[-1] + 1.5 >= 20.0
        for t in times:
            before, after = motion.pos_m(t - 1e-6), motion.pos_m(t)
            assert np.linalg.norm(after - before) == pytest.approx(0.12, abs=1e-9)
            np.testing.assert_array_equal(after, motion.pos_m(t + 0.5 * 1.5))  # constant between jumps
            assert np.all(after >= spec.low) and np.all(after <= spec.high)
        np.testing.assert_array_equal(motion.pos_m(0.0), motion.pos_m(times[0] - 1e-6))


@pytest.mark.parametrize(
    ("changes", "named"),
    [
        ({"kind": "teleport"}, "teleport"),
        ({"speed_m_s": -0.5}, "-0.5"),
        ({"speed_m_s": float("nan")}, "nan"),
        ({"workspace_low_m": (0.7, -0.3, 0.15)}, "0.7"),
        ({"workspace_low_m": (0.3, 0.0)}, "workspace_low_m"),
        ({"kind": "circle", "circle_radius_m": 0.2}, "0.2"),
        ({"circle_radius_m": 0.0}, "circle_radius_m"),
        ({"kind": "jump", "jump_dist_m": 0.5}, "0.5"),
        ({"jump_period_s": -1.0}, "-1.0"),
    ],
)
def test_bad_target_specs_raise_naming_the_value(changes, named):
    with pytest.raises(ValueError, match=named.replace(".", r"\.").replace("-", r"\-")):
        TargetSpec(**changes)


def test_bad_time_raises():
    with pytest.raises(ValueError, match="-1"):
        make_motion(TargetSpec(), 0).pos_m(-1.0)


# ------------------------------------------------------------------ scene


def test_scene_model_settings():
    scene = SceneConfig(armature_kgm2=(0.2,) * 7, n_objects=2)
    model = build_panda_model(scene)
    assert model.opt.timestep == pytest.approx(0.001)
    assert model.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    np.testing.assert_allclose(model.dof_armature[arm_dof_adr(model)], 0.2)
    tau_max = np.asarray(JointLimits().tau_max_nm)
    np.testing.assert_allclose(model.actuator_ctrlrange[:7], np.column_stack([-tau_max, tau_max]))
    np.testing.assert_allclose(model.actuator_gear[:7, 0], 1.0)
    assert model.nmocap == 2
    for name in ("front", "top", "side"):
        assert mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, name) >= 0
    with pytest.raises(ValueError, match="3"):
        SceneConfig(n_objects=3)
    with pytest.raises(ValueError, match="'back'"):
        SceneConfig(camera_names=("back",))


def test_robot_collides_with_table_not_itself():
    model = build_panda_model(SceneConfig())
    table = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "table")
    robot = [g for g in range(model.ngeom) if model.geom_bodyid[g] != 0 and model.body_mocapid[model.geom_bodyid[g]] < 0]

    def collide(a: int, b: int) -> bool:
        return bool(model.geom_contype[a] & model.geom_conaffinity[b]) or bool(model.geom_contype[b] & model.geom_conaffinity[a])

    assert all(collide(g, table) for g in robot)
    assert not any(collide(a, b) for a in robot for b in robot)
    for mocap_geom in np.flatnonzero(model.body_mocapid[model.geom_bodyid] >= 0):
        assert model.geom_contype[mocap_geom] == 0 and model.geom_conaffinity[mocap_geom] == 0


# ------------------------------------------------------------------ world


@pytest.fixture()
def world():
    w = SimWorld(SceneConfig(), TargetSpec(kind="linear"), noise_m=0.002)
    yield w
    w.close()


def test_reset_state(world):
    state = world.reset(5)
    np.testing.assert_allclose(state.q_rad, HOME_Q_RAD)
    np.testing.assert_array_equal(state.dq_rad_s, 0.0)
    assert state.t_s == 0.0 and state.gripper_m == pytest.approx(GRIPPER_MAX_M)
    np.testing.assert_allclose(state.ee_pos_m, home_tcp_pos_m(world.model), atol=1e-12)
    np.testing.assert_allclose(world.target_pos_m(), make_motion(world.target, 5).pos_m(0.0))
    assert world.instruction and "red" in world.instruction
    assert world.target_jump_times_s() == ()


def test_gravity_compensation_holds_home_and_objects_move(world):
    world.reset(0)
    dof = arm_dof_adr(world.model)
    start_target = world.target_pos_m()
    for _ in range(1000):  # 1 s
        world.step(world.data.qfrc_bias[dof].copy(), GRIPPER_MAX_M)
    state = world.state()
    assert state.t_s == pytest.approx(1.0)
    np.testing.assert_allclose(state.q_rad, HOME_Q_RAD, atol=1e-3)
    np.testing.assert_allclose(state.ee_pos_m, home_tcp_pos_m(world.model), atol=1e-3)
    assert np.linalg.norm(world.target_pos_m() - start_target) > 0.05  # 0.2 m/s for 1 s, bounces aside
    # the TCP reported is that of the current qpos, and the mocap body is at the target
    data = mujoco.MjData(world.model)
    data.qpos[:] = world.data.qpos
    data.mocap_pos[:] = world.data.mocap_pos
    mujoco.mj_kinematics(world.model, data)
    np.testing.assert_allclose(state.ee_pos_m, data.site_xpos[tcp_site_id(world.model)], atol=1e-12)
    np.testing.assert_allclose(world.data.mocap_pos[0], world.target_pos_m(), atol=1e-12)


def test_torques_are_clipped_to_effort_limits(world):
    world.reset(0)
    world.step(np.full(7, 500.0), GRIPPER_MAX_M)
    np.testing.assert_allclose(world.data.actuator_force[:7], JointLimits().tau_max_nm)
    world.step(np.full(7, -500.0), GRIPPER_MAX_M)
    np.testing.assert_allclose(world.data.actuator_force[:7], -np.asarray(JointLimits().tau_max_nm))
    with pytest.raises(ValueError, match="shape"):
        world.step(np.zeros(6), 0.0)


def test_gripper_follows_opening_command(world):
    world.reset(0)
    dof = arm_dof_adr(world.model)
    for command in (0.02, 0.0, 0.06):
        for _ in range(500):
            world.step(world.data.qfrc_bias[dof].copy(), command)
        assert world.state().gripper_m == pytest.approx(command, abs=2e-3)
        f1, f2 = world.data.qpos[7:9]
        assert f1 == pytest.approx(f2, abs=1e-4)


def test_measurement_noise_and_dropout():
    world = SimWorld(SceneConfig(), TargetSpec(kind="static"), noise_m=0.01, dropout=0.3)
    world.reset(1)
    n = 6000
    meas = [world.measure_target() for _ in range(n)]
    hits = np.array([m for m in meas if m is not None])
    rate = 1.0 - len(hits) / n
    assert rate == pytest.approx(0.3, abs=4 * np.sqrt(0.3 * 0.7 / n))
    err = hits - world.target_pos_m()
    np.testing.assert_allclose(err.mean(axis=0), 0.0, atol=4 * 0.01 / np.sqrt(len(hits)))
    np.testing.assert_allclose(err.std(axis=0), 0.01, rtol=4 / np.sqrt(2 * len(hits)))
    world.reset(1)  # same seed, same measurement stream
    again = [world.measure_target() for _ in range(20)]
    assert all((a is None and b is None) or np.array_equal(a, b) for a, b in zip(meas[:20], again))
    with pytest.raises(ValueError, match="1.5"):
        SimWorld(SceneConfig(), TargetSpec(), dropout=1.5)


def test_two_objects_instruction_and_separation():
    world = SimWorld(SceneConfig(n_objects=2), TargetSpec(kind="circle"))
    seen = set()
    for seed in range(12):
        world.reset(seed)
        objs = world.objects_pos_m()
        assert objs.shape == (2, 3)
        assert np.linalg.norm(objs[0] - objs[1]) >= 0.15
        np.testing.assert_array_equal(world.target_pos_m(), objs[world.target_index])
        colour, other = ("red", "blue") if world.target_index == 0 else ("blue", "red")
        assert colour in world.instruction and other not in world.instruction
        seen.add(world.target_index)
    assert seen == {0, 1}
    world.reset(3, target_index=1)
    assert world.target_index == 1 and "blue" in world.instruction
    with pytest.raises(ValueError, match="2"):
        world.reset(3, target_index=2)


def test_world_requires_reset():
    world = SimWorld(SceneConfig(), TargetSpec())
    with pytest.raises(RuntimeError, match="reset"):
        world.state()


def test_jump_world_reports_jump_times():
    world = SimWorld(SceneConfig(), TargetSpec(kind="jump"))
    world.reset(4)
    assert world.target_jump_times_s() == make_motion(world.target, 4).jump_times_s


# ------------------------------------------------------------------ rendering and video


def test_render_shape_and_content():
    scene = SceneConfig(image_size_px=64, camera_names=("front", "top"))
    world = SimWorld(scene, TargetSpec(kind="static"))
    world.reset(0)
    try:
        frames = world.render()
    except RuntimeError as exc:
        if "renderer" in str(exc):
            pytest.skip(f"no offscreen OpenGL (EGL) here: {exc}")
        raise
    try:
        assert frames.shape == (2, 64, 64, 3) and frames.dtype == np.uint8
        for view in frames:
            assert view.std() > 10.0
        red = (frames[..., 0] > 150) & (frames[..., 1] < 80) & (frames[..., 2] < 80)
        assert red.sum() >= 3  # the red target is seen
        world.step(np.zeros(7), GRIPPER_MAX_M)
        assert world.render().shape == (2, 64, 64, 3)
    finally:
        world.close()


def test_write_mp4(tmp_path):
    frames = [np.full((2, 32, 32, 3), 10 * i, dtype=np.uint8) for i in range(8)]
    path = write_mp4(frames, tmp_path / "clip.mp4", fps=10)
    assert path.is_file() and path.stat().st_size > 0
    with pytest.raises(ValueError, match="no frames"):
        write_mp4([], tmp_path / "empty.mp4", fps=10)


def test_configs_are_frozen():
    with pytest.raises(dataclasses.FrozenInstanceError):
        SceneConfig().dt_s = 0.002  # type: ignore[misc]
    with pytest.raises(dataclasses.FrozenInstanceError):
        TargetSpec().kind = "linear"  # type: ignore[misc]
