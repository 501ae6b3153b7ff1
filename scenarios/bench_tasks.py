"""The episode's real-time factor on each task, in one run on this machine: reach beside pick and insert.

    python -m scenarios.bench_tasks                 # 5 episodes per row, about 2 minutes on 2 cores
    python -m scenarios.bench_tasks --episodes 10 --json out/bench_tasks.json

Each row runs the scripted expert (lead velocity) under the same stack (hybrid: Kalman filter, retargeting, Ruckig,
MPC, QP; 1 Hz, 200 ms) for 6 s episodes on the same seeds, and prints the real-time factor (simulated over wall
time, the whole episode: physics, contacts, the expert, the stack), its share of reach's (measured in the same run,
so it carries from one host to another where the factors themselves do not) and the 1 kHz tick's median and p99.
The contact tasks add MuJoCo contacts (the cubes on the belt, the peg in the fingers and the fixture) and, with
``--compliance``, the impedance task, whose desired acceleration a second compiled kernel computes for the QP's
fast path (``controllers.tick_kernels.impedance_acc``).
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import asdict, dataclass

import numpy as np

#: (label, task, target, speed m/s, compliance)
ROWS: tuple[tuple[str, str, str, float, bool], ...] = (
    ("reach, linear 0.2 m/s", "reach", "linear", 0.2, False),
    ("pick, linear 0.2 m/s", "pick", "linear", 0.2, False),
    ("insert, static, 1 mm", "insert", "static", 0.0, False),
    ("insert, static, 1 mm, --compliance", "insert", "static", 0.0, True),
)


@dataclass(frozen=True)
class TaskSpeed:
    """One row: the label, the episodes, the real-time factor (median, min over episodes), the tick (median, p99 over
    every tick, us) and the success rate."""

    label: str
    episodes: int
    realtime_factor_median: float
    realtime_factor_min: float
    tick_us_median: float
    tick_us_p99: float
    success_rate: float


def bench_row(label: str, task: str, target: str, speed_m_s: float, compliance: bool, episodes: int,
              seed: int) -> TaskSpeed:
    from mmact_ctrl.config import StackConfig
    from mmact_ctrl.controller import HybridController
    from mmact_ctrl.loop import run_episode
    from mmact_ctrl.metrics import episode_metrics
    from scenarios.world.factory import make_expert, make_world
    from scenarios.world.tasks.registry import task_stack_settings

    world = make_world(target, speed_m_s, task=task, n_objects=2 if task != "insert" else 1)
    source = make_expert(lead="velocity", world=world)
    cfg = StackConfig(mode="hybrid", duration_s=6.0, **task_stack_settings(task, compliance))
    rtf, ticks, success = [], [], []
    for i in range(episodes):
        log = run_episode(world, source, HybridController(cfg), seed=seed + i)
        m = episode_metrics(log)
        rtf.append(m["realtime_factor"])
        ticks.extend(np.asarray(log.tick_us, dtype=float).tolist())
        success.append(bool(m["success"]))
    world.close()
    t = np.asarray(ticks)
    return TaskSpeed(label, episodes, float(np.median(rtf)), float(np.min(rtf)), float(np.median(t)),
                     float(np.percentile(t, 99)), float(np.mean(success)))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m scenarios.bench_tasks", description=__doc__.split("\n\n")[0])
    p.add_argument("--episodes", type=int, default=5, help="episodes per row (default 5)")
    p.add_argument("--seed", type=int, default=0, help="the first seed (default 0)")
    p.add_argument("--json", metavar="PATH", help="write the rows as JSON")
    args = p.parse_args(argv)
    if args.episodes < 1:
        p.error(f"--episodes must be >= 1, got {args.episodes}")
    rows, shares = [], []
    print(f"{'task':<38} {'RTF median':>10} {'RTF min':>8} {'of reach':>9} {'tick median [us]':>17} "
          f"{'tick p99 [us]':>14} {'success':>8}")
    for row in ROWS:
        r = bench_row(*row, episodes=args.episodes, seed=args.seed)
        rows.append(r)
        shares.append(r.realtime_factor_median / rows[0].realtime_factor_median)  # ROWS[0] is reach
        print(f"{r.label:<38} {r.realtime_factor_median:>9.1f}x {r.realtime_factor_min:>7.1f}x {shares[-1]:>9.2f} "
              f"{r.tick_us_median:>17.0f} {r.tick_us_p99:>14.0f} {100 * r.success_rate:>7.0f}%", flush=True)
    if args.json:
        with open(args.json, "w") as f:
            json.dump([dict(asdict(r), share_of_reach=share) for r, share in zip(rows, shares)], f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
