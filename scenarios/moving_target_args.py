"""The main job's command line: its switches (by group), their one-line checks, and what they make (the stack's
configuration, the rates and latencies that follow from them). ``scenarios.moving_target`` runs it."""

from __future__ import annotations

import argparse
import textwrap

from controllers.qp_id import REALTIME_MAX_ITER, QPConfig, SolverSettings
from controllers.retarget import RULES, RetargetConfig
from controllers.target_estimator import FILTER_MODELS, EstimatorConfig
from mmact_ctrl.config import MODES, StackConfig
from mmact_ctrl.sources.action_space import GRIPPERS, KINDS as ACTION_KINDS
from scenarios.cli import HelpFormatter, OneLineErrorParser
from scenarios.cli import number as _number
from scenarios.sources import source_spec_arg
from scenarios.world.expert import LEADS
from scenarios.world.factory import POLICY_PLANE_Z_M
from scenarios.world.targets import KINDS as TARGET_KINDS

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
    _source_args(p)
    _execution_args(p)
    _world_args(p)
    _task_args(p)
    _output_args(p)
    _realtime_args(p)
    return p


def _source_args(p: argparse.ArgumentParser) -> None:
    """The chunk source and, for a ws:// source, its convention."""
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


def _execution_args(p: argparse.ArgumentParser) -> None:
    """How chunks are executed: the mode and every layer's switch."""
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


def _world_args(p: argparse.ArgumentParser) -> None:
    """The scene: the target's motion, the objects, the measurement channel, the episodes."""
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
    w.add_argument("--filter-accel-m-s2", type=_number(float, "--filter-accel-m-s2", 0, False), default=None,
                   metavar="A",
                   help="--filter cv: the standard deviation of its white (piecewise-constant) acceleration, m/s^2 "
                        "(default: EstimatorConfig's 2.0). Larger follows a carrier's flip sooner and a steady course "
                        "more noisily (README, Contact, 'Out of sample again': pick's reversal at 5)")
    w.add_argument("--episodes", type=_number(int, "--episodes", 1), default=10, help="episodes per mode")
    w.add_argument("--duration-s", type=_number(float, "--duration-s", 0, False), default=6.0, help="episode length (s)")
    w.add_argument("--seed", type=_number(int, "--seed", 0), default=0, help="seed of the first episode (episode i uses seed+i)")


def _task_args(p: argparse.ArgumentParser) -> None:
    """The task (``scenarios.world.tasks``) and the contact layers."""
    from scenarios.world.tasks.registry import TASKS

    t = p.add_argument_group("task and contact")
    t.add_argument("--task", choices=TASKS, default="reach",
                   help="reach: the TCP within 3 cm of a ball for 0.3 s (mocap balls, no contact); pick: grasp the "
                        "instructed cube on a conveyor moving as --target at --speed and lift it 5 cm for 1 s "
                        "(the scripted expert can; the shipped policy was trained for reach only)")
    t.add_argument("--clearance-mm", type=_number(float, "--clearance-mm", 0, False), default=1.0,
                   help="insert: the hole's clearance over the peg, per side (mm)")
    t.add_argument("--grasp-reflex", action="store_true",
                   help="the fast layer keeps the gripper open until the measured object is between the fingers "
                        "and closes it then, whatever the chunk's clock says (default: the chunk's gripper channel)")
    t.add_argument("--close-at-grasp", action="store_true",
                   help="pick, in a mode that reads the object: the gripper starts closing only with the TCP down at "
                        "its grasp height (not 8 mm above it), and the hand stops coming down there while it closes "
                        "(a pad sliding down the cube's side wedged it against the belt; README, Contact, point 14: "
                        "fewer episodes over the contact-force limit, fewer picks); default: the closing as published")
    t.add_argument("--compliance", action="store_true",
                   help="in contact (a measured force over 3 N, and 0.1 s after), the TCP tracks its reference as a "
                        "spring-damper whose force is capped at 2/3 of --contact-force-limit-n, in place of stiff "
                        "tracking (controllers.qp.impedance, mmact_ctrl.control.compliance_gate); stiff in free "
                        "space; every mode")
    t.add_argument("--contact-force-limit-n", type=_number(float, "--contact-force-limit-n", 0, False), default=30.0,
                   help="external force on the robot above which a tick counts as a contact_force violation (N; "
                        "franka_ros2's default collision thresholds are 30 N lower / 40 N upper)")


def _output_args(p: argparse.ArgumentParser) -> None:
    """What is written: JSON, plot, video, Rerun, viewer."""
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


