"""The Gymnasium environment: Gymnasium's own checker, determinism, refused chunks, termination, the vector env,
and agreement with the main job on the same seeds."""

import json
import subprocess
import sys
import warnings
from pathlib import Path

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import mmact_ctrl  # noqa: F401  (registers the environment)
from scenarios.world.factory import make_expert
from scenarios.world.gym_env import ENV_ID, as_observation

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("mode", ["open_loop", "hybrid"])
@pytest.mark.parametrize("cameras", [("front",), ("front", "side")])
def test_gymnasiums_checker_passes(mode, cameras):
    env = gymnasium.make(ENV_ID, mode=mode, cameras=cameras, duration_s=2.5, render_mode="rgb_array")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # no warning either (bounds, dtypes, determinism)
            check_env(env.unwrapped)
        frame = env.unwrapped.render()
        assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
        assert env.unwrapped.metadata["render_fps"] == 1.0
    finally:
        env.close()
        env.close()  # twice is fine


def _hold(obs, horizon=16):
    """A chunk that holds the TCP where it is (gripper open)."""
    w = np.zeros((horizon, 7))
    w[:, :3] = obs["tcp_pose"][:3]
    w[:, 3:6] = obs["tcp_pose"][3:]
    w[:, 6] = 0.08
    return w


def test_the_same_seed_and_actions_give_the_same_episode():
    env = gymnasium.make(ENV_ID, target="reversal", mode="hybrid", cameras=("front",), duration_s=3.0,
                         terminate_on_success=False)
    runs = []
    for _ in range(2):
        obs, info = env.reset(seed=11)
        expert = make_expert(lead="velocity", world=env.unwrapped.world)
        trace = [obs["pixels"]["front"].copy()]
        for _ in range(2):
            obs, reward, term, trunc, info = env.step(expert.plan(as_observation(info)).waypoints)
            trace += [obs["agent_pos"].copy(), reward]
        runs.append(trace)
    env.close()
    for a, b in zip(*runs):
        assert np.array_equal(a, b)


def test_a_nan_or_misshapen_chunk_is_refused_and_a_valid_one_still_runs():
    env = gymnasium.make(ENV_ID, target="static", mode="hybrid", cameras=(), duration_s=2.0)
    obs, info = env.reset(seed=0)
    t0 = info["t_s"]
    bad = _hold(obs)
    bad[5, 1] = np.nan
    with pytest.raises(ValueError, match=r"NaN or inf \(first at waypoint 5, dim 1\)"):
        env.step(bad)
    with pytest.raises(ValueError, match=r"shape \(16, 7\).*got \(3,\)"):
        env.step(np.zeros(3))
    with pytest.raises(ValueError, match=r"shape \(16, 7\).*got \(16, 6\)"):
        env.step(np.zeros((16, 6)))
    obs2, reward, term, trunc, info2 = env.step(_hold(obs))  # the episode was left as it was
    assert info2["t_s"] == pytest.approx(t0 + 1.0) and info2["limit_violations"] == 0 and not info2["rejections"]
    assert np.isfinite(reward)
    env.close()


def test_terminated_when_the_expert_reaches_a_static_target():
    env = gymnasium.make(ENV_ID, target="static", mode="hybrid", cameras=(), duration_s=6.0)
    obs, info = env.reset(seed=2)
    expert = make_expert(lead="velocity", world=env.unwrapped.world)
    for step in range(6):
        obs, reward, terminated, truncated, info = env.step(expert.plan(as_observation(info)).waypoints)
        if terminated or truncated:
            break
    assert terminated and not truncated and step < 5
    assert info["success"] and info["episode"]["success"] and reward > 0.5  # the bonus, minus a few mm
    assert info["episode"]["limit_violations"] == 0
    with pytest.raises(RuntimeError, match="call reset"):
        env.step(_hold(obs))
    env.close()


def test_truncated_at_the_duration_and_the_episode_metrics_come_with_it():
    env = gymnasium.make(ENV_ID, target="linear", mode="open_loop", cameras=(), duration_s=2.0)
    obs, info = env.reset(seed=0)
    steps = 0
    while True:
        obs, reward, terminated, truncated, info = env.step(_hold(obs))
        steps += 1
        if terminated or truncated:
            break
    env.close()
    assert truncated and not terminated and steps == 2
    assert {"success", "final_error_m", "limit_violations", "tick_us_median"} <= set(info["episode"])


def test_two_environments_run_vectorized():
    # spawn, not fork: a forked MuJoCo renderer (EGL) can deadlock in the child; the "mmact_ctrl:" prefix makes
    # each fresh child import the package that registers the environment
    envs = gymnasium.vector.AsyncVectorEnv([lambda: gymnasium.make("mmact_ctrl:" + ENV_ID, target="static",
                                                                   cameras=("front",), duration_s=2.0)] * 2,
                                           context="spawn")
    try:
        obs, info = envs.reset(seed=[0, 1])
        assert obs["pixels"]["front"].shape == (2, 96, 96, 3) and obs["agent_pos"].shape == (2, 8)
        assert not np.array_equal(obs["pixels"]["front"][0], obs["pixels"]["front"][1])  # two scenes
        actions = np.stack([_hold({"tcp_pose": p}) for p in obs["tcp_pose"]]).astype(np.float32)
        obs, reward, terminated, truncated, info = envs.step(actions)
        assert reward.shape == (2,) and np.all(np.isfinite(reward)) and not truncated.any()
    finally:
        envs.close()


def test_the_readme_example_agrees_with_the_main_job_on_the_same_seeds(tmp_path):
    sys.path.insert(0, str(REPO))
    from examples.gym_expert import run

    env_runs = run(episodes=3, mode="hybrid", target="linear")
    out = tmp_path / "mt.json"
    subprocess.run([sys.executable, "-m", "scenarios.moving_target", "--source", "expert", "--mode", "hybrid",
                    "--target", "linear", "--episodes", "3", "--quiet", "--json", str(out)], check=True, cwd=REPO,
                   capture_output=True, timeout=300)
    main_runs = json.loads(out.read_text())["episodes"]
    for a, b in zip(env_runs, main_runs):
        assert a["success"] == b["success"]
        assert round(1000 * a["final_error_m"], 1) == round(1000 * b["final_error_m"], 1)


def test_registered_on_import_and_with_the_module_prefix():
    code = ("import gymnasium; env = gymnasium.make('mmact_ctrl:mmact_ctrl/MovingTarget-v0', cameras=()); "
            "obs, info = env.reset(seed=0); print(sorted(obs)); env.close()")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "['agent_pos', 'instruction', 'tcp_pose']" in out.stdout


def test_a_bad_setting_is_one_clear_error():
    with pytest.raises(ValueError, match="unknown setting 'sped'"):
        gymnasium.make(ENV_ID, sped=0.3)
    with pytest.raises(ValueError, match="replan_hz"):
        gymnasium.make(ENV_ID, replan_hz=-1.0)
