"""What the Gymnasium wrapper costs: environment steps per second against the main job's loop on the same work.

    python -m scenarios.gym_bench [--episodes 5] [--json PATH]

Both sides run the same episodes (hybrid, the scripted expert leading, one camera rendered at every query, the
same seeds): the environment steps ``mmact_ctrl/MovingTarget-v0`` with the expert's chunks (observations, the
reward, ``info``), the main job runs ``run_episode`` with the expert asked for the same camera frame. The ratio of
their throughputs is the wrapper's cost (the goal: >= 0.8, a cost of at most 20 %).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path


class _SeeingExpert:
    """The expert, asked for the camera frame at every query as the environment renders it."""

    needs_image = True

    def __init__(self, expert) -> None:
        self.expert = expert
        self.action_token_range = expert.action_token_range

    def plan(self, observation):
        return self.expert.plan(observation)


def bench(episodes: int = 5, duration_s: float = 6.0, mode: str = "hybrid") -> dict:
    import gymnasium

    import mmact_ctrl  # noqa: F401  (registers the environment)
    from mmact_ctrl.controller import HybridController
    from mmact_ctrl.loop import run_episode
    from scenarios.world.factory import make_expert
    from scenarios.world.gym_env import ENV_ID, as_observation
    from scenarios.moving_target import build_parser, make_sensor, stack_config

    env = gymnasium.make(ENV_ID, mode=mode, cameras=("front",), duration_s=duration_s, terminate_on_success=False)
    world = env.unwrapped.world
    expert = make_expert(lead="velocity", world=world)
    steps = 0
    t0 = time.perf_counter()
    for seed in range(episodes):
        obs, info = env.reset(seed=seed)
        done = False
        while not done:
            obs, reward, terminated, truncated, info = env.step(expert.plan(as_observation(info)).waypoints)
            steps += 1
            done = terminated or truncated
    env_wall_s = time.perf_counter() - t0
    # the main job on the same world, seeds and settings
    args = build_parser().parse_args(["--mode", mode, "--duration-s", str(duration_s), "--source", "expert"])
    cfg = stack_config(args, mode)
    controller = HybridController(cfg)
    sensor = make_sensor(args, world, cfg.dt_s)
    source = _SeeingExpert(expert)
    t0 = time.perf_counter()
    for seed in range(episodes):
        run_episode(world, source, controller, seed=seed, sensor=sensor)
    main_wall_s = time.perf_counter() - t0
    env.close()
    sim_s = episodes * duration_s
    return {
        "episodes": episodes, "env_steps": steps,
        "env_steps_per_s": steps / env_wall_s, "env_sim_s_per_wall_s": sim_s / env_wall_s,
        "main_sim_s_per_wall_s": sim_s / main_wall_s,
        "throughput_ratio": main_wall_s / env_wall_s,
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m scenarios.gym_bench", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--episodes", type=int, default=5, help="episodes per side (default 5)")
    p.add_argument("--duration-s", type=float, default=6.0, help="episode length, s")
    p.add_argument("--mode", default="hybrid", help="execution mode (default hybrid)")
    p.add_argument("--json", metavar="PATH", help="write the figures as JSON")
    args = p.parse_args(argv)
    if args.episodes < 1 or not args.duration_s > 0:
        p.error(f"--episodes must be >= 1 and --duration-s > 0, got {args.episodes} and {args.duration_s}")
    r = bench(args.episodes, args.duration_s, args.mode)
    print(f"environment: {r['env_steps']} steps, {r['env_steps_per_s']:.2f} steps/s, "
          f"{r['env_sim_s_per_wall_s']:.2f} simulated s per wall s")
    print(f"main job:    {r['main_sim_s_per_wall_s']:.2f} simulated s per wall s (same episodes, same camera frames)")
    print(f"throughput ratio env / main job: {r['throughput_ratio']:.3f} (goal >= 0.8)")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(r, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
