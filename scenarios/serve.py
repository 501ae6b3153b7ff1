"""Serve a chunk source of ours over openpi's websocket policy protocol.

    python -m scenarios.serve --source policy --port 8000              # the shipped token policy
    python -m scenarios.serve --source expert --expert-lead velocity   # the scripted expert
    python -m scenarios.serve --source my_pkg.my_module:make_source --source-arg horizon=10
    python -m scenarios.serve --source expert --preset libero           # the expert speaking LIBERO's convention

With ``--preset`` the source speaks that convention instead of ours (``mmact_ctrl.sources.remote.preset_serving``):
it reads the convention's observation keys and answers its actions (LIBERO: successive normalised OSC steps at
20 Hz; DROID: normalised joint velocities at 15 Hz), and declares only its ``action_horizon`` and the privileged keys
it reads (the expert reads the true target): a client must say ``--preset`` itself, as with any foreign server.

Any openpi client (``openpi_client.websocket_client_policy.WebsocketClientPolicy``) can then drive it, and our stack
can run it from another process (``mmact_ctrl.sources.openpi.RemoteSource``). The observation travels in the
``mmact`` mapping, the reply holds ``"actions"`` (H, 7) in our task space, and the metadata frame says everything a
client of ours needs (``mmact_ctrl.sources.remote.serving``). ``GET /healthz`` answers ``OK``.
"""

from __future__ import annotations

import argparse
import asyncio
import signal
import sys

from mmact_ctrl.sources.contract import check_source
from mmact_ctrl.sources.openpi.server import DEFAULT_PORT, ListenError, PolicyServer
from mmact_ctrl.sources.remote.serving import SourcePolicy
from scenarios.cli import OneLineErrorParser as _OneLineErrorParser
from scenarios.cli import number as _number
from scenarios.world.tasks.registry import TASKS
from scenarios.world.expert import LEADS

PROG = "python -m scenarios.serve"
EPILOG = f"""examples:
  {PROG} --source policy --port 8000
  {PROG} --source policy --checkpoint policy/checkpoints/mmact_3d.pt --port 8001
  {PROG} --source expert --expert-lead none --horizon 10 --chunk-dt-s 0.05
  {PROG} --source my_pkg.sources:make_source --source-arg horizon=10 --source-arg lead=none
  {PROG} --source expert --host 0.0.0.0 --port 8000      # reachable from other machines
  {PROG} --source expert --preset droid --infer-delay-ms 150   # a DROID-speaking stand-in for a 150 ms model

check it:  curl http://127.0.0.1:8000/healthz   (answers OK)
"""

#: switches that only mean something for one kind of source: name -> (the source kind, argparse dest)
_ONLY_FOR = {"--checkpoint": ("policy", "checkpoint"), "--action-steps": ("policy", "action_steps"),
             "--refine-bins": ("policy", "refine_bins"), "--expert-lead": ("expert", "expert_lead"),
             "--bins": ("expert", "bins"), "--horizon": ("expert", "horizon"), "--chunk-dt-s": ("expert", "chunk_dt_s")}


def _source_arg(text: str) -> tuple[str, str]:
    key, sep, value = text.partition("=")
    if not sep or not key.strip():
        raise argparse.ArgumentTypeError(f"--source-arg must be KEY=VALUE, got {text!r}")
    return key.strip(), value


def _source(text: str) -> str:
    if text in ("policy", "expert") or (":" in text and "://" not in text):
        return text
    raise argparse.ArgumentTypeError(f"--source must be policy, expert or module.path:factory, got {text!r}")


