"""The main job: a chunk source drives the Panda toward a moving target, with and without the control layer.

    python -m scenarios.moving_target                      # both modes, linear target, table side by side
    python -m scenarios.moving_target --mode hybrid --target jump --json out/run.json --plot out/run.png

Prints a table; ``--json PATH`` writes ``{"config", "summary", "episodes", "runs"}`` (``summary`` and
``episodes`` are those of the last ``--mode`` given; ``runs`` holds every mode's); ``--plot PATH``
draws TCP vs target over time and the error curve; ``--video PATH`` writes an MP4 from the camera.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import sys
import textwrap
import time
from pathlib import Path

import numpy as np

from controllers.qp_id import REALTIME_MAX_ITER, QPConfig, SolverSettings
from controllers.retarget import RULES, RetargetConfig
from controllers.target_estimator import FILTER_MODELS, EstimatorConfig
from mmact_ctrl.config import MODES, StackConfig
from mmact_ctrl.controller import HybridController
from mmact_ctrl.loop import run_episode
from mmact_ctrl.metrics import episode_metrics, summarize
from mmact_ctrl.report import format_table, write_json
from policy.checkpoint import CheckpointError
from scenarios.world.targets import KINDS as TARGET_KINDS
from scenarios.world.expert import LEADS
from mmact_ctrl.executors import make_executor
from mmact_ctrl.sources.action_space import GRIPPERS, KINDS as ACTION_KINDS
from mmact_ctrl.sources.contract import require_capabilities
from scenarios.world.factory import POLICY_PLANE_Z_M, make_world
from scenarios.cli import HelpFormatter, OneLineErrorParser
from scenarios.cli import number as _number
from scenarios.sources import (build_source, close_source, connect_check, scene_settings, settings_from_args,
                               source_spec_arg)

PROG = "python -m scenarios.moving_target"
DEFAULT_SOURCE = "policy"
#: per-tick lists of the episode metrics that the summary pools and the JSON leaves out
PER_TICK_KEYS: tuple[str, ...] = ("exec_us", "mpc_solve_us")
#: the fastest target any arm here can follow: the Panda's TCP speed limit, m/s
MAX_SPEED_M_S = 1.7
#: the fastest replanning that means anything: the slow loop at the target channel's rate, Hz
MAX_REPLAN_HZ = 100.0


def _refine_bins(text: str):
    """``auto`` (the checkpoint's matched window), else an integer >= 0."""
    return "auto" if text == "auto" else _number(int, "--refine-bins (an integer >= 0 or auto)", 0)(text)


def _plane(text: str):
    if text.strip().lower() == "auto":
        return "auto"
    return _number(float, "--plane-z-m", 0, True, 0.6)(text)


def _scale(text: str) -> tuple[float, ...]:
    """``--action-scale``: one number > 0 or a comma-separated list of them."""
    parse = _number(float, "--action-scale (numbers > 0, comma-separated)", 0, False)
    return tuple(parse(t.strip()) for t in text.split(","))


def _clip(text: str):
    """``--action-clip``: ``LO,HI`` with LO < HI, or ``none``."""
    if text.strip().lower() == "none":
        return "none"
    parts = text.split(",")
    parse = _number(float, "--action-clip (LO,HI or none)")
    if len(parts) != 2 or not parse(parts[0]) < parse(parts[1]):
        raise argparse.ArgumentTypeError(f"--action-clip must be LO,HI with LO < HI, or none, got {text!r}")
    return parse(parts[0]), parse(parts[1])


def _latency(text: str):
    if text.strip().lower() == "measured":
        return "measured"
    return _number(float, "--latency-ms", 0)(text)


EPILOG = """examples:
  python -m scenarios.moving_target                                   # the shipped policy, open_loop vs hybrid, linear target
  python -m scenarios.moving_target --source expert --target reversal --replan-hz 5
  python -m scenarios.moving_target --source examples/byo_source.py:make_source --mode hybrid
  python -m scenarios.moving_target --source my_pkg.policies:make --source-arg horizon=50 --source-arg dt_s=0.05
  python -m scenarios.serve --source policy --port 8000 &            # a policy in another process ...
  python -m scenarios.moving_target --source ws://127.0.0.1:8000 --latency-ms measured   # ... driving the stack
  python -m scenarios.moving_target --mode hybrid --target jump --json out/run.json --plot out/run.png
"""


def build_parser() -> argparse.ArgumentParser:
    p = OneLineErrorParser(
        prog=PROG,
        description=textwrap.fill(
            "Drive the MuJoCo Panda toward a moving target with an action-chunk source (by default the shipped "
            "unified-token policy; or the scripted expert, your own Python source, or a policy server speaking "
            "openpi's protocol) and measure how much the 1 kHz control layer (Kalman filter + chunk retargeting + "
            "Ruckig + MPC + task-space QP) buys back over executing each chunk open-loop and over the field's fixes.",
            width=100),
        epilog=EPILOG,
        formatter_class=HelpFormatter,
    )
    src = p.add_argument_group("chunk source")
    src.add_argument("--source", type=source_spec_arg, default=DEFAULT_SOURCE, metavar="SOURCE",
                     help="policy: the shipped unified-token policy looks at the camera and reads the instruction; "
                          "expert: the scripted expert (by default it leads the target from two frames, see "
                          "--expert-lead); module.path:factory or path/file.py:factory: your own source (README, "
                          "'Bring your own policy'); ws://HOST:PORT: a policy server speaking openpi's protocol "
                          "(python -m scenarios.serve, or any openpi server). Default: policy")
    src.add_argument("--source-arg", action="append", default=[], metavar="KEY=VALUE",
                     help="a keyword setting for a module:factory source (repeatable; VALUE is read as JSON when it "
                          "parses, else as a string)")
    src.add_argument("--preset", metavar="NAME|PATH", default=None,
                     help="ws:// source: the convention its policy was trained in, in one switch: libero (openpi's "
                          "LIBERO client: 224 px frames upright, 8-D state, each row one 20 Hz step of robosuite's "
                          "OSC, normalised to [-1, 1] x 0.05 m / 0.5 rad, gripper -1 open / +1 closed), droid (joint "
                          "velocities x 0.2 rad per 15 Hz step, gripper 1 = closed), mmact (ours), or a JSON preset "
                          "file (README, 'Conventions'). Each piece's own switch below overrides it. Default: what the "
                          "server declares; a foreign server that declares nothing needs it (or every piece)")
    src.add_argument("--obs-mapping", metavar="NAME|PATH", default=None,
                     help="ws:// source: which observation keys carry images, state and prompt: libero, droid, mmact "
                          "(ours: it carries the true target, which no real robot has), or a JSON mapping file; "
                          "overrides the preset's")
    src.add_argument("--action-space", choices=ACTION_KINDS, default=None,
                     help="ws:// source: the kind of its actions (overrides the preset's)")
    src.add_argument("--gripper", choices=GRIPPERS, default=None,
                     help="ws:// source: the convention of its actions' last value: width_m (m), open_1 (1 = open), "
                          "close_1 (1 = closed: DROID), sign (-1 open, +1 closed: LIBERO), none (overrides the preset's)")
    src.add_argument("--delta-from", choices=("observation", "previous"), default=None,
                     help="ws:// source with tcp_delta / joint_delta actions: observation = every row is a delta from "
                          "the observed pose; previous = rows are successive steps, each from the one before (LIBERO's "
                          "and DROID's); overrides the preset's")
    src.add_argument("--action-rotation", choices=("nominal", "world"), default=None,
                     help="ws:// source with tcp_pose actions: world = an absolute world-frame axis-angle; nominal = "
                          "ours, relative to the hand pointing down (overrides the preset's)")
    src.add_argument("--action-scale", type=_scale, default=None, metavar="S[,S...]",
                     help="ws:// source: what one unit of each arm dimension is, m or rad (one value, or one per arm "
                          "dimension: 6 for TCP actions, 7 for joints); the gripper value is not scaled (overrides the "
                          "preset's; libero: 0.05,0.05,0.05,0.5,0.5,0.5; droid: 0.2)")
    src.add_argument("--action-clip", type=_clip, default=None, metavar="LO,HI|none",
                     help="ws:// source: clip every action value to [LO, HI] before scaling, as the trained controller "
                          "did (none: no clipping; overrides the preset's)")
    src.add_argument("--image-rotation", type=int, choices=(0, 180), default=None,
                     help="ws:// source: turn our frames (they come out upright) by this many degrees before sending "
                          "(180: what robosuite's raw renders look like); overrides the preset's (0)")
    src.add_argument("--expert-lead", choices=LEADS, default=None,
                     help="expert: velocity = it sees two frames (t0 - 0.1 s and t0), estimates the target's velocity and "
                          "aims each waypoint where the target will be at that waypoint's time (latency included); "
                          "none = it aims where the target is in the frame at t0 (a single-frame policy). Default: velocity")
    src.add_argument("--checkpoint", metavar="PATH", default=None,
                     help="policy checkpoint (default: the shipped policy/checkpoints/mmact_small.pt)")
    src.add_argument("--action-steps", type=_number(int, "--action-steps", 1), default=None,
                     help="policy: decoding passes per chunk (default 1: the whole chunk in one forward pass)")
    src.add_argument("--refine-bins", type=_refine_bins, default=None,
                     help="policy: 0 = each action token's bin centre; W > 0 = the probability-weighted mean bin "
                          "within +-W bins of the greedy token (sub-bin detokenizing from the same forward pass); "
                          "auto (default) = the window matched to the checkpoint's Gaussian training labels (4 std: 64)")
    g = p.add_argument_group("execution")
    g.add_argument("--mode", nargs="+", choices=MODES, default=["open_loop", "hybrid"],
                   help="open_loop: dequantized waypoints interpolated and tracked by the QP, nothing else; "
                        "receding: run the first k waypoints of each chunk, then replan (Diffusion Policy); "
                        "temporal_ensemble: average overlapping chunks with exponential weights (ACT); "
                        "inpaint: real-time chunking, the waypoints that run during inference are frozen and the rest "
                        "filled in; residual: an A2C2-style learned correction from the latest target measurements and "
                        "the TCP state, tracked by the QP (--residual-checkpoint); hybrid: ours, Kalman-filtered "
                        "retargeting + Ruckig + MPC + QP. "
                        "Several modes run side by side on the same seeds.")
    g.add_argument("--receding-k", type=_number(int, "--receding-k", 0), default=0,
                   help="receding: waypoints run per chunk before replanning (0: 1 / (replan-hz * chunk-dt-s))")
    g.add_argument("--ensemble-decay", type=_number(float, "--ensemble-decay", 0), default=1.0,
                   help="temporal_ensemble: weight exp(-decay * age difference in s), oldest chunk weighs most")
    g.add_argument("--residual-checkpoint", metavar="PATH", default=None,
                   help="residual: the learned residual's checkpoint (default: the shipped policy/checkpoints/residual.pt, "
                        "trained by python -m scenarios.train_residual)")
    g.add_argument("--no-ruckig", action="store_true", help="hybrid: track the retargeted reference without Ruckig smoothing")
    g.add_argument("--no-mpc", action="store_true",
                   help="hybrid: no MPC between Ruckig and the QP (the QP tracks the smoothed reference directly)")
    g.add_argument("--retarget", choices=RULES, default="warp",
                   help="hybrid: displacement shifts the chunk by how far the filtered target moved since the observation; "
                        "snap pulls the chunk's aim onto the filtered target (also removes aim and quantization error), "
                        "blended in over time; warp (default) does the same in proportion to the chunk's own progress "
                        "along its path, so a chunk that aims beside the ball does not push the arm off it; none")
    g.add_argument("--trust-radius-m", type=_number(float, "--trust-radius-m", 0, False), default=0.3,
                   help="retargeting only applies when the target is within this distance of the chunk's aim")
    g.add_argument("--replan-hz", type=_number(float, "--replan-hz", 0, False, MAX_REPLAN_HZ), default=1.0,
                   help=f"how often the chunk source is queried (Hz; the slow loop: at most {MAX_REPLAN_HZ:g}, the "
                        "target channel's rate)")
    g.add_argument("--latency-ms", type=_latency, default=200.0,
                   help="inference latency: a chunk observed at t0 becomes active at t0 + latency; 'measured' uses each "
                        "chunk's measured inference time")
    g.add_argument("--chunk-timeout-s", type=_number(float, "--chunk-timeout-s", 0, False), default=2.5,
                   help="stale-chunk watchdog: when no valid chunk has arrived for this long, or the active chunk has "
                        "run out, the reference brakes to rest within the smoother's limits and holds (counted)")
    g.add_argument("--splice-radius-m", type=_number(float, "--splice-radius-m", 0, False), default=0.1,
                   help="a chunk whose position when it becomes active is farther than this from the reference being "
                        "executed is rejected and counted; the previous chunk keeps running")
    g.add_argument("--bins", type=_number(int, "--bins", 0), default=2048,
                   help="action bins per dimension of the tokenizer (0 = no quantization)")
    g.add_argument("--horizon", type=_number(int, "--horizon", 1), default=None,
                   help="expert: waypoints per chunk (H, default 16); a ws:// server decides its own")
    g.add_argument("--chunk-dt-s", type=_number(float, "--chunk-dt-s", 0, False), default=None,
                   help="expert: waypoint spacing, s (default 0.1); ws:// source: the server's waypoint spacing, "
                        "overriding its preset's")
    w = p.add_argument_group("world")
    w.add_argument("--target", choices=TARGET_KINDS, default="linear", help="how the target moves")
    w.add_argument("--plane-z-m", type=_plane, default="auto",
                   help="objects at this height (+ up to 2 cm) moving horizontally, as in the policy's training scenes; "
                        f"0 = the full 3-D workspace; auto = the checkpoint's training plane with --source policy ({POLICY_PLANE_Z_M} "
                        "for the shipped one), the scene a server of ours declares, else 0 (--source expert, a "
                        "module:factory source or a foreign ws:// server: the full 3-D workspace)")
    w.add_argument("--objects", type=int, choices=(1, 2), default=None,
                   help="objects in the scene (two differently coloured balls: the instruction names one; default: "
                        "the source's scene, else 2)")
    w.add_argument("--instruction", metavar="TEXT", default=None,
                   help="a fixed instruction for every episode, naming one object by colour (default: a random "
                        "phrasing naming a random object per episode)")
    w.add_argument("--speed", type=_number(float, "--speed", 0, True, MAX_SPEED_M_S), default=0.2,
                   help=f"target speed (m/s; at most {MAX_SPEED_M_S:g}, the Panda's TCP speed limit: no arm follows a "
                        "faster target)")
    w.add_argument("--noise-m", type=_number(float, "--noise-m", 0), default=0.002,
                   help="standard deviation of the 100 Hz target measurement noise (m)")
    w.add_argument("--dropout", type=_number(float, "--dropout", 0, True, 0.99), default=0.1,
                   help="probability that a target measurement is missed")
    w.add_argument("--perception", choices=("oracle", "camera"), default="oracle",
                   help="where the hybrid layer's target measurements come from: oracle = the truth + --noise-m "
                        "Gaussian noise with --dropout; camera = the instructed ball measured in rendered depth + "
                        "segmentation images of --cameras (pixel quantization, depth noise growing with distance, "
                        "occlusion by the arm)")
    w.add_argument("--perception-hz", type=_number(float, "--perception-hz", 0, False, 1000.0), default=None,
                   help="measurement rate (Hz; default 100 for oracle, 30 for camera)")
    w.add_argument("--perception-latency-ms", type=_number(float, "--perception-latency-ms", 0), default=None,
                   help="capture-to-arrival delay of each measurement (exposure + processing; ms; default 0 for "
                        "oracle, 50 for camera): the filter fuses it at its capture time and predicts to now")
    w.add_argument("--cameras", nargs="+", default=["front"], metavar="NAME",
                   help="camera perception: the scene camera(s) that measure the ball (front, top, side)")
    w.add_argument("--filter", choices=FILTER_MODELS, default="cv",
                   help="target model of the Kalman filter: cv constant velocity, ca constant acceleration, imm an "
                        "interacting multiple model of both (follows curving and accelerating targets), ct a "
                        "coordinated turn (constant speed and turn rate about the vertical), imm-ct an interacting "
                        "multiple model of cv, ca and ct (predicts along a circle: the best for curving targets)")
    w.add_argument("--episodes", type=_number(int, "--episodes", 1), default=10, help="episodes per mode")
    w.add_argument("--duration-s", type=_number(float, "--duration-s", 0, False), default=6.0, help="episode length (s)")
    w.add_argument("--seed", type=_number(int, "--seed", 0), default=0, help="seed of the first episode (episode i uses seed+i)")
    o = p.add_argument_group("output")
    o.add_argument("--json", metavar="PATH", help="write {config, summary, episodes, runs} as JSON")
    o.add_argument("--plot", metavar="PATH", help="write a PNG of TCP vs target and the error over time (first episode per mode)")
    o.add_argument("--video", metavar="PATH", help="write an MP4 of the first episode per mode from the camera (MUJOCO_GL=egl)")
    o.add_argument("--rerun", metavar="PATH.rrd",
                   help="write a Rerun recording of the first episode per mode (TCP path, target and its estimate, "
                        "the active chunk, the reference, the MPC preview, per-tick error / torque rate / tick time / "
                        "overruns, the camera frames of each query); view it later with: rerun PATH.rrd "
                        "(needs pip install -e '.[viz]')")
    o.add_argument("--viewer", action="store_true",
                   help="watch the episodes in MuJoCo's passive viewer (needs a display; without one: one line saying so)")
    o.add_argument("--quiet", action="store_true", help="no progress bar")
    r = p.add_argument_group("real time")
    r.add_argument("--realtime", action="store_true",
                   help="run physics and control paced to the wall clock at 1 kHz, the chunk source computing in its "
                        "own process meanwhile (a ws:// source as it is; policy, expert or module:factory started by "
                        "this command through python -m scenarios.serve), the MPC in a process of its own; each chunk "
                        "becomes active when it actually arrives (--latency-ms does not apply). Reports overruns, "
                        "cycles missed, tick work and jitter, control_command_success_rate and the real-time rate")
    r.add_argument("--mpc-phase-ms", type=_number(float, "--mpc-phase-ms", 0, True, 19.999), default=None,
                   help="hybrid: the MPC ticks are this long after each 20 ms mark (default 5 with --realtime, so the "
                        "MPC's work and the 100 Hz fusion fall on different ticks; 0 otherwise)")
    r.add_argument("--qp-max-iter", type=_number(int, "--qp-max-iter", 1, True, 100000), default=None,
                   help="OSQP's iteration cap in the 1 kHz QP; a solve not converged by then goes to DAQP's exact "
                        "active-set solve (default 100 with --realtime, which bounds the command path's worst case; "
                        "400 otherwise, as every simulated-time study ran)")
    r.add_argument("--rt-priority", type=_number(int, "--rt-priority", 0, True, 99), default=0,
                   help="real time: run the loop's thread under SCHED_FIFO at this priority (0: normal scheduling; "
                        "needs the right to, else it runs at normal priority and says so)")
    return p


def stack_config(args: argparse.Namespace, mode: str) -> StackConfig:
    return StackConfig(
        mode=mode,
        use_ruckig=not args.no_ruckig,
        use_mpc=not args.no_mpc,
        retarget=RetargetConfig(rule=args.retarget, trust_radius_m=args.trust_radius_m),
        replan_hz=args.replan_hz,
        latency_ms=0.0 if args.latency_ms == "measured" else args.latency_ms,
        measured_latency=args.latency_ms == "measured",
        bins=args.bins,
        duration_s=args.duration_s,
        receding_k=args.receding_k,
        ensemble_decay_per_s=args.ensemble_decay,
        chunk_timeout_s=args.chunk_timeout_s,
        splice_radius_m=args.splice_radius_m,
        residual_checkpoint=args.residual_checkpoint or "",
        perception_hz=perception_hz(args),
        # a noise-free oracle repeats itself legitimately: the frozen gate is for real (noisy) sensors
        filter=EstimatorConfig(model=args.filter, frozen_gate=args.perception == "camera" or args.noise_m > 0),
        # real time: the MPC's 50 Hz work off the 100 Hz fusion's ticks (StackConfig.mpc_phase_s)
        mpc_phase_s=mpc_phase_ms(args) / 1000.0,
        qp=QPConfig(solver=SolverSettings(max_iter=qp_max_iter(args))),
    )


def qp_max_iter(args: argparse.Namespace) -> int:
    """``--qp-max-iter``, else ``controllers.qp_id.REALTIME_MAX_ITER`` in real time and ``QPConfig.max_iter`` in simulated time."""
    value = getattr(args, "qp_max_iter", None)
    if value is not None:
        return int(value)
    return REALTIME_MAX_ITER if getattr(args, "realtime", False) else QPConfig().max_iter


def mpc_phase_ms(args: argparse.Namespace) -> float:
    """``--mpc-phase-ms``, else 5 ms in real time (``StackConfig.mpc_phase_s``) and 0 in simulated time."""
    value = getattr(args, "mpc_phase_ms", None)
    if value is not None:
        return float(value)
    return 5.0 if getattr(args, "realtime", False) else 0.0


def perception_hz(args: argparse.Namespace) -> float:
    if args.perception_hz is not None:
        return float(args.perception_hz)
    return 30.0 if args.perception == "camera" else 100.0


def perception_latency_ms(args: argparse.Namespace) -> float:
    if args.perception_latency_ms is not None:
        return float(args.perception_latency_ms)
    return 50.0 if args.perception == "camera" else 0.0


def make_sensor(args: argparse.Namespace, world, dt_s: float):
    """The target sensor of ``--perception`` on ``world``."""
    if args.perception == "camera":
        from scenarios.world.camera_sensor import CameraSensor, CameraSensorConfig

        return CameraSensor(world, CameraSensorConfig(rate_hz=perception_hz(args), latency_ms=perception_latency_ms(args),
                                                      cameras=tuple(args.cameras)))
    from mmact_ctrl.perception import OracleSensor

    return OracleSensor(world, perception_hz(args), perception_latency_ms(args), dt_s)


def make_source(args: argparse.Namespace, world=None):
    """The chunk source of ``--source`` (``scenarios.sources``)."""
    return build_source(settings_from_args(args), world)


def make_source_and_world(args: argparse.Namespace):
    """The source and the world it runs in: the expert's world is built first (it reads its workspace); any other
    source first, and its world with the scene it asks for (our policy's cameras and training plane, a foreign
    source's cameras), ``--plane-z-m`` / ``--objects`` overriding."""
    settings = settings_from_args(args)
    settings.check()
    world_kw = dict(noise_m=args.noise_m, dropout=args.dropout, instruction=args.instruction)
    if settings.kind == "expert":
        plane_z_m = 0.0 if args.plane_z_m == "auto" else args.plane_z_m
        world = make_world(args.target, args.speed, n_objects=args.objects or 2, plane_z_m=plane_z_m, **world_kw)
        return build_source(settings, world), world
    source = build_source(settings)
    try:
        scene = scene_settings(source)
        plane = scene.pop("plane_z_m", 0.0)
        objects = scene.pop("n_objects", 2)
        world = make_world(args.target, args.speed, n_objects=args.objects or objects,
                           plane_z_m=plane if args.plane_z_m == "auto" else args.plane_z_m, **scene, **world_kw)
    except BaseException:
        close_source(source)
        raise
    return source, world


def check_modes_of_running(args: argparse.Namespace) -> None:
    """One-line errors for switches that cannot go together (before any work)."""
    if args.realtime:
        if args.video:
            raise ValueError("--video renders in the 1 kHz loop: not with --realtime (use --rerun PATH.rrd)")
        if args.perception == "camera":
            raise ValueError("--perception camera renders depth images in the 1 kHz loop: not with --realtime yet")
        if args.viewer:
            raise ValueError("--viewer syncs the viewer in the 1 kHz loop: not with --realtime (use --rerun PATH.rrd)")
    if args.viewer:
        from scenarios.world.viewer import require_display

        require_display()


def realtime_source_args(args: argparse.Namespace):
    """Real time: (the arguments with the source as a ws:// URL, the ServedSource started for it or None)."""
    from scenarios.served import ServedSource, serve_argv

    settings = settings_from_args(args)
    settings.check()
    if settings.kind == "remote":
        return args, None
    from mmact_ctrl.realtime.loop_thread import cpu_split

    _, workers = cpu_split(0)
    served = ServedSource(serve_argv(settings), cpus=workers)
    # the served source declares itself: none of its own switches apply to the URL
    remote = argparse.Namespace(**{**vars(args), "source": served.url, "checkpoint": None, "source_arg": [],
                                   "action_steps": None, "refine_bins": None, "expert_lead": None, "horizon": None,
                                   "chunk_dt_s": None})
    return remote, served


def _episode_runner(args: argparse.Namespace, world, source, controller, sensor, stack: contextlib.ExitStack):
    """``run(seed, record) -> EpisodeLog`` for one mode: on the wall clock (``--realtime``), in the viewer
    (``--viewer``) or plain; what it opens is closed by ``stack``."""
    if args.realtime:
        from mmact_ctrl.realtime.session import RealtimeConfig, RealtimeSession

        session = stack.enter_context(RealtimeSession(world, source, controller,
                                                      RealtimeConfig(fifo_priority=args.rt_priority)))
        if session.priority_refused:
            print(f"note: {session.priority_refused}; the loop runs at normal priority", file=sys.stderr)
        return lambda seed, record, fps: session.episode(seed, sensor=sensor, record=record)
    if args.viewer:
        from scenarios.world.viewer import run_with_viewer

        return lambda seed, record, fps: run_with_viewer(world, source, controller, seed, sensor=sensor, record=record)
    return lambda seed, record, fps: run_episode(world, source, controller, seed=seed, video_fps=fps, sensor=sensor,
                                                 record=record)


def run(args: argparse.Namespace) -> dict:
    """Run every requested mode on the same seeds; returns the JSON payload."""
    from tqdm import tqdm

    configs = {mode: stack_config(args, mode) for mode in args.mode}  # validates before any work
    check_modes_of_running(args)
    runs: dict[str, dict] = {}
    first_logs = {}
    with contextlib.ExitStack() as stack:  # everything opened below is closed, whatever happens
        source_args = args
        if args.realtime:
            source_args, served = realtime_source_args(args)
            if served is not None:
                stack.callback(served.close)
        source, world = make_source_and_world(source_args)
        stack.callback(world.close)
        stack.callback(close_source, source)
        connect = _connect(args, source, world)
        # a mode that needs what the source cannot do (inpainting): one line now, not a silent episode later
        for mode in configs:
            require_capabilities(source, make_executor(mode).needs, mode)
        sensor = make_sensor(args, world, next(iter(configs.values())).dt_s)
        stack.callback(getattr(sensor, "close", lambda: None))
        bar = tqdm(total=len(configs) * args.episodes, desc="episodes", unit="ep", disable=args.quiet, file=sys.stderr)
        stack.callback(bar.close)
        for mode, cfg in configs.items():
            controller = HybridController(cfg)
            episodes, ticks, afters = [], [], []
            with contextlib.ExitStack() as mode_stack:
                episode = _episode_runner(args, world, source, controller, sensor, mode_stack)
                for i in range(args.episodes):
                    log = episode(args.seed + i, bool(args.rerun) and i == 0, 30.0 if (args.video and i == 0) else 0.0)
                    m = episode_metrics(log)
                    m["mode"] = mode
                    episodes.append(m)
                    ticks.append(log.tick_us)
                    afters.append(log.after_us)
                    if i == 0:
                        first_logs[mode] = log
                    _say_source_errors(bar, mode, i, args.seed + i, m, bool(args.json))
                    bar.set_postfix(mode=mode, success=f"{np.mean([e['success'] for e in episodes]):.0%}")
                    bar.update(1)
            summary = summarize(episodes, np.concatenate(ticks), np.concatenate(afters))
            for e in episodes:  # per-tick lists: pooled into the summary, too long for the JSON (medians stay)
                for key in PER_TICK_KEYS:
                    e.pop(key, None)
            runs[mode] = {"config": dataclasses.asdict(cfg), "summary": summary, "episodes": episodes}
    last = args.mode[-1]
    payload = {
        "config": {**vars(args), "modes": list(args.mode), "mode": last, "stack": runs[last]["config"],
                   "target_spec": dataclasses.asdict(world.target), "objects": int(world.n_objects),
                   "cameras": list(world.scene.camera_names),
                   "refine_bins_used": getattr(source, "refine_bins", None),
                   "source_url": getattr(source, "name", args.source) if args.realtime else args.source,
                   **({"connect": connect.to_dict()} if connect is not None else {})},
        "summary": runs[last]["summary"],
        "episodes": runs[last]["episodes"],
        "runs": runs,
    }
    payload["_logs"] = first_logs
    payload["_connect"] = connect
    return payload


def _connect(args: argparse.Namespace, source, world):
    """A policy server's connect check (``scenarios.sources.connect_check``), its block printed; None otherwise."""
    measured = args.realtime or args.latency_ms == "measured"
    report = connect_check(source, world, args.seed, args.replan_hz, None if measured else args.latency_ms / 1e3,
                           "measured: the first call's round trip" if measured else "--latency-ms")
    if report is not None:
        print("\n".join(report.lines()), flush=True)
    return report


def _say_source_errors(bar, mode: str, i: int, seed: int, m: dict, in_json: bool) -> None:
    """Once per episode: the first line of what the source said when it failed (the whole text is in the JSON)."""
    errors = m.get("source_errors")
    if not errors:
        return
    n = sum(e["count"] for e in errors)
    more = f" (+{len(errors) - 1} other error text{'s' if len(errors) > 2 else ''})" if len(errors) > 1 else ""
    where = "; the whole text is in the JSON (episodes[].source_errors)" if in_json else ""
    bar.write(f"{mode} episode {i + 1} (seed {seed}): the source failed {n} time{'s' if n != 1 else ''}: "
              f"{errors[0]['line']}{more}{where}", file=sys.stderr)


def _watchdog_note(payload: dict, connect) -> None:
    """Why the arm braked, when the connect check knows: the chunks ran out before the next arrived."""
    stops = sum(e.get("watchdog_stops", 0) for r in payload["runs"].values() for e in r["episodes"])
    cov = connect.coverage if connect is not None else None
    if stops and cov is not None and not cov.covers:
        fix = (f"--replan-hz {cov.suggested_replan_hz:g} covers them" if cov.suggested_replan_hz is not None
               else "no replan rate covers them")
        print(f"\nnote: {stops} watchdog stop(s): each chunk ({cov.chunk_s:g} s) ran out before the next was active "
              f"(replan every {cov.period_s:g} s + latency {cov.latency_s * 1e3:.0f} ms); {fix}")


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    args.mode = list(dict.fromkeys(args.mode))
    try:
        t0 = time.perf_counter()
        payload = run(args)
    except (ValueError, FileNotFoundError, CheckpointError, ConnectionError, TimeoutError, RuntimeError) as exc:
        # bad configuration, a missing or unreadable checkpoint, a server that is down: one clear line
        parser.error(str(exc).splitlines()[0] if str(exc) else type(exc).__name__)
    logs = payload.pop("_logs")
    connect = payload.pop("_connect")
    # a static target has no speed: printing --speed's default next to it read as if it moved
    target_desc = "static target" if args.target == "static" else f"{args.target} target at {args.speed:g} m/s"
    latency = args.latency_ms if args.latency_ms == "measured" else f"{args.latency_ms:g}"
    run_desc = (f"{args.source} source, {payload['config']['objects']} object(s), {target_desc}, replan {args.replan_hz:g} Hz, "
                f"latency {latency} ms")  # one description: table header and plot title
    if args.source == "expert":  # the expert's chunks go through the action tokenizer; other sources have their own
        run_desc += f", {args.bins or 'no'} bins"
    if args.realtime:
        run_desc = run_desc.replace(f"latency {latency} ms", "real time (latency as it ran)")
        if args.source != payload["config"]["source_url"]:
            run_desc = run_desc.replace(f"{args.source} source", f"{args.source} source (served at {payload['config']['source_url']})")
    if args.source == "policy" and not args.realtime:  # our policy in this process (in real time: served)
        w = payload["config"]["refine_bins_used"]
        passes = "one pass" if (args.action_steps or 1) == 1 else f"{args.action_steps} passes"
        run_desc += f" (policy: {passes}, {'refine +-' + str(w) + ' bins' if w else 'bin centres'})"
    print(f"\n{run_desc}, {args.episodes} episodes x {args.duration_s:g} s per mode "
          f"({time.perf_counter() - t0:.1f} s wall)\n")
    print(format_table({m: r["summary"] for m, r in payload["runs"].items()}))
    _watchdog_note(payload, connect)
    if args.json:
        write_json(args.json, payload)
        print(f"\nwrote {args.json}")
    if args.plot:
        from mmact_ctrl.plotting import plot_runs

        plot_runs(logs, args.plot, title=run_desc)
        print(f"wrote {args.plot}")
    if args.rerun:
        from mmact_ctrl.recording import write_recording

        write_recording(logs, args.rerun, camera_names=tuple(payload["config"]["cameras"]))
        print(f"wrote {args.rerun}  (view it: rerun {args.rerun})")
    if args.video:
        from scenarios.world.video import write_mp4

        for mode, log in logs.items():
            path = Path(args.video)
            if len(logs) > 1:
                path = path.with_name(f"{path.stem}_{mode}{path.suffix or '.mp4'}")
            write_mp4(log.frames, path, fps=30.0)
            print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
