"""``mmact_ctrl.reaction``: reaction and reach times on synthetic trajectories with known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mmact_ctrl.reaction import reaction_metrics
from scenarios.world.targets import make_motion, target_spec

DT_S = 1e-3
T_S = np.arange(0.0, 4.0, DT_S)


def _line_m(x_m: np.ndarray) -> np.ndarray:
    """Points (N, 3) moving along world x at y = 0, z = 0.3."""
    return np.stack([x_m, np.zeros_like(x_m), np.full_like(x_m, 0.3)], axis=1)


def _bounce_m(t_s: np.ndarray, t_flip_s: float, speed_m_s: float = 0.2) -> np.ndarray:
    """x of a point moving at +speed that reverses sharply at ``t_flip_s``."""
    return speed_m_s * np.where(t_s < t_flip_s, t_s, 2 * t_flip_s - t_s)


def test_tcp_reversing_100_ms_after_the_target():
    target = _line_m(0.4 + _bounce_m(T_S, 1.5))
    tcp = _line_m(0.39 + _bounce_m(T_S, 1.6))
    out = reaction_metrics(T_S, tcp, target, (1.5,))
    assert out["reaction_s"] == pytest.approx(0.1, abs=0.03)
    assert (out["n_changes"], out["n_evaluated"], out["reacted"]) == (1, 1, 1)
    assert out["reaction_times_s"] == [out["reaction_s"]]


def test_tcp_braking_gradually_reacts_at_its_onset():
    """Braking at 4 m/s^2 from 0.1 s after the flip: the velocity change reaches 0.05 m/s 12.5 ms later."""
    target = _line_m(0.4 + _bounce_m(T_S, 1.5))
    s = np.clip(T_S - 1.6, 0.0, 0.1)  # braking time so far, s
    tcp_x = 0.39 + 0.2 * T_S - 2.0 * s**2 - 0.4 * np.clip(T_S - 1.7, 0.0, None)  # -0.2 m/s after braking
    out = reaction_metrics(T_S, _line_m(tcp_x), target, (1.5,))
    assert out["reaction_s"] == pytest.approx(0.1125, abs=0.01)


def test_tcp_that_never_turns_gives_nan():
    target = _line_m(0.4 + _bounce_m(T_S, 1.5))
    tcp = _line_m(0.39 + 0.2 * T_S)
    out = reaction_metrics(T_S, tcp, target, (1.5,))
    assert math.isnan(out["reaction_s"]) and out["reacted"] == 0 and out["n_evaluated"] == 1


def test_swerve_by_45_degrees():
    """A TCP that copies a 45 deg swerve 0.1 s late reacts at 0.1 s (the component along the new course
    barely changes at 45 deg, the projection on the target's velocity change does)."""
    t_c_s, a = 1.5, math.radians(45.0)
    new_dir = np.array([math.cos(a), math.sin(a), 0.0])

    def path_m(t_turn_s: float) -> np.ndarray:
        before = np.minimum(T_S, t_turn_s)[:, None] * np.array([0.2, 0.0, 0.0])
        return np.array([0.4, 0.0, 0.3]) + before + 0.2 * np.clip(T_S - t_turn_s, 0.0, None)[:, None] * new_dir

    out = reaction_metrics(T_S, path_m(t_c_s + 0.1) - [0.01, 0, 0], path_m(t_c_s), (t_c_s,))
    assert out["reaction_s"] == pytest.approx(0.1, abs=0.03)


def test_jump_reaction_and_reach():
    """Target jumps 0.15 m at 1 s; the TCP sets off toward it at 0.3 m/s 0.1 s later: it is within 3 cm
    after 0.1 + 0.12 / 0.3 = 0.5 s."""
    target = _line_m(np.where(T_S < 1.0, 0.4, 0.55))
    tcp = _line_m(0.4 + 0.3 * np.clip(T_S - 1.1, 0.0, 0.15 / 0.3))
    out = reaction_metrics(T_S, tcp, target, (1.0,))
    assert out["reaction_s"] == pytest.approx(0.1, abs=0.03)
    assert out["reach_after_change_s"] == pytest.approx(0.5, abs=2 * DT_S)
    assert out["reach_times_s"][0] == out["reach_after_change_s"] and out["reached"] == 1


def test_window_past_the_end_and_changes_after_it():
    target = _line_m(0.4 + _bounce_m(T_S, 3.0))
    tcp = _line_m(0.39 + _bounce_m(T_S, 3.1))
    out = reaction_metrics(T_S, tcp, target, (3.0, 5.0))  # 3.0 + 1.5 s > 4 s; 5.0 s is after the episode
    assert out["n_changes"] == 1 and out["n_evaluated"] == 0
    assert math.isnan(out["reaction_times_s"][0]) and math.isnan(out["reach_times_s"][0])
    assert math.isnan(out["reaction_s"]) and math.isnan(out["reach_after_change_s"])


def test_reach_nan_when_never_within_radius():
    target = _line_m(np.where(T_S < 1.0, 0.4, 0.55))
    tcp = _line_m(np.full_like(T_S, 0.4))
    out = reaction_metrics(T_S, tcp, target, (1.0,))
    assert math.isnan(out["reach_after_change_s"]) and out["reached"] == 0 and out["reacted"] == 0


@pytest.mark.parametrize("kind", ["reversal", "swerve"])
def test_a_delayed_copy_of_a_real_motion_reacts_after_the_delay(kind):
    for seed in (0, 1, 2):
        motion = make_motion(target_spec(kind, 0.2), seed)
        target = np.array([motion.pos_m(t) for t in T_S])
        tcp = np.array([motion.pos_m(max(0.0, t - 0.15)) for t in T_S])
        out = reaction_metrics(T_S, tcp, target, motion.change_times_s)
        assert out["reacted"] == out["n_evaluated"] >= 1
        assert out["reaction_s"] == pytest.approx(0.15, abs=0.03), (kind, seed)


def test_bad_inputs():
    with pytest.raises(ValueError, match="ee_pos_m"):
        reaction_metrics(T_S, np.zeros((3, 3)), np.zeros((len(T_S), 3)), ())
    with pytest.raises(ValueError, match="window_s"):
        reaction_metrics(T_S, np.zeros((len(T_S), 3)), np.zeros((len(T_S), 3)), (), window_s=0.1)
