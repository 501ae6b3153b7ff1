"""Tests of the rendered camera sensor: accuracy vs distance, latency, frame rate, occlusion, bad values.

Measured on this scene (front camera, 160x120, depth noise 0.001 m/m^2, 20 frames per position):
mean centre error ~0.25 mm at 0.97 m, ~0.5-0.7 mm at 1.25 m, ~1.2 mm at 1.56 m, worst frame 1.9 mm;
without depth noise ~0.2 mm everywhere (the rendered sphere is a tessellation slightly inside the true
one). The bounds below are about twice the measured worst cases.
"""

from __future__ import annotations

import numpy as np
import pytest

from scenarios.world.sim_world import SimWorld  # first: sets MUJOCO_GL before mujoco is imported

import mujoco  # noqa: E402

from controllers.robot_description import HOME_Q_RAD  # noqa: E402
from scenarios.world.camera_sensor import CameraSensor, CameraSensorConfig  # noqa: E402
from scenarios.world.panda_scene import HAND_BODY, SceneConfig  # noqa: E402
from scenarios.world.targets import TargetSpec  # noqa: E402

#: workspace points at increasing distance from the ``front`` camera (0.97, 1.25, 1.56 m)
NEAR, MID, FAR = (0.65, -0.3, 0.45), (0.5, 0.0, 0.3), (0.35, 0.3, 0.15)
#: per-frame centre error bound with the default depth noise (measured worst 1.9 mm)
MAX_ERR_M = 0.004
#: error bound without depth noise (measured 0.25 mm: tessellation, not pixels)
MAX_ERR_NOISELESS_M = 0.0005


@pytest.fixture
def world():
    w = SimWorld(SceneConfig(), TargetSpec(kind="static"), noise_m=0.0)
    w.reset(0)
    yield w
    w.close()


def _place(world: SimWorld, pos) -> np.ndarray:
    p = np.asarray(pos, dtype=float)
    world.data.mocap_pos[world._mocap[world.target_index]] = p
    return p


def _cam_pos(world: SimWorld, name: str = "front") -> np.ndarray:
    mujoco.mj_camlight(world.model, world.data)
    return world.data.cam_xpos[mujoco.mj_name2id(world.model, mujoco.mjtObj.mjOBJ_CAMERA, name)].copy()


def _errors(sensor: CameraSensor, truth: np.ndarray, n_frames: int) -> np.ndarray:
    """Centre errors (m) of ``n_frames`` frames polled one frame period apart (latency 0)."""
    sensor.reset(0)
    errs = []
    for k in range(n_frames):
        (m,) = sensor.poll(k / sensor.config.rate_hz)
        assert m.pos_m is not None and m.status == "detected", m
        errs.append(np.linalg.norm(m.pos_m - truth))
    return np.asarray(errs)


# ------------------------------------------------------------------ accuracy


def test_static_ball_accuracy_and_error_grows_with_distance(world):
    cam = _cam_pos(world)
    with CameraSensor(world, CameraSensorConfig(latency_ms=0.0)) as noisy, \
            CameraSensor(world, CameraSensorConfig(latency_ms=0.0, depth_noise_m_per_m2=0.0)) as clean:
        dists, means = [], []
        for pos in (NEAR, MID, FAR):
            truth = _place(world, pos)
            errs = _errors(noisy, truth, 20)
            assert errs.max() < MAX_ERR_M, (pos, errs.max())
            assert _errors(clean, truth, 2).max() < MAX_ERR_NOISELESS_M, pos
            dists.append(np.linalg.norm(truth - cam))
            means.append(errs.mean())
        assert dists == sorted(dists) and dists[0] < 1.0 and dists[-1] > 1.5, dists
        # depth noise std ~ d^2: the mean error grows with distance
        assert means[0] < means[1] < means[2], means
        assert means[2] > 2.0 * means[0], means


