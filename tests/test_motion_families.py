"""The target motion families with abrupt course changes (``reversal``, ``swerve``, ``accelerating``) and
``change_times_s`` on every family (``scenarios.world.targets``)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from scenarios.world.targets import KINDS, TargetSpec, make_motion, target_spec

NEW_KINDS = ("reversal", "swerve", "accelerating")
SEEDS = (0, 1, 2, 7)
PLANE_Z_M = (0.0, 0.1)  # the full 3-D box, a flat workspace at 10 cm
GRID_DT_S = 0.01


def _positions_m(motion, t_end_s: float = 10.0, dt_s: float = 1e-3) -> tuple[np.ndarray, np.ndarray]:
    times_s = np.arange(0.0, t_end_s, dt_s)
    return times_s, np.array([motion.pos_m(t) for t in times_s])


def _course_around_m_s(motion, t_c_s: float, n_steps: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Velocities over the ``n_steps`` grid segments before and after the one holding ``t_c_s`` (near a
    wall bounce their speed is low: a bounce shortens the chord)."""
    k = int(math.floor(t_c_s / GRID_DT_S))
    p = lambda i: motion.pos_m(i * GRID_DT_S)  # noqa: E731
    before = (p(k) - p(k - n_steps)) / (n_steps * GRID_DT_S)
    after = (p(k + 1 + n_steps) - p(k + 1)) / (n_steps * GRID_DT_S)
    return before, after


def _straight(v_m_s: np.ndarray, speed_m_s: float) -> bool:
    return abs(float(np.linalg.norm(v_m_s)) - speed_m_s) < 1e-6 * speed_m_s


@pytest.mark.parametrize("plane_z_m", PLANE_Z_M)
@pytest.mark.parametrize("kind", NEW_KINDS)
def test_new_families_are_deterministic_and_stay_in_the_box(kind, plane_z_m):
    spec = target_spec(kind, 0.3, plane_z_m)
    for seed in SEEDS:
        motion = make_motion(spec, seed)
        _, pos_m = _positions_m(motion)
        assert np.all(pos_m >= spec.low - 1e-9) and np.all(pos_m <= spec.high + 1e-9), (kind, seed)
        again = make_motion(spec, seed)
        np.testing.assert_array_equal(pos_m, _positions_m(again)[1])
        assert again.change_times_s == motion.change_times_s
        assert np.linalg.norm(pos_m[0] - np.asarray(spec.avoid_pos_m)) >= spec.min_start_dist_m
        if plane_z_m > 0:  # a flat workspace stays flat
            assert np.ptp(pos_m[:, 2]) < 1e-12, (kind, seed)
    assert not np.allclose(make_motion(spec, 0).pos_m(3.0), make_motion(spec, 1).pos_m(3.0))


@pytest.mark.parametrize("plane_z_m", PLANE_Z_M)
@pytest.mark.parametrize("kind", ["reversal", "swerve"])
@pytest.mark.parametrize("speed_m_s", [0.1, 0.3])
def test_reversal_and_swerve_keep_their_speed(kind, speed_m_s, plane_z_m):
    spec = target_spec(kind, speed_m_s, plane_z_m)
    for seed in SEEDS[:3]:
        motion = make_motion(spec, seed)
        times_s, pos_m = _positions_m(motion)
        speed = np.linalg.norm(np.diff(pos_m, axis=0), axis=1) / np.diff(times_s)
        # a change or a wall bounce inside a 10 ms grid segment shortens its chord, never lengthens it
        assert np.max(speed) <= speed_m_s * (1 + 1e-6), (kind, seed)
        assert np.mean(np.abs(speed - speed_m_s) < 1e-6 * speed_m_s) > 0.9, (kind, seed)
        # every grid segment that holds no change (and no bounce) is at the exact speed
        changes = np.asarray(motion.change_times_s)
        free = np.setdiff1d(np.arange(1000), np.floor(changes / GRID_DT_S).astype(int))
        chord = np.array([np.linalg.norm(motion.pos_m((k + 1) * GRID_DT_S) - motion.pos_m(k * GRID_DT_S)) for k in free])
        assert np.mean(np.abs(chord / GRID_DT_S - speed_m_s) < 1e-6 * speed_m_s) > 0.95, (kind, seed)


@pytest.mark.parametrize("kind", ["reversal", "swerve"])
def test_change_times_follow_the_gaps(kind):
    spec = TargetSpec(kind=kind, horizon_s=30.0, **{f"{kind}_min_gap_s": 0.5, f"{kind}_max_gap_s": 0.7})
    for seed in SEEDS:
        times = np.asarray(make_motion(spec, seed).change_times_s)
        assert 1.0 <= times[0] <= 2.0
        assert np.all((np.diff(times) >= 0.5) & (np.diff(times) <= 0.7))
        assert times[-1] < 30.0 and times[-1] + 0.7 >= 30.0
        assert make_motion(spec, seed).jump_times_s == ()
    fixed = TargetSpec(kind=kind, **{f"{kind}_min_gap_s": 1.0, f"{kind}_max_gap_s": 1.0})
    np.testing.assert_allclose(np.diff(make_motion(fixed, 3).change_times_s), 1.0)


