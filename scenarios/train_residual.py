"""Collect open-loop rollouts and train the A2C2-style residual (``policy.residual``); write its checkpoint and card.

    python -m scenarios.train_residual                       # the shipped policy/checkpoints/residual.pt (~5-8 min)
    python -m scenarios.train_residual --episodes 40 --epochs 5 --out /tmp/r.pt --card /tmp/R.md   # a quick one

Data: the base chunk source (the scripted expert; optionally the learned policy) drives the Panda with
``--mode open_loop`` semantics (``StackConfig(mode="open_loop", latency_ms=200)``: each chunk's waypoints
interpolated and tracked by the 1 kHz QP, nothing else). Every 10 ms (the perception rate) one sample is taken
while a chunk is executing: the base waypoint being tracked, the age of that chunk's observation, the 100 Hz
oracle measurements (recorded from the episode's own channel: truth + 2 mm noise, 10 % dropout, a dropped one
leaves the previous one as the latest), the TCP position and velocity (1 ms backward difference). The label is the
correction that would have put the waypoint on the target a little ahead, ``clip_norm(target(t + lead) - base(t),
max_correction_m)``. Training seeds start at 10,000, disjoint from the evaluation seeds 0..999.
"""

from __future__ import annotations

# The command's parts live beside this module: ``train_residual_plan`` (the episodes to collect and their constants),
# ``train_residual_rollout`` (one rollout turned into samples, every rollout collected), ``train_residual_card`` (the
# model card). Every name stays importable from here. (The docstring above is the command's description.)
import argparse
import json
import shlex
import sys
import time
from dataclasses import asdict
from pathlib import Path

import torch

from policy.residual import DEFAULT_RESIDUAL_CHECKPOINT, ResidualConfig
from policy.residual_training import train
from scenarios.train_residual_card import (DEFAULT_CARD, DESIGN_NOTES, _card_error_lines,  # noqa: F401
                                           _card_loss_lines, _card_made_lines, write_card)
from scenarios.train_residual_plan import (MOVING_KINDS, REPLAN_HZ, SAMPLE_HZ, SPEEDS_M_S, TRAIN_SEED0, EpisodeSpec,
                                           available_kinds, expert_leads, plan_episodes)
from scenarios.train_residual_rollout import (_CACHE, _active_chunks, _parts, _recording_sensor,  # noqa: F401
                                              _RecordingSources, _sample_rows, _samples, _worker, collect_samples,
                                              rollout_samples)

__all__ = ["PROG", "TRAIN_SEED0", "SPEEDS_M_S", "REPLAN_HZ", "MOVING_KINDS", "SAMPLE_HZ", "DEFAULT_CARD",
           "DESIGN_NOTES", "EpisodeSpec", "available_kinds", "expert_leads", "plan_episodes", "rollout_samples",
           "collect_samples", "write_card", "build_parser", "main"]

PROG = "python -m scenarios.train_residual"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=PROG, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    d = p.add_argument_group("data")
    d.add_argument("--sources", nargs="+", choices=("expert", "policy"), default=["expert"],
                   help="base chunk sources to roll out (default: expert). policy = the shipped learned policy in its "
                        "own scenes (two balls at 0.1 m height); it renders a frame and runs a forward pass per chunk "
                        "(slower than the expert, the more so at 5 Hz replanning), so it is off by default and its "
                        "episode count is --policy-episodes (default 30)")
    d.add_argument("--episodes", type=int, default=800,
                   help="expert episodes (default 800: 3-6 min with 2 workers on the shared 2-core machine)")
    d.add_argument("--policy-episodes", type=int, default=30, help="episodes of the policy source when --sources "
                   "includes policy (default 30)")
    d.add_argument("--kinds", nargs="+", default=None, metavar="KIND",
                   help="moving target families (default: every non-static kind of scenarios.world.targets.KINDS at run "
                        "time: linear, circle, random_walk, jump, and reversal, accelerating, swerve where present)")
    d.add_argument("--static-fraction", type=float, default=0.08, help="share of static-target episodes (default 0.08)")
    d.add_argument("--none-lead-fraction", type=float, default=0.25,
                   help="share of expert episodes with lead='none' (the rest 'velocity'), when make_expert has a lead "
                        "keyword (default 0.25)")
    d.add_argument("--duration-s", type=float, default=6.0, help="episode length, s (default 6)")
    d.add_argument("--latency-ms", type=float, default=200.0, help="chunk latency, ms (default 200)")
    d.add_argument("--seed", type=int, default=TRAIN_SEED0,
                   help=f"first episode seed (episode i uses seed + i); must be >= {TRAIN_SEED0}: evaluation uses 0-999")
    d.add_argument("--workers", type=int, default=2, help="collection processes (default 2)")
    m = p.add_argument_group("model and label")
    m.add_argument("--lead-ms", type=float, default=25.0,
                   help="the label aims at the target this far ahead of the sample time, for the QP's tracking lag "
                        "(default 25 ms: 0, 25 and 50 ms tied in closed loop, 100 ms was worse; see the card)")
    m.add_argument("--hidden", type=int, default=128)
    m.add_argument("--layers", type=int, default=3)
    m.add_argument("--max-correction-m", type=float, default=0.15)
    m.add_argument("--history-s", type=float, default=0.1)
    t = p.add_argument_group("training")
    t.add_argument("--epochs", type=int, default=40, help="passes over the training split (default 40: 1-2 min)")
    t.add_argument("--batch-size", type=int, default=512)
    t.add_argument("--lr", type=float, default=2e-3)
    t.add_argument("--weight-decay", type=float, default=1e-4)
    t.add_argument("--tcp-shift-prob", type=float, default=0.5,
                   help="share of training samples whose TCP features are shifted toward the corrected reference "
                        "(augmentation against the closed loop's state shift; 0 = off)")
    t.add_argument("--val-fraction", type=float, default=0.15, help="share of episodes held out (default 0.15)")
    t.add_argument("--train-seed", type=int, default=0)
    t.add_argument("--threads", type=int, default=1, help="torch threads for training (default 1: on the shared 2-core machine 2 threads were 10x slower)")
    o = p.add_argument_group("output")
    o.add_argument("--out", default=str(DEFAULT_RESIDUAL_CHECKPOINT), help="checkpoint path (default %(default)s)")
    o.add_argument("--card", default=None, help="model card path (default: RESIDUAL_CARD.md beside --out)")
    o.add_argument("--no-progress", action="store_true", help="no progress bars")
    return p