def test_same_seed_same_noise_new_seed_new_noise(world):
    _place(world, MID)
    with CameraSensor(world, CameraSensorConfig(latency_ms=0.0)) as sensor:
        sensor.reset(3)
        a = sensor.poll(0.0)[0].pos_m
        sensor.reset(3)
        b = sensor.poll(0.0)[0].pos_m
        sensor.reset(4)
        c = sensor.poll(0.0)[0].pos_m
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_measures_the_current_state_and_the_instructed_ball():
    w = SimWorld(SceneConfig(n_objects=2), TargetSpec(kind="static"), noise_m=0.0)
    try:
        with CameraSensor(w, CameraSensorConfig(latency_ms=0.0)) as sensor:
            for index in (0, 1):
                w.reset(0, target_index=index)
                w.data.mocap_pos[w._mocap[0]] = NEAR
                w.data.mocap_pos[w._mocap[1]] = FAR
                sensor.reset(0)
                (m,) = sensor.poll(0.0)
                assert np.linalg.norm(m.pos_m - w.target_pos_m()) < MAX_ERR_M, (index, m.pos_m)
    finally:
        w.close()


def test_two_cameras_fuse_and_cover_each_other(world):
    cfg = CameraSensorConfig(latency_ms=0.0, cameras=("front", "side"))
    with CameraSensor(world, cfg) as sensor:
        truth = _place(world, MID)
        (m,) = sensor.poll(0.0)
        assert m.camera == "front+side" and np.linalg.norm(m.pos_m - truth) < MAX_ERR_M
        # hidden from the front by the hand, still seen from the side
        truth = _place(world, _behind_hand(world))
        (m,) = sensor.poll(1.0)
        assert m.camera == "side" and m.pos_m is not None and np.linalg.norm(m.pos_m - truth) < MAX_ERR_M, m


# ------------------------------------------------------------------ timing


def test_latency_is_exact(world):
    _place(world, MID)
    with CameraSensor(world, CameraSensorConfig(rate_hz=30.0, latency_ms=50.0)) as sensor:
        sensor.reset(0)
        got = {}
        for i in range(0, 120):  # 1 kHz ticks, 0..119 ms
            for m in sensor.poll(i * 1e-3):
                got[m.t_capture_s] = (i, m)
        # frames captured at 0, 34, 67, 100 ms (first tick at or after k/30 s); each arrives 50 ms later
        assert sorted(got) == pytest.approx([0.0, 0.034, 0.067]), sorted(got)
        for t_cap, (i, m) in got.items():
            assert m.t_arrival_s == pytest.approx(t_cap + 0.050, abs=1e-12)
            assert i == round(t_cap * 1e3) + 50, (t_cap, i)  # not a tick earlier, not a tick later
        assert sensor.stats["frames"] == 4  # the 100 ms frame is still in flight
        assert sensor.poll(0.149) == [] and len(sensor.poll(0.150)) == 1
    with CameraSensor(world, CameraSensorConfig(latency_ms=0.0)) as sensor:
        (m,) = sensor.poll(0.0)  # zero latency: the frame comes back from the poll that captured it
        assert m.t_arrival_s == m.t_capture_s == 0.0


@pytest.mark.parametrize("rate_hz", [30.0, 12.5])
def test_rate_over_one_second_at_1khz(world, rate_hz):
    _place(world, MID)
    with CameraSensor(world, CameraSensorConfig(rate_hz=rate_hz, latency_ms=20.0)) as sensor:
        sensor.reset(0)
        captures = []
        for i in range(1000):
            captures += [m.t_capture_s for m in sensor.poll(i * 1e-3)]
        frames = sensor.stats["frames"]
        assert abs(frames - rate_hz) <= 1, frames
        gaps = np.diff(captures)
        assert np.all(np.abs(gaps - 1.0 / rate_hz) <= 1.0e-3 + 1e-9), gaps  # on the grid, to one tick
        # polling slower than the frame rate skips the missed frames: back at 1 kHz, the next frame is
        # the next one on the grid k / rate (not one per tick to catch up)
        sensor.reset(0)
        for i in range(10):
            sensor.poll(i * 0.1)
        assert sensor.stats["frames"] == 10
        for i in range(901, 1000):
            sensor.poll(i * 1e-3)
        assert sensor.stats["frames"] == 10 + sum(0.9 < k / rate_hz < 0.999 for k in range(100)), sensor.stats