@pytest.mark.parametrize("plane_z_m", PLANE_Z_M)
def test_reversal_flips_the_velocity(plane_z_m):
    spec = target_spec("reversal", 0.2, plane_z_m)
    checked = 0
    for seed in SEEDS:
        motion = make_motion(spec, seed)
        for t_c in (t for t in motion.change_times_s if t < 10.0):
            before, after = _course_around_m_s(motion, t_c)
            if _straight(before, 0.2) and _straight(after, 0.2):  # no wall bounce around the flip
                np.testing.assert_allclose(after, -before, atol=1e-9)
                checked += 1
    assert checked >= 10


@pytest.mark.parametrize("plane_z_m", PLANE_Z_M)
def test_swerve_turns_by_45_to_135_degrees(plane_z_m):
    spec = target_spec("swerve", 0.2, plane_z_m)
    angles_deg = []
    for seed in SEEDS:
        motion = make_motion(spec, seed)
        for t_c in (t for t in motion.change_times_s if t < 10.0):
            before, after = _course_around_m_s(motion, t_c)
            if _straight(before, 0.2) and _straight(after, 0.2):
                cos = np.dot(before, after) / (np.linalg.norm(before) * np.linalg.norm(after))
                angles_deg.append(math.degrees(math.acos(np.clip(cos, -1.0, 1.0))))
                if plane_z_m > 0:
                    assert abs(after[2]) < 1e-12  # the turn is in the horizontal plane
    assert len(angles_deg) >= 10
    assert 45.0 - 1e-6 <= min(angles_deg) and max(angles_deg) <= 135.0 + 1e-6
    assert max(angles_deg) - min(angles_deg) > 30.0  # really drawn, not one angle


@pytest.mark.parametrize("plane_z_m", PLANE_Z_M)
def test_accelerating_sets_off_from_rest_and_peaks_at_speed(plane_z_m):
    spec = replace(target_spec("accelerating", 0.25, plane_z_m), accel_period_s=1.5, horizon_s=20.0)
    for seed in SEEDS:
        motion = make_motion(spec, seed)
        times = np.asarray(motion.change_times_s)
        assert 0.0 < times[0] <= 1.5 and times[-1] < 20.0 and times[-1] + 1.5 >= 20.0
        np.testing.assert_allclose(np.diff(times), 1.5)
        times_s, pos_m = _positions_m(motion)
        speed = np.linalg.norm(np.diff(pos_m, axis=0), axis=1) / np.diff(times_s)
        assert np.max(speed) <= 0.25 * (1 + 1e-6) and np.max(speed) > 0.99 * 0.25
        for t_c in times[times < 9.0]:  # at rest at a set-off, then speeding up
            i = int(round(t_c / 1e-3))
            assert speed[i] < 0.01 * 0.25
            assert speed[i + 300] > speed[i + 100] > speed[i]


def test_change_times_of_the_other_families():
    for kind in ("static", "linear", "circle", "random_walk"):
        assert make_motion(TargetSpec(kind=kind), 5).change_times_s == ()  # wall bounces are no changes
    jump = make_motion(TargetSpec(kind="jump"), 5)
    assert jump.change_times_s == jump.jump_times_s and len(jump.change_times_s) > 0
    assert set(NEW_KINDS) <= set(KINDS)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"reversal_min_gap_s": 0.0}, "reversal_min_gap_s"),
        ({"reversal_max_gap_s": -1.0}, "reversal_max_gap_s"),
        ({"swerve_min_gap_s": float("nan")}, "swerve_min_gap_s"),
        ({"accel_period_s": 0.0}, "accel_period_s"),
        ({"reversal_min_gap_s": 2.0, "reversal_max_gap_s": 1.0}, "reversal_min_gap_s=2.0"),
        ({"swerve_min_gap_s": 1.7}, "swerve_max_gap_s=1.6"),
    ],
)
def test_new_fields_are_validated(kwargs, message):
    with pytest.raises(ValueError, match=message):
        TargetSpec(kind="swerve", **kwargs)


def test_sim_world_reports_change_times():
    from scenarios.world.panda_scene import SceneConfig
    from scenarios.world.sim_world import SimWorld

    world = SimWorld(SceneConfig(), TargetSpec(kind="swerve"))
    world.reset(seed=4)
    assert world.target_change_times_s() == make_motion(world.target, 4).change_times_s
    assert world.target_jump_times_s() == ()
    world.close()
