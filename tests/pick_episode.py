"""One pick episode through the main job's settings, for the tests that hold a measured pick episode in the loop."""

from __future__ import annotations

import dataclasses

from mmact_ctrl.controller import HybridController
from mmact_ctrl.loop import run_episode


def run_pick_episode(target: str, speed: str, seed: int, duration_s: str, mode: str = "hybrid", **overrides):
    """``(log, controller, config)`` of one pick episode of the scripted expert (``--target target --speed speed``,
    ``duration_s`` long, on ``seed``) in ``mode``, with ``overrides`` replacing the main job's ``StackConfig`` fields."""
    from scenarios.moving_target import make_sensor, make_source_and_world
    from scenarios.moving_target_args import build_parser, stack_config

    args = build_parser().parse_args(["--source", "expert", "--task", "pick", "--target", target, "--speed", speed,
                                      "--duration-s", duration_s, "--episodes", "1", "--seed", str(seed)])
    cfg = dataclasses.replace(stack_config(args, mode), **overrides)
    source, world = make_source_and_world(args)
    ctl = HybridController(cfg)
    try:
        log = run_episode(world, source, ctl, seed=seed, sensor=make_sensor(args, world, cfg.dt_s))
    finally:
        world.close()
    return log, ctl, cfg