def build_parser() -> argparse.ArgumentParser:
    p = _OneLineErrorParser(
        prog=PROG,
        description=("Serve a chunk source over openpi's websocket policy protocol (msgpack-numpy frames, the metadata "
                     "frame on connect, GET /healthz): the shipped token policy, the scripted expert, or any "
                     "module:factory source."),
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    s = p.add_argument_group("source")
    s.add_argument("--source", type=_source, default="policy",
                   help="policy (default): the shipped unified-token policy; expert: the scripted expert; "
                        "module.path:factory: a callable returning a chunk source")
    s.add_argument("--source-arg", type=_source_arg, action="append", default=[], metavar="KEY=VALUE",
                   help="module:factory: a keyword argument of the factory (repeatable; VALUE read as JSON when it "
                        "parses, else as a string)")
    s.add_argument("--checkpoint", metavar="PATH", default=None,
                   help="policy: the checkpoint (default: the shipped policy/checkpoints/mmact_small.pt)")
    s.add_argument("--action-steps", type=_number(int, "--action-steps", 1), default=None,
                   help="policy: decoding passes per chunk (default 1: the whole chunk in one forward pass)")
    s.add_argument("--refine-bins", default=None, metavar="W|auto",
                   help="policy: 0 = bin centres; W > 0 = probability-weighted mean within +-W bins; auto (default) = "
                        "the checkpoint's matched window")
    s.add_argument("--expert-lead", choices=LEADS, default=None,
                   help="expert: velocity (default) = two frames, it aims where the target will be at each waypoint's "
                        "time (reflected at the workspace walls); none = where one frame shows it")
    s.add_argument("--bins", type=_number(int, "--bins", 0), default=None,
                   help="expert: action bins of its tokenizer (default 2048; 0 = no quantization)")
    s.add_argument("--horizon", type=_number(int, "--horizon", 1), default=None,
                   help="expert: waypoints per chunk (default 16)")
    s.add_argument("--chunk-dt-s", type=_number(float, "--chunk-dt-s", 0, False, 10.0), default=None,
                   help="expert: waypoint spacing in s (default 0.1)")
    w = p.add_argument_group("scene the source is made for (expert, module:factory; the policy's comes from its checkpoint)")
    w.add_argument("--plane-z-m", type=_number(float, "--plane-z-m", 0, True, 0.6), default=0.0,
                   help="objects at this height (m), 0 = the full 3-D workspace (the expert's lead reflects at the "
                        "walls of this workspace)")
    w.add_argument("--objects", type=int, choices=(1, 2), default=2, help="objects in the scene")
    w.add_argument("--task", choices=TASKS, default="reach",
                   help="the task the scripted expert does (scenarios.world.tasks; run the client with the same --task)")
    c = p.add_argument_group("convention")
    c.add_argument("--preset", metavar="NAME|PATH", default=None,
                   help="expert or module:factory: speak this convention instead of ours (libero, droid, or a JSON "
                        "preset file): its observation keys, its actions, its spacing (the expert's --chunk-dt-s and "
                        "--horizon default to the preset's); the expert checks that each frame of a scene camera is "
                        "upright, as a policy of the convention was trained to see it, and refuses it otherwise")
    c.add_argument("--infer-delay-ms", type=_number(float, "--infer-delay-ms", 0, True, 60000.0), default=0.0,
                   help="answer each request this long after it arrived at the earliest (a stand-in for a slower "
                        "model), ms")
    n = p.add_argument_group("network")
    n.add_argument("--host", default="127.0.0.1",
                   help="address to listen on (default 127.0.0.1: this machine only; 0.0.0.0: every interface)")
    n.add_argument("--port", type=_number(int, "--port", 0, True, 65535), default=DEFAULT_PORT,
                   help=f"TCP port (default {DEFAULT_PORT}, openpi's; 0 = a free one)")
    return p


def _check_switches(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    kind = args.source if args.source in ("policy", "expert") else "module:factory"
    for flag, (only, dest) in _ONLY_FOR.items():
        if getattr(args, dest) is not None and kind != only:
            parser.error(f"{flag} applies to --source {only} only (got --source {args.source})")
    if args.source_arg and kind != "module:factory":
        parser.error(f"--source-arg applies to --source module.path:factory only (got --source {args.source})")
    if args.preset is not None and kind == "policy":
        parser.error("--preset applies to --source expert or module:factory: the policy reads its own cameras at its "
                     "own size (serve it in our convention)")


def _refine_bins(text: str | None) -> int | None:
    if text is None or text == "auto":
        return None
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise ValueError(f"--refine-bins must be an integer >= 0 or auto, got {text!r}")
    return value


def make_served_source(args: argparse.Namespace):
    """(the chunk source, its scene dict, a one-line description) of the arguments."""
    if args.source == "policy":
        from mmact_ctrl.policy_source import PolicyChunkSource
        from scenarios.world.factory import policy_scene

        source = PolicyChunkSource(args.checkpoint, action_steps=args.action_steps or 1,
                                   refine_bins=_refine_bins(args.refine_bins))
        scene = policy_scene(source)
        return source, scene, f"policy {source.checkpoint.name} (refine +-{source.refine_bins} bins)"
    scene = {"plane_z_m": float(args.plane_z_m), "n_objects": int(args.objects)}
    if args.source == "expert":
        from scenarios.world.factory import make_expert, make_world

        world = make_world("linear", plane_z_m=args.plane_z_m, n_objects=args.objects, task=args.task)  # its box
        try:
            lead = args.expert_lead or "velocity"
            conv = _preset(args)
            dt_s = args.chunk_dt_s or (conv.action.dt_s if conv is not None else 0.1)
            if conv is not None and abs(dt_s - conv.action.dt_s) > 1e-9:
                raise ValueError(f"--chunk-dt-s {dt_s:g} is not the {conv.name} preset's spacing "
                                 f"({conv.action.dt_s:g} s): leave it out")
            horizon = args.horizon or (conv.horizon if conv is not None and conv.horizon else 16)
            source = make_expert(bins=2048 if args.bins is None else args.bins, horizon=horizon, dt_s=dt_s, lead=lead,
                                 world=world)
        finally:
            world.close()
        cfg = source.config
        what = "scripted expert" if args.task == "reach" else f"scripted {args.task} expert"
        return source, scene, (f"{what} (lead {lead}, {cfg.horizon} x {cfg.dt_s:g} s, "
                               f"{source.tokenizer.bins if source.tokenizer else 'no'} bins)")
    from mmact_ctrl.sources.loader import load_source, parse_source_args

    source = load_source(args.source, parse_source_args(f"{k}={v}" for k, v in args.source_arg))
    return source, dict(getattr(source, "scene", None) or scene), f"{args.source}"


def _preset(args: argparse.Namespace):
    """The convention of ``--preset`` (None without it)."""
    if args.preset is None:
        return None
    from mmact_ctrl.sources.presets import load_preset

    try:
        return load_preset(args.preset)
    except ValueError as exc:
        raise ValueError(f"--preset: {exc}") from None


def make_policy(args: argparse.Namespace, source, scene: dict):
    """The openpi policy that serves ``source``: in our convention, or in ``--preset``'s."""
    conv = _preset(args)
    if conv is None:
        return SourcePolicy(check_source(source, f"--source {args.source}"), scene=scene,
                            infer_delay_ms=args.infer_delay_ms)
    from mmact_ctrl.sources.remote.mapping import PRIVILEGED_PARTS
    from mmact_ctrl.sources.remote.preset_serving import ConventionPolicy

    check_source(source, f"--source {args.source}")
    expert = args.source == "expert"
    return ConventionPolicy(source, conv, privileged=PRIVILEGED_PARTS if expert else (),
                            infer_delay_ms=args.infer_delay_ms, frame_check=_frame_checks(conv, scene) if expert else None)


def _frame_checks(conv, scene: dict):
    """The expert's eye: every image key of a scene camera must be upright (``scenarios.world.frame_check``)."""
    from scenarios.world.factory import make_world
    from scenarios.world.frame_check import UprightCheck

    keys = [k for k in getattr(conv.mapping, "images", ()) if k.camera in ("front", "top", "side")]
    if not keys:
        return None
    world = make_world("static", n_objects=int(scene.get("n_objects", 2)), cameras=tuple({k.camera for k in keys}))
    try:
        checks = [UprightCheck(world.model, k.camera, k.key, int(scene.get("n_objects", 2))) for k in keys]
    finally:
        world.close()

    def check(obs: dict, observation) -> None:
        for c in checks:
            c(obs, observation)

    return check


def banner(url: str, policy, what: str) -> str:
    """What is served, where, and what its metadata declares."""
    health = url.replace("ws://", "http://", 1) + "/healthz"
    if not isinstance(policy, SourcePolicy):
        conv = policy.convention
        return "\n".join([
            f"serving {what} at {url}   (health: {health})",
            f"  convention: {conv.name} (a client must say --preset {conv.name}: it is not declared); "
            f"{conv.mapping.describe()}",
            f"  actions: {conv.action.describe()}; metadata: {policy.metadata}",
            "  Ctrl-C stops."])
    m = policy.metadata["mmact"]
    space = m["action_space"]
    if m["needs_image"]:
        size = f"{m['image_size_px']} px" if m["image_size_px"] else "the world's default size"
        frames = f"frames of {', '.join(m['camera_names'])} at {size}"
        if m["prev_frame_gap_s"] > 0:
            frames += f" + the frames {m['prev_frame_gap_s']:g} s earlier"
    else:
        frames = "no images"
    tok = m["action_token_range"]
    scene = m["scene"] or {}
    return "\n".join([
        f"serving {what} at {url}   (health: {health})",
        f"  actions: {space['kind']} ({space['gripper']}), {m['chunk_dt_s']:g} s apart; observation: mmact keys, {frames}",
        f"  capabilities: {', '.join(m['capabilities']) or 'none'}; action tokens: "
        f"{f'[{tok[0]}, {tok[1]})' if tok else 'none'}; scene: "
        + (", ".join(f"{k} {v}" for k, v in scene.items()) or "not declared"),
        "  Ctrl-C stops.",
    ])


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    _check_switches(parser, args)
    try:
        source, scene, what = make_served_source(args)
        policy = make_policy(args, source, scene)
        server = PolicyServer(policy, host=args.host, port=int(args.port))
    except (ValueError, FileNotFoundError, RuntimeError) as exc:  # a bad checkpoint, factory or setting: one line
        parser.error(str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__)

    def ready(port: int) -> None:
        print(banner(f"ws://{args.host}:{port}", policy, what), flush=True)

    async def serve_until_signal() -> None:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):  # Ctrl-C, or kill: close the connections and the port cleanly
            loop.add_signal_handler(sig, stop.set)
        await server.run(on_ready=ready, stop=stop)

    try:
        asyncio.run(serve_until_signal())
    except ListenError as exc:
        parser.error(exc.strerror or str(exc))
    finally:
        getattr(source, "close", lambda: None)()
    print("stopped", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