def _realtime_args(p: argparse.ArgumentParser) -> None:
    """Real time: the wall clock, the MPC's phase, the QP's cap, the loop's priority."""
    r = p.add_argument_group("real time")
    r.add_argument("--no-lookahead", action="store_true",
                   help="simulated time: call the chunk source in line, the loop waiting for it (by default a source "
                        "that declares its plan pure, as the shipped policy does, is called in a worker thread while "
                        "the ticks before its chunk's activation run: the same results bit for bit, sooner)")
    r.add_argument("--realtime", action="store_true",
                   help="run physics and control paced to the wall clock at 1 kHz, the chunk source computing in its "
                        "own process meanwhile (a ws:// source as it is; policy, expert or module:factory started by "
                        "this command through python -m scenarios.serve), the MPC in a process of its own; each chunk "
                        "becomes active when it actually arrives (--latency-ms does not apply). Reports overruns, "
                        "cycles missed, tick work and jitter, control_command_success_rate and the real-time rate")
    r.add_argument("--mpc-phase-ms", type=_number(float, "--mpc-phase-ms", 0, True, 19.999), default=None,
                   help="hybrid: the MPC ticks are this long after each 20 ms mark (default 5 with --realtime, so the "
                        "MPC's work and the 100 Hz fusion fall on different ticks; 0 otherwise)")
    r.add_argument("--mpc-delay-ms", type=_number(float, "--mpc-delay-ms", 0, True, 20.0), default=None,
                   help="simulated time, hybrid: solve the 50 Hz MPC in a process of its own beside the loop and take "
                        "each plan this long after the tick that asked for it (0-20 ms; deterministic whatever the "
                        "load; 0 gives the default's results bit for bit). Off by default: the plan is solved inline "
                        "and drives the tick that asked for it, as every published figure ran. A speed option: the "
                        "solve leaves the loop's thread; what the older plan costs is in the README (Speed)")
    r.add_argument("--qp-max-iter", type=_number(int, "--qp-max-iter", 1, True, 100000), default=None,
                   help="OSQP's iteration cap in the 1 kHz QP; a solve not converged by then goes to DAQP's exact "
                        "active-set solve (default 100 with --realtime, which bounds the command path's worst case; "
                        "400 otherwise, as every simulated-time study ran)")
    r.add_argument("--rt-priority", type=_number(int, "--rt-priority", 0, True, 99), default=0,
                   help="real time: run the loop's thread under SCHED_FIFO at this priority (0: normal scheduling; "
                        "needs the right to, else it runs at normal priority and says so)")


def stack_config(args: argparse.Namespace, mode: str) -> StackConfig:
    """The stack of ``mode`` from the switches; the task (``--task``) sets the TCP floor it needs and the axes a chunk is
    retargeted on (``scenarios.world.tasks``)."""
    from scenarios.world.tasks.registry import task_by_name, task_guard_settings, task_target_box

    task = task_by_name(getattr(args, "task", "reach"))
    return StackConfig(
        mode=mode,
        use_ruckig=not args.no_ruckig,
        use_mpc=not args.no_mpc,
        retarget=RetargetConfig(rule=args.retarget, trust_radius_m=args.trust_radius_m, pull_axes=task.pull_axes),
        **({"tcp_floor_m": task.tcp_floor_m} if task.tcp_floor_m is not None else {}),
        contact_force_limit_n=getattr(args, "contact_force_limit_n", 30.0),
        grasp_reflex=bool(getattr(args, "grasp_reflex", False)),
        target_box_m=task_target_box(task),
        compliance=bool(getattr(args, "compliance", False)),
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
        filter=EstimatorConfig(model=args.filter, frozen_gate=args.perception == "camera" or args.noise_m > 0,
                               **filter_accel_setting(args)),
        # real time: the MPC's 50 Hz work off the 100 Hz fusion's ticks (StackConfig.mpc_phase_s)
        mpc_phase_s=mpc_phase_ms(args) / 1000.0,
        mpc_delay_s=None if getattr(args, "mpc_delay_ms", None) is None else args.mpc_delay_ms / 1000.0,
        qp=QPConfig(solver=SolverSettings(max_iter=qp_max_iter(args))),
        **task_guard_settings(task, bool(getattr(args, "close_at_grasp", False))),
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


def filter_accel_setting(args: argparse.Namespace) -> dict:
    """``--filter-accel-m-s2`` as an ``EstimatorConfig`` setting (none: the config's default); a model other than
    cv, which has no such noise, is a one-line error naming both switches."""
    accel = getattr(args, "filter_accel_m_s2", None)
    if accel is None:
        return {}
    if args.filter != "cv":
        raise ValueError(f"--filter-accel-m-s2 sets the cv model's noise; --filter {args.filter} has none")
    return {"accel_noise_m_s2": float(accel)}


def perception_latency_ms(args: argparse.Namespace) -> float:
    if args.perception_latency_ms is not None:
        return float(args.perception_latency_ms)
    return 50.0 if args.perception == "camera" else 0.0
