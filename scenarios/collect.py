"""Record demonstrations of the scripted expert in the MuJoCo scene, for training the token policy.

    python -m scenarios.collect --episodes 1000 --out data/demos

Each episode: one or two coloured balls (static or moving), an instruction naming one of them,
the arm driven toward it by the QP tracking the expert's chunks from a randomly perturbed start. Every
``--sample-every-s`` a sample is recorded: the camera frame(s), the joint state, the expert's
action chunk for that frame (float, not quantized), the frame ``--future-dt-s`` later (for
``<|t2i|>``), and a question/answer pair about the scene (for ``<|mmu|>``).

Output: a directory with ``meta.json`` and shards ``shard_XXXX.npz`` (arrays ``images (N,V,H,W,3)
uint8``, ``future_images``, ``q_rad (N,7)``, ``actions (N,16,7)``, ``instructions``, ``questions``,
``answers`` (unicode strings), ``target_index (N,)``, ``target_pos_m (N,3)``, ``target_prev_pos_m (N,3)``: the
instructed ball where the earlier frame was taken), which numpy or any npz reader opens.

Seeing in 3-D and seeing motion (issue 14): ``--plane-z-m 0`` puts the balls anywhere in the workspace box,
``--cameras front side`` renders two views (so a ball's depth and height are both in the frames), ``--frame-gap-s 0.1``
adds each camera's frame 0.1 s before the sample (``images`` then holds ``[cam0@t, cam1@t, cam0@t-0.1, cam1@t-0.1]``,
``meta.json`` says ``frame_offsets_s: [0, -0.1]``; the first sample of an episode, which has no earlier frame, repeats
the current one), ``--motion all`` mixes static and moving balls (linear, reversal, swerve, random_walk, jump), and
``--expert-lead velocity`` labels each chunk with the leading expert (where the two frames say the ball will be at
each waypoint's time, reflected at the workspace walls; ``scenarios.world.expert``). ``--holdout-box-m X0 X1 Y0 Y1``
leaves out every scene whose instructed ball starts in that region of the table (for measuring generalization).

DAgger-style relabelling (``--driver-checkpoint PATH --driver-prob P``): each chunk that *drives* the arm comes
from that trained policy with probability P (from the expert otherwise), while every recorded label is still
the expert's chunk for the recorded frame. The data then covers the states the policy itself visits, e.g. the
gripper hovering a few centimetres off the ball and hiding it from the camera, which pure expert runs seldom
reach. ``--duration-s 3`` keeps the arm around the ball for most of the episode.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from policy.action_tokenizer import ActionBounds
from scenarios.collect_episode import (MOTION_CHOICES, MOTIONS, collect_episode, draw_motion, in_box,  # noqa: F401
                                       question_answer)
from scenarios.world.expert import LEADS, ExpertConfig


@dataclass(frozen=True)
class CollectConfig:
    """Attributes:
    episodes: number of episodes.
    objects: 1, 2, or 0 for a random mix (one third single-object).
    motion: target motion: one of ``MOTIONS`` (a ``scenarios.world.targets`` kind), "mixed" (two thirds static, one third
        linear) or "all" (one third static, the rest evenly linear, reversal, swerve, random_walk, jump).
    speed_m_s: speed of moving targets.
    duration_s: episode length.
    sample_every_s: spacing of recorded samples.
    future_dt_s: how far ahead the t2i target frame is.
    start_noise_rad: std of the perturbation of the home pose at the start.
    image_size_px: camera resolution.
    cameras: camera names.
    seed: seed of episode 0 (episode i uses seed + i).
    plane_z_m: > 0: every object at this height (+ up to 2 cm), moving horizontally, so one camera
        frame determines its position; 0: the full 3-D workspace.
    frame_gap_s: > 0: each sample also holds the frames this long before it (a policy that sees motion); 0: one frame.
    expert_lead: the expert that labels the chunks: "none" (aim where the ball is) or "velocity" (where the two
        frames ``frame_gap_s`` apart say it will be at each waypoint's time).
    holdout_box_m: ``(x0, x1, y0, y1)`` m: scenes whose instructed ball starts inside are skipped (redrawn); () = none.
    """

    episodes: int = 1000
    objects: int = 2
    motion: str = "mixed"
    speed_m_s: float = 0.2
    duration_s: float = 1.0
    sample_every_s: float = 0.5
    future_dt_s: float = 0.5
    start_noise_rad: float = 0.25
    image_size_px: int = 96
    cameras: tuple[str, ...] = ("front",)
    seed: int = 0
    plane_z_m: float = 0.0
    driver_checkpoint: str = ""
    driver_prob: float = 0.0
    frame_gap_s: float = 0.0
    expert_lead: str = "none"
    holdout_box_m: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        if self.episodes < 1:
            raise ValueError(f"episodes must be >= 1, got {self.episodes}")
        if self.objects not in (0, 1, 2):
            raise ValueError(f"objects must be 1, 2 or 0 (mix), got {self.objects}")
        if self.motion not in MOTION_CHOICES:
            raise ValueError(f"motion must be one of {MOTION_CHOICES}, got {self.motion!r}")
        if not (np.isfinite(self.frame_gap_s) and 0.0 <= self.frame_gap_s < self.sample_every_s):
            raise ValueError(f"frame_gap_s must be in [0, sample_every_s), got {self.frame_gap_s}")
        if self.expert_lead not in LEADS:
            raise ValueError(f"expert_lead must be one of {LEADS}, got {self.expert_lead!r}")
        if self.expert_lead != "none" and self.frame_gap_s <= 0:
            raise ValueError("expert_lead 'velocity' needs frame_gap_s > 0 (the two frames the lead is estimated from)")
        if self.holdout_box_m and (len(self.holdout_box_m) != 4 or not self.holdout_box_m[0] < self.holdout_box_m[1]
                                   or not self.holdout_box_m[2] < self.holdout_box_m[3]):
            raise ValueError(f"holdout_box_m must be (x0, x1, y0, y1) with x0 < x1 and y0 < y1, got {self.holdout_box_m}")
        if not (0 < self.sample_every_s < self.duration_s):
            raise ValueError(f"sample_every_s must be in (0, duration_s), got {self.sample_every_s}")
        if not self.future_dt_s > 0:
            raise ValueError(f"future_dt_s must be > 0, got {self.future_dt_s}")
        if not 0.0 <= self.driver_prob <= 1.0:
            raise ValueError(f"driver_prob must be in [0, 1], got {self.driver_prob}")
        if self.driver_prob > 0 and not self.driver_checkpoint:
            raise ValueError("driver_prob > 0 needs a driver_checkpoint (the policy whose chunks drive the arm)")
        if self.driver_checkpoint and not Path(self.driver_checkpoint).is_file():
            raise ValueError(f"driver_checkpoint {self.driver_checkpoint!r} does not exist")


def _worker(args: tuple[CollectConfig, list[int]]) -> dict[str, list]:
    cfg, indices = args
    cache: dict = {}
    merged: dict[str, list] = {}
    for i in indices:
        for key, values in collect_episode(cfg, i, cache).items():
            merged.setdefault(key, []).extend(values)
    for key, w in cache.items():
        if isinstance(key, tuple):
            w.close()
    return merged


def write_shard(out: Path, index: int, samples: dict[str, list]) -> int:
    arrays = {}
    for key, values in samples.items():
        if key in ("instructions", "questions", "answers"):
            arrays[key] = np.array(values, dtype=str)
        else:
            arrays[key] = np.stack([np.asarray(v) for v in values])
    np.savez_compressed(out / f"shard_{index:04d}.npz", **arrays)
    return len(samples["images"])


def collect(cfg: CollectConfig, out: Path, workers: int = 1, episodes_per_shard: int = 100, progress: bool = True) -> int:
    """Collect ``cfg.episodes`` episodes into ``out``; returns the number of samples."""
    from tqdm import tqdm

    out.mkdir(parents=True, exist_ok=True)
    chunks = [list(range(s, min(s + 10, cfg.episodes))) for s in range(0, cfg.episodes, 10)]
    total = 0
    shard, buffer, buffered_eps = 0, {}, 0
    bar = tqdm(total=cfg.episodes, desc="episodes", unit="ep", disable=not progress, file=sys.stderr)
    ctx = mp.get_context("spawn")
    pool = ctx.Pool(workers) if workers > 1 else None
    try:
        results = pool.imap(_worker, [(cfg, c) for c in chunks]) if pool else map(_worker, [(cfg, c) for c in chunks])
        for c, res in zip(chunks, results):
            for key, values in res.items():
                buffer.setdefault(key, []).extend(values)
            buffered_eps += len(c)
            bar.update(len(c))
            if buffered_eps >= episodes_per_shard:
                total += write_shard(out, shard, buffer)
                shard, buffer, buffered_eps = shard + 1, {}, 0
        if buffer:
            total += write_shard(out, shard, buffer)
    finally:
        bar.close()
        if pool:
            pool.close()
            pool.join()
    bounds = ActionBounds()
    meta = {
        "image_size_px": cfg.image_size_px,
        "camera_names": list(cfg.cameras),
        "chunk_horizon": ExpertConfig().horizon,
        "chunk_dt_s": ExpertConfig().dt_s,
        "action_bounds": {"low": list(bounds.low), "high": list(bounds.high)},
        "action_bins": 2048,
        "future_dt_s": cfg.future_dt_s,
        "frame_offsets_s": [0.0, -cfg.frame_gap_s] if cfg.frame_gap_s > 0 else [0.0],
        "n_samples": total,
        "collect_config": asdict(cfg),
        "command": " ".join(["python -m scenarios.collect", *sys.argv[1:]]),
    }
    (out / "meta.json").write_text(json.dumps(meta, indent=2))
    return total


def _format_of(argv: list[str]) -> str:
    """The ``--format`` given (``npz`` when none): ``lerobot`` hands the whole command to ``collect_lerobot``."""
    fmt = argparse.ArgumentParser(add_help=False)
    fmt.add_argument("--format", default="npz")
    known, _ = fmt.parse_known_args(argv)
    return known.format


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if _format_of(argv) == "lerobot":
        from scenarios.collect_lerobot import main as lerobot_main

        return lerobot_main(argv)
    p = argparse.ArgumentParser(prog="python -m scenarios.collect", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--format", choices=("npz", "lerobot"), default="npz",
                   help="npz: the token policy's training shards (this help); lerobot: a LeRobotDataset v3.0 of any "
                        "source's episodes (python -m scenarios.collect --format lerobot --help)")
    p.add_argument("--episodes", type=int, default=1000, help="number of episodes")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--objects", type=int, default=0, choices=(0, 1, 2), help="objects per scene (0: random mix of 1 and 2)")
    p.add_argument("--motion", default="mixed", choices=MOTION_CHOICES,
                   help="target motion: one kind, mixed (2/3 static, 1/3 linear) or all (1/3 static, the rest evenly "
                        "linear, reversal, swerve, random_walk, jump)")
    p.add_argument("--frame-gap-s", type=float, default=0.0,
                   help="> 0: each sample also holds every camera's frame this long earlier (motion); 0: one frame")
    p.add_argument("--expert-lead", default="none", choices=LEADS,
                   help="labels: none = aim where the ball is in the frame; velocity = where the two frames say it "
                        "will be at each waypoint's time (needs --frame-gap-s > 0)")
    p.add_argument("--holdout-box-m", type=float, nargs=4, default=None, metavar=("X0", "X1", "Y0", "Y1"),
                   help="skip scenes whose instructed ball starts in this region of the table (m), to measure "
                        "generalization on it")
    p.add_argument("--speed", type=float, default=0.2, help="speed of moving targets (m/s)")
    p.add_argument("--image-size-px", type=int, default=96, help="camera resolution")
    p.add_argument("--cameras", nargs="+", default=["front"], help="camera names")
    p.add_argument("--seed", type=int, default=0, help="seed of the first episode")
    p.add_argument("--plane-z-m", type=float, default=0.0,
                   help="> 0: objects at this height (+ up to 2 cm), moving horizontally; 0: the 3-D workspace")
    p.add_argument("--duration-s", type=float, default=1.0,
                   help="episode length; samples every 0.5 s before it (many short episodes = many scenes)")
    p.add_argument("--driver-checkpoint", default="",
                   help="DAgger: a trained policy whose chunks drive the arm (labels stay the expert's)")
    p.add_argument("--driver-prob", type=float, default=0.0,
                   help="DAgger: probability that a driving chunk comes from --driver-checkpoint (default 0)")
    p.add_argument("--workers", type=int, default=1, help="parallel processes")
    args = p.parse_args(argv)
    try:
        cfg = CollectConfig(episodes=args.episodes, objects=args.objects, motion=args.motion, speed_m_s=args.speed,
                            image_size_px=args.image_size_px, cameras=tuple(args.cameras), seed=args.seed,
                            duration_s=args.duration_s, plane_z_m=args.plane_z_m,
                            driver_checkpoint=args.driver_checkpoint, driver_prob=args.driver_prob,
                            frame_gap_s=args.frame_gap_s, expert_lead=args.expert_lead,
                            holdout_box_m=tuple(args.holdout_box_m or ()))
    except ValueError as exc:
        p.error(str(exc))
    n = collect(cfg, Path(args.out), workers=args.workers)
    print(f"wrote {n} samples to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
