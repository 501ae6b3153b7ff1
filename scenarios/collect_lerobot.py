"""``python -m scenarios.collect --format lerobot``: episodes of our scenes as a LeRobotDataset v3.0.

    python -m scenarios.collect --format lerobot --out data/reach_linear --episodes 50 --target linear
    python -m scenarios.collect --format lerobot --out data/pick --task pick --target linear --fps 20
    python -m scenarios.collect --format lerobot --show data/reach_linear [--rerun ep0.rrd --episode 0]

Each episode runs as ``python -m scenarios.moving_target`` runs it (every switch of the stack, the source, the world
and the task is the same here: ``--source expert`` by default, ``--mode open_loop`` by default so that the recorded
actions are the source's own commands), and at each frame time ``m / fps`` the frames of ``--cameras`` at
``--image-size-px``, the robot's state (7 joints + the gripper opening) and the true target are taken.

What a frame holds (``meta/info.json`` says it too):

``observation.images.<camera>``   the camera's frame (mp4, h264)
``observation.state``             joints (rad) + gripper opening (m), 8
``action``                        ``--action-space tcp_pose``: the command active at the frame, the TCP pose for the
                                  next frame's time ``[x, y, z (m), rx, ry, rz (rad, rotation vector relative to
                                  the nominal grasp), gripper (m)]``, 7; ``joint_pos``: the same command in joints (its
                                  inverse kinematics from the arm's own posture) + the gripper command, 8
``target_pos_m``                  the instructed object's true position (for analysis only: no policy input)

``meta/mmact.json`` (ours, beside LeRobot's files) holds what made the dataset (the command, every switch) and each
episode's seed and figures (success, final error), which ``--show`` and the replay check (``python -m
scenarios.lerobot_replay``) read.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from mmact_ctrl.datasets.conventions import JOINT_ACTION_NAMES, STATE_FEATURE_NAMES, TCP_ACTION_NAMES
from mmact_ctrl.datasets.video import PIX_FMTS
from scenarios.cli import HelpFormatter, OneLineErrorParser
from scenarios.lerobot_episode import ACTION_SPACES, FrameSettings
from scenarios.world.panda_scene import AVAILABLE_CAMERAS

PROG = "python -m scenarios.collect --format lerobot"
#: the frame rates a dataset may have: those whose frame period is a whole number of 1 ms ticks, and the cameras'
#: 15 and 30 fps, whose frames are taken at the nearest tick (at most 1/3 ms from ``m / fps``)
TICK_FPS: tuple[int, ...] = tuple(f for f in range(1, 1001) if 1000 % f == 0)
CAMERA_FPS: tuple[int, ...] = (15, 30)
TARGET_NAMES: tuple[str, ...] = ("x_m", "y_m", "z_m")
ROBOT_TYPE = "franka_panda"
MMACT_META = "meta/mmact.json"
#: switches of the export itself (not of the episode): kept out of the replay's arguments
EXPORT_KEYS: tuple[str, ...] = ("format", "out", "fps", "image_size_px", "dataset_action_space", "show", "rerun",
                                "episode", "quiet", "verify", "pix_fmt")


def check_fps(fps: int) -> int:
    """``fps`` if frames can be taken at it (one line naming it if not)."""
    if fps in TICK_FPS or fps in CAMERA_FPS:
        return fps
    ok = ", ".join(str(f) for f in TICK_FPS if f <= 100)
    raise ValueError(f"--fps {fps} does not divide the 1 kHz control rate: use one that does ({ok}, ...) or the "
                     f"cameras' 15 / 30 (frames at the nearest 1 ms tick)")


def _fps_arg(text: str) -> int:
    try:
        return check_fps(int(text))
    except ValueError as exc:
        msg = str(exc) if str(exc).startswith("--fps") else f"--fps {text!r} is not an integer"
        raise argparse.ArgumentTypeError(msg) from None


def _size_arg(text: str) -> int:
    try:
        size = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--image-size-px {text!r} is not an integer") from None
    if not (16 <= size <= 480) or size % 2:
        raise argparse.ArgumentTypeError(f"--image-size-px {size}: an even size in 16 .. 480 px (h264 in yuv420p "
                                         "halves the colour planes: it needs even sides)")
    return size


def build_parser() -> argparse.ArgumentParser:
    from scenarios import moving_target_args as mt

    p = OneLineErrorParser(prog=PROG, description=__doc__, formatter_class=HelpFormatter, conflict_handler="resolve")
    p.add_argument("--format", choices=("npz", "lerobot"), default="lerobot",
                   help="lerobot: LeRobotDataset v3.0 (this command); npz: our token policy's shards "
                        "(python -m scenarios.collect --help)")
    mt._source_args(p)
    mt._execution_args(p)
    mt._world_args(p)
    mt._task_args(p)
    d = p.add_argument_group("the dataset")
    d.add_argument("--out", metavar="DIR", help="the dataset's directory (new or empty)")
    d.add_argument("--fps", type=_fps_arg, default=10,
                   help="frames per second: 10 = the waypoints as sent (0.1 s apart); 20, 30, ... = interpolated "
                        "(slerp for the orientation)")
    d.add_argument("--cameras", nargs="+", default=["front", "side"], choices=AVAILABLE_CAMERAS, metavar="NAME",
                   help=f"cameras recorded, of {', '.join(AVAILABLE_CAMERAS)}")
    d.add_argument("--image-size-px", type=_size_arg, default=96, help="side of the square camera frames")
    d.add_argument("--pix-fmt", choices=PIX_FMTS, default=PIX_FMTS[0],
                   help="the videos' pixel format: yuv444p keeps the colour of a 4-px ball (PSNR 40 dB at 96 px); "
                        "yuv420p (LeRobot's default) plays in a web browser but halves the colour planes (35 dB)")
    d.add_argument("--action-space", dest="dataset_action_space", choices=ACTION_SPACES, default="tcp_pose",
                   help="the action feature: tcp_pose (the commanded TCP pose + gripper, 7) or joint_pos (the same "
                        "command in joints, inverse kinematics from the arm's posture, + gripper, 8)")
    d.add_argument("--verify", action="store_true",
                   help="after writing, read every frame back with PyAV and compare it with the rendered one (PSNR), "
                        "and check every timestamp and index range (the rendered frames wait in a temporary folder)")
    d.add_argument("--show", metavar="DIR", help="print the one-screen summary of an existing dataset (no collection)")
    d.add_argument("--rerun", metavar="PATH.rrd", help="with --show: write a Rerun recording of --episode")
    d.add_argument("--episode", type=int, default=0, help="with --rerun: the episode recorded")
    d.add_argument("--quiet", action="store_true", help="no progress bar")
    # moving_target's switches that a collection does not offer, at their defaults (no wall clock, no viewer)
    p.set_defaults(source="expert", mode=["open_loop"], episodes=10, realtime=False, viewer=False, video=None,
                   json=None, plot=None, mpc_phase_ms=None, qp_max_iter=None, rt_priority=0)
    return p


def settings_of(args: argparse.Namespace) -> FrameSettings:
    return FrameSettings(fps=args.fps, cameras=tuple(args.cameras), image_size_px=args.image_size_px,
                         action_space=args.dataset_action_space)


def schema_of(settings: FrameSettings, pix_fmt: str = PIX_FMTS[0]):
    from mmact_ctrl.datasets.video import VideoSettings
    from mmact_ctrl.datasets.writer import DatasetSchema, VectorFeature

    action = TCP_ACTION_NAMES if settings.action_space == "tcp_pose" else JOINT_ACTION_NAMES
    return DatasetSchema(fps=settings.fps, robot_type=ROBOT_TYPE, cameras=settings.cameras,
                         image_size_px=settings.image_size_px,
                         vectors=(VectorFeature("observation.state", STATE_FEATURE_NAMES), VectorFeature("action", action),
                                  VectorFeature("target_pos_m", TARGET_NAMES)),
                         video=VideoSettings(fps=settings.fps, pix_fmt=pix_fmt))


def _episode_row(i: int, ep) -> dict:
    m = ep.metrics
    row = {"episode_index": i, "seed": ep.seed, "task": ep.instruction, "frames": ep.length,
           "success": bool(m.get("success")), "final_error_m": float(m.get("final_error_m", float("nan")))}
    for key in ("time_to_reach_s", "time_to_grasp_s", "time_to_seat_s", "peak_contact_force_n"):
        if key in m and m[key] is not None:
            row[key] = float(m[key])
    return row


def collect_lerobot(args: argparse.Namespace, argv: list[str] | None = None) -> dict:
    """Run ``args.episodes`` episodes and write them to ``args.out``; returns the run's figures."""
    from tqdm import tqdm

    from mmact_ctrl.controller import HybridController
    from mmact_ctrl.datasets.writer import EpisodeData, LeRobotWriter
    from scenarios.lerobot_episode import record_episode
    from scenarios.moving_target import check_modes_of_running, make_sensor, make_source_and_world
    from scenarios.moving_target_args import stack_config
    from scenarios.sources import close_source

    if len(args.mode) != 1:
        raise ValueError(f"--mode {' '.join(args.mode)}: a dataset is collected in one mode")
    settings = settings_of(args)
    writer = LeRobotWriter(args.out, schema_of(settings, args.pix_fmt))  # refuses a non-empty --out before any work
    cfg = stack_config(args, args.mode[0])
    check_modes_of_running(args)
    source, world = make_source_and_world(args)
    rows, run_s, write_s = [], 0.0, 0.0
    kept = tempfile.TemporaryDirectory(prefix="mmact_frames_") if args.verify else None
    try:
        controller = HybridController(cfg)
        sensor = make_sensor(args, world, cfg.dt_s)
        for i in tqdm(range(args.episodes), desc="episodes", unit="ep", disable=args.quiet, file=sys.stderr):
            t0 = time.perf_counter()
            ep = record_episode(world, source, controller, sensor, args.seed + i, settings)
            t1 = time.perf_counter()
            writer.add_episode(EpisodeData(task=ep.instruction, images=dict(ep.images),
                                           vectors={"observation.state": ep.state, "action": ep.action,
                                                    "target_pos_m": ep.target_pos_m}))
            write_s += time.perf_counter() - t1
            run_s += t1 - t0
            rows.append(_episode_row(i, ep))
            if kept is not None:
                for cam, frames in ep.images.items():
                    np.save(Path(kept.name) / f"{i}_{cam}.npy", frames)
        t1 = time.perf_counter()
        writer.close()
        write_s += time.perf_counter() - t1
        frames = sum(r["frames"] for r in rows)
        figures = {"episodes": len(rows), "frames": frames, "collect_s": run_s, "export_s": write_s,
                   "collect_fps": frames / run_s if run_s else float("nan"),
                   "export_fps": frames / write_s if write_s else float("nan")}
        if kept is not None:
            figures["round_trip"] = _verify(Path(args.out), Path(kept.name))
    finally:
        close_source(source)
        world.close()
        if kept is not None:
            kept.cleanup()
    given = list(sys.argv[1:] if argv is None else argv)
    meta = {"command": " ".join(["python -m scenarios.collect", *given]),
            "args": {k: v for k, v in vars(args).items() if k not in EXPORT_KEYS and _jsonable(v)},
            "frame_settings": {"fps": settings.fps, "cameras": list(settings.cameras),
                               "image_size_px": settings.image_size_px, "action_space": settings.action_space,
                               "pix_fmt": args.pix_fmt},
            "figures": figures, "episodes": rows}
    (Path(args.out) / MMACT_META).write_text(json.dumps(meta, indent=2))
    return figures


