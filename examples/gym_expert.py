"""The README's Gymnasium example: the scripted expert drives ``mmact_ctrl/MovingTarget-v0``, one chunk per step.

    python examples/gym_expert.py --episodes 20 --mode hybrid --target linear

prints success and final error per seed: the same as ``python -m scenarios.moving_target --source expert
--mode hybrid --target linear --episodes 20`` (same seeds, same chunks, same loop).
"""

import argparse

import gymnasium

import mmact_ctrl  # noqa: F401  (importing it registers the environment)
from scenarios.world.factory import make_expert
from scenarios.world.gym_env import as_observation


def run(episodes: int = 20, mode: str = "hybrid", target: str = "linear") -> list[dict]:
    env = gymnasium.make("mmact_ctrl/MovingTarget-v0", target=target, mode=mode, cameras=(), terminate_on_success=False)
    expert = make_expert(lead="velocity", world=env.unwrapped.world)  # it reads the target from info["observation"]
    results = []
    for seed in range(episodes):
        obs, info = env.reset(seed=seed)
        done = False
        while not done:
            chunk = expert.plan(as_observation(info)).waypoints  # (16, 7): TCP position, rotation vector, gripper
            obs, reward, terminated, truncated, info = env.step(chunk)
            done = terminated or truncated
        results.append(info["episode"])
    env.close()
    return results


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--episodes", type=int, default=20)
    p.add_argument("--mode", default="hybrid")
    p.add_argument("--target", default="linear")
    a = p.parse_args()
    for seed, m in enumerate(run(a.episodes, a.mode, a.target)):
        print(f"seed {seed:2d}: success {m['success']!s:5}  final error {1000 * m['final_error_m']:.1f} mm")