def test_capture_cost_is_reported(world):
    _place(world, MID)
    with CameraSensor(world, CameraSensorConfig(latency_ms=0.0)) as sensor:
        sensor.poll(0.0)  # first frame pays for GL setup
        sensor.reset(0)
        for k in range(10):
            sensor.poll(k / 30.0)
        ms = sensor.stats["render_ms_total"] / sensor.stats["frames"]
    print(f"camera capture: {ms:.2f} ms/frame, {30 * ms:.0f} ms per simulated second at 30 Hz")
    assert 0.0 < ms < 50.0, ms  # ~3 ms here; 50 ms would mean shadows/MSAA crept back into the render


# ------------------------------------------------------------------ occlusion


def _hand_geom_pos(world: SimWorld) -> np.ndarray:
    """Centre of the hand geom (the link-7 geom nearest the TCP)."""
    mujoco.mj_kinematics(world.model, world.data)
    body = mujoco.mj_name2id(world.model, mujoco.mjtObj.mjOBJ_BODY, HAND_BODY)
    geoms = range(world.model.body_geomadr[body], world.model.body_geomadr[body] + world.model.body_geomnum[body])
    tcp = world.state().ee_pos_m
    return min((world.data.geom_xpos[g].copy() for g in geoms), key=lambda p: np.linalg.norm(p - tcp))


def _behind_hand(world: SimWorld, beyond_m: float = 0.15) -> np.ndarray:
    """A point on the camera -> hand ray, ``beyond_m`` past the hand (the open fingers leave a gap at the TCP)."""
    cam, hand = _cam_pos(world), _hand_geom_pos(world)
    ray = (hand - cam) / np.linalg.norm(hand - cam)
    return hand + beyond_m * ray


def test_ball_behind_the_hand_is_occluded_and_visible_when_the_arm_moves(world):
    with CameraSensor(world, CameraSensorConfig(latency_ms=0.0)) as sensor:
        truth = _place(world, _behind_hand(world))
        (m,) = sensor.poll(0.0)
        assert m.pos_m is None and m.status == "occluded" and m.n_pixels < sensor.config.min_pixels, m
        assert sensor.stats["occluded"] == 1 and sensor.stats["detections"] == 0
        # same ball, arm swung away (base joint +0.8 rad): now seen, and where it is
        q = np.array(HOME_Q_RAD, dtype=float)
        q[0] += 0.8
        world.set_arm_state(q)
        (m,) = sensor.poll(1.0)
        assert m.status == "detected" and np.linalg.norm(m.pos_m - truth) < MAX_ERR_M, m
        # out of the image entirely: a different miss
        _place(world, (3.0, 3.0, 0.3))
        (m,) = sensor.poll(2.0)
        assert m.pos_m is None and m.status == "out_of_view" and m.n_pixels == 0
        stats = sensor.stats
        assert (stats["frames"], stats["detections"], stats["occluded"], stats["out_of_view"]) == (3, 1, 1, 1), stats


# ------------------------------------------------------------------ bad values


@pytest.mark.parametrize("kwargs, pattern", [
    ({"rate_hz": 0}, r"rate_hz.*got 0"),
    ({"rate_hz": -5.0}, r"rate_hz.*-5"),
    ({"latency_ms": -1}, r"latency_ms.*got -1"),
    ({"cameras": ()}, r"cameras.*\(\)"),
    ({"width_px": 4}, r"width_px.*got 4"),
    ({"height_px": 7}, r"height_px.*got 7"),
    ({"min_pixels": 0}, r"min_pixels.*got 0"),
    ({"depth_noise_m_per_m2": -0.1}, r"depth_noise_m_per_m2.*-0.1"),
])
def test_bad_config_values(kwargs, pattern):
    with pytest.raises(ValueError, match=pattern) as info:
        CameraSensorConfig(**kwargs)
    assert "\n" not in str(info.value)


def test_unknown_camera_and_oversized_image(world):
    with pytest.raises(ValueError, match=r"unknown camera 'wrist'; the scene has: front, top, side"):
        CameraSensor(world, CameraSensorConfig(cameras=("front", "wrist")))
    with pytest.raises(ValueError, match=r"1000x120 px exceeds"):
        CameraSensor(world, CameraSensorConfig(width_px=1000))
    with CameraSensor(world, CameraSensorConfig()) as sensor:
        sensor.poll(0.5)
        with pytest.raises(ValueError, match=r"poll time went back"):
            sensor.poll(0.1)
        with pytest.raises(ValueError, match=r"finite.*nan"):
            sensor.poll(float("nan"))