def _verify(root: Path, kept: Path) -> dict:
    """The round trip (``mmact_ctrl.datasets.roundtrip``) against the frames kept in ``kept``."""
    from dataclasses import asdict

    from mmact_ctrl.datasets.layout import IMAGES_PREFIX
    from mmact_ctrl.datasets.reader import LeRobotDataset
    from mmact_ctrl.datasets.roundtrip import round_trip

    rt = round_trip(LeRobotDataset.open(root), lambda ep, key: np.load(kept / f"{ep}_{key[len(IMAGES_PREFIX):]}.npy"))
    return {k: (v.item() if hasattr(v, "item") else v) for k, v in {**asdict(rt), "ok": rt.ok()}.items()}


def _jsonable(value) -> bool:
    try:
        json.dumps(value)
        return True
    except TypeError:
        return False


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parser.parse_args(argv)
    try:
        if args.show:
            from scenarios.lerobot_show import show

            print(show(args.show, rerun=args.rerun, episode=args.episode))
            return 0
        if not args.out:
            raise ValueError("--out DIR is needed (or --show DIR to look at a dataset)")
        figures = collect_lerobot(args, argv)
    except (ValueError, FileNotFoundError, RuntimeError, ConnectionError, TimeoutError) as exc:
        parser.error(str(exc).splitlines()[0] if str(exc) else type(exc).__name__)
    from scenarios.lerobot_show import show

    print(show(args.out))
    rt = figures.get("round_trip")
    if rt is not None:
        print(f"round trip: {rt['frames']} frames read back, PSNR min {rt['psnr_min_db']:.1f} dB (median "
              f"{rt['psnr_median_db']:.1f}), timestamp error max {rt['timestamp_error_max_s']:.1e} s, missing "
              f"{rt['frames_missing']}, timestamps exact {rt['timestamps_exact']}, indices contiguous "
              f"{rt['index_contiguous']}: {'ok' if rt['ok'] else 'FAILED'}")
    print(f"collection {figures['collect_fps']:.0f} frames/s (the episodes, rendering included), export "
          f"{figures['export_fps']:.0f} frames/s (encoding and writing)")
    return 0
