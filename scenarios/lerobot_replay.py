"""Replay check: does a dataset mean what it says? Each recorded episode's actions are replayed through the stack
(``--source lerobot:DIR``, open loop, the episode's own seed and every switch it was collected with, read from
``meta/mmact.json``), and the replay's success and final error are set beside the recorded ones.

    python -m scenarios.lerobot_replay data/reach_linear --episodes 20 [--json out.json]

The figure (issue 34): the same success and a final error within 2 mm of the recorded one, episode by episode.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from scenarios.cli import HelpFormatter, OneLineErrorParser

#: a replayed episode agrees with its recording when its final error is within this, m (and its success is the same)
FINAL_ERROR_TOL_M = 0.002


def replay_args(root: Path) -> tuple[argparse.Namespace, list[dict]]:
    """The collection's arguments (the source replaced by the dataset, the mode by open loop) and its episodes."""
    from scenarios.collect_lerobot import MMACT_META, build_parser

    meta_path = root / MMACT_META
    if not meta_path.is_file():
        raise FileNotFoundError(f"{str(root)!r} has no {MMACT_META}: the replay check needs the seeds and switches "
                                "of one of our exports (any dataset replays with --source lerobot:DIR in moving_target)")
    meta = json.loads(meta_path.read_text())
    args = build_parser().parse_args(["--out", str(root)])
    for key, value in meta["args"].items():
        setattr(args, key, tuple(value) if key == "action_scale" and value is not None else value)
    args.source, args.mode, args.source_arg = f"lerobot:{root}", ["open_loop"], []
    for key in ("checkpoint", "action_steps", "refine_bins", "expert_lead", "horizon", "chunk_dt_s"):
        setattr(args, key, None)
    return args, meta["episodes"]


def replay(root: str | Path, episodes: int | None = None, progress: bool = True) -> dict:
    """Replay the first ``episodes`` episodes of ``root`` (all: None); returns ``{"rows", "summary"}``."""
    from tqdm import tqdm

    from mmact_ctrl.controller import HybridController
    from mmact_ctrl.loop import run_episode
    from mmact_ctrl.metrics import episode_metrics
    from scenarios.moving_target import make_sensor, make_source_and_world
    from scenarios.moving_target_args import stack_config
    from scenarios.sources import close_source

    root = Path(root)
    args, recorded = replay_args(root)
    recorded = recorded[: episodes or len(recorded)]
    cfg = stack_config(args, "open_loop")
    source, world = make_source_and_world(args)  # the dataset's episodes in order, one per run episode
    rows = []
    try:
        controller = HybridController(cfg)
        sensor = make_sensor(args, world, cfg.dt_s)
        for rec in tqdm(recorded, desc="replay", unit="ep", disable=not progress, file=sys.stderr):
            m = episode_metrics(run_episode(world, source, controller, seed=rec["seed"], sensor=sensor))
            diff = abs(float(m["final_error_m"]) - rec["final_error_m"])
            rows.append({"episode_index": rec["episode_index"], "seed": rec["seed"], "recorded_success": rec["success"],
                         "replay_success": bool(m["success"]), "recorded_final_error_m": rec["final_error_m"],
                         "replay_final_error_m": float(m["final_error_m"]), "final_error_diff_m": diff,
                         "agrees": bool(m["success"]) == rec["success"] and diff <= FINAL_ERROR_TOL_M})
    finally:
        close_source(source)
        world.close()
    diffs = np.array([r["final_error_diff_m"] for r in rows])
    summary = {"episodes": len(rows), "agree": sum(r["agrees"] for r in rows),
               "same_success": sum(r["recorded_success"] == r["replay_success"] for r in rows),
               "recorded_success": sum(r["recorded_success"] for r in rows),
               "replay_success": sum(r["replay_success"] for r in rows),
               "final_error_diff_median_mm": float(np.median(diffs) * 1e3),
               "final_error_diff_max_mm": float(diffs.max() * 1e3), "tolerance_mm": FINAL_ERROR_TOL_M * 1e3,
               "task": args.task, "target": args.target, "action_space": _action_space(root)}
    return {"rows": rows, "summary": summary}


def _action_space(root: Path) -> str:
    meta = json.loads((root / "meta" / "mmact.json").read_text())
    return meta["frame_settings"]["action_space"]


def main(argv: list[str] | None = None) -> int:
    p = OneLineErrorParser(prog="python -m scenarios.lerobot_replay", description=__doc__,
                           formatter_class=HelpFormatter)
    p.add_argument("root", metavar="DIR", help="a dataset written by python -m scenarios.collect --format lerobot")
    p.add_argument("--episodes", type=int, default=None, help="replay the first N episodes (default: all)")
    p.add_argument("--json", metavar="PATH", help="write the rows and the summary here")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    args = p.parse_args(argv)
    try:
        out = replay(args.root, args.episodes, progress=not args.quiet)
    except (ValueError, FileNotFoundError, RuntimeError) as exc:
        p.error(str(exc).splitlines()[0])
    s = out["summary"]
    for r in out["rows"]:
        print(f"episode {r['episode_index']:>3} seed {r['seed']:>6}: success {r['recorded_success']!s:>5} -> "
              f"{r['replay_success']!s:>5}, final error {r['recorded_final_error_m'] * 1e3:6.2f} -> "
              f"{r['replay_final_error_m'] * 1e3:6.2f} mm{'' if r['agrees'] else '   DISAGREES'}")
    print(f"{s['agree']}/{s['episodes']} episodes agree (same success, final error within {s['tolerance_mm']:g} mm); "
          f"success recorded {s['recorded_success']}/{s['episodes']}, replayed {s['replay_success']}/{s['episodes']}; "
          f"|final error difference| median {s['final_error_diff_median_mm']:.3f} mm, max "
          f"{s['final_error_diff_max_mm']:.3f} mm ({s['task']}, {s['target']}, action {s['action_space']})")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(out, indent=2))
    return 0 if s["agree"] == s["episodes"] else 1


if __name__ == "__main__":
    sys.exit(main())