def _resolve(parser: argparse.ArgumentParser, args: argparse.Namespace):
    """The residual's config, the target families and the expert and policy episode counts, checked (a bad value
    exits with status 2)."""
    try:
        config = ResidualConfig(hidden=args.hidden, layers=args.layers, max_correction_m=args.max_correction_m,
                                history_s=args.history_s)
    except ValueError as exc:
        parser.error(str(exc))
    if args.seed < TRAIN_SEED0:
        parser.error(f"--seed must be >= {TRAIN_SEED0} (evaluation uses seeds 0-999), got {args.seed}")
    if args.episodes < 0 or args.policy_episodes < 0 or args.workers < 1 or args.epochs < 1:
        parser.error("--episodes/--policy-episodes must be >= 0, --workers/--epochs >= 1")
    if not 0 <= args.lead_ms <= 500:
        parser.error(f"--lead-ms must be in [0, 500], got {args.lead_ms}")
    known = available_kinds()
    kinds = tuple(args.kinds) if args.kinds else known
    bad = [k for k in kinds if k not in known]
    if bad:
        parser.error(f"--kinds: unknown {bad}; choose from {list(known)}")
    n_expert = args.episodes if "expert" in args.sources else 0
    n_policy = args.policy_episodes if "policy" in args.sources else 0
    if n_expert + n_policy < 2:
        parser.error("need at least 2 episodes (one is held out for validation)")
    return config, kinds, n_expert, n_policy


def main(argv: list[str] | None = None) -> Path:
    parser = build_parser()
    args = parser.parse_args(argv)
    t_start = time.perf_counter()
    config, kinds, n_expert, n_policy = _resolve(parser, args)
    if args.threads:
        torch.set_num_threads(args.threads)
    specs = plan_episodes(n_expert, n_policy, kinds, args.static_fraction, args.none_lead_fraction, args.seed)
    c0 = time.perf_counter()
    data = collect_samples(specs, args.duration_s, args.latency_ms, args.lead_ms / 1e3, config.history_s,
                           config.max_correction_m, workers=args.workers, progress=not args.no_progress)
    collect_wall = time.perf_counter() - c0
    policy, info = train(data, config, epochs=args.epochs, batch_size=args.batch_size, lr=args.lr,
                         weight_decay=args.weight_decay, val_fraction=args.val_fraction, seed=args.train_seed,
                         tcp_shift_prob=args.tcp_shift_prob, progress=not args.no_progress)
    info["config"] = asdict(config)
    command = " ".join(shlex.quote(a) for a in [*PROG.split(), *(sys.argv[1:] if argv is None else argv)])
    out = Path(args.out)
    total_wall = time.perf_counter() - t_start
    meta = {"command": command, "label_lead_s": args.lead_ms / 1e3, "collect_wall_s": collect_wall,
            "total_wall_s": total_wall,
            "data": {"n_episodes": len(specs), "sources": sorted({s.source for s in specs}),
                     "kinds": sorted({s.kind for s in specs}), "seeds": [specs[0].seed, specs[-1].seed],
                     **data["settings"]},
            **{k: v for k, v in info.items() if k != "history"}, "history": info["history"]}
    policy.save(out, meta)
    card = Path(args.card) if args.card else out.parent / "RESIDUAL_CARD.md"
    write_card(card, out, command, specs, data, info, collect_wall, time.perf_counter() - t_start, args.lead_ms / 1e3)
    print(json.dumps({"checkpoint": str(out), "card": str(card), "n_samples": info["n_samples"],
                      "final_train_loss": info["final_train_loss"], "final_val_loss": info["final_val_loss"],
                      "val": info["val"], "wall_s": round(time.perf_counter() - t_start, 1)}, indent=1))
    return out


if __name__ == "__main__":
    main()
