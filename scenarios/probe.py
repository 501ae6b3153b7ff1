"""The conformance probe: does a policy server answer as the convention it is said to speak? One observation, in
seconds, before any episode.

    python -m scenarios.probe ws://127.0.0.1:8000 --preset libero
    python -m scenarios.probe ws://GPU-BOX:8000 --preset droid --json probe.json
    python -m scenarios.probe ws://127.0.0.1:8000                       # a server of ours declares its convention

It connects, settles the convention (the server's metadata and the switches, as ``moving_target`` does: the same
switches), sends the first observation of a scene (seed ``--seed``), and prints what went out (keys, shapes, dtypes),
what came back (the reply's keys, the actions' shape, dtype and range per dimension, the timing) and the chunk it
means in our task space; then what looks wrong for the convention (``mmact_ctrl.sources.conformance``: values outside
the clip range, a gripper outside its convention, deltas that look absolute or poses that look like deltas, a TCP
speed beyond the Panda's, NaN). Exit status: 0 when nothing looks wrong, 1 when something does (or the server
failed: its own words are printed), 2 for bad input or a server that cannot be reached or configured.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

from scenarios.cli import HelpFormatter, OneLineErrorParser
from scenarios.cli import number as _number

PROG = "python -m scenarios.probe"
#: the probe's budget for the one call (it should finish in under 10 s), s
CALL_TIMEOUT_S = 6.0


def build_parser() -> argparse.ArgumentParser:
    from scenarios.moving_target import build_parser as main_parser

    p = OneLineErrorParser(prog=PROG, description=__doc__.split("\n\n")[0], formatter_class=HelpFormatter,
                           epilog="examples:\n  " + "\n  ".join(ln.strip() for ln in __doc__.split("\n\n")[1].splitlines()))
    p.add_argument("url", help="the policy server, ws://HOST:PORT")
    conv = p.add_argument_group("the server's convention (as for python -m scenarios.moving_target)")
    main = {a.dest: a for a in main_parser()._actions}
    for dest in ("preset", "obs_mapping", "action_space", "gripper", "delta_from", "action_rotation", "action_scale",
                 "action_clip", "image_rotation", "chunk_dt_s"):
        a = main[dest]
        conv.add_argument(*a.option_strings, dest=dest, type=a.type, choices=a.choices, default=None,
                          metavar=a.metavar, help=a.help)
    s = p.add_argument_group("scene")
    s.add_argument("--seed", type=_number(int, "--seed", 0), default=0, help="the scene's seed")
    s.add_argument("--target", default="static", help="the target's motion (scenarios.world.targets)")
    p.add_argument("--json", metavar="PATH", help="also write what was sent, received and judged as JSON")
    return p


def _describe(value) -> str:
    a = np.asarray(value)
    if a.dtype.kind in "US" or isinstance(value, str):
        return f"text {str(value)[:40]!r}"
    if a.ndim == 0:
        return f"{a.dtype} scalar {a.item():.4g}" if a.dtype.kind in "biuf" else f"{a.dtype} {a.item()!r}"
    return f"{a.dtype} {tuple(a.shape)}"


def _ranges(actions: np.ndarray) -> list[str]:
    a = np.asarray(actions, dtype=np.float64).reshape(-1, actions.shape[-1])
    return [f"    dim {i}: {a[:, i].min():+.4g} .. {a[:, i].max():+.4g}" for i in range(a.shape[1])]


def _chunk_lines(waypoints: np.ndarray, obs, dt_s: float) -> list[str]:
    pos = np.vstack([obs.ee_pos_m, waypoints[:, :3]])
    step = np.linalg.norm(np.diff(pos, axis=0), axis=1)
    return [f"  in our task space: from TCP {np.round(obs.ee_pos_m, 3).tolist()} to {np.round(waypoints[-1, :3], 3).tolist()} "
            f"m, path {step.sum():.3f} m, fastest step {step.max() / dt_s:.2f} m/s, gripper "
            f"{waypoints[:, 6].min():.3f} .. {waypoints[:, 6].max():.3f} m"]


def probe(args: argparse.Namespace) -> tuple[dict, int]:
    """Probe the server; returns (what was found, exit status)."""
    from mmact_ctrl.sources.conformance import reply_problems
    from mmact_ctrl.sources.openpi import ClientConfig
    from mmact_ctrl.sources.remote import RemoteSource
    from scenarios.sources import SourceSettings, first_observation, scene_settings
    from scenarios.world.factory import make_world

    t_start = time.perf_counter()
    settings = SourceSettings(spec=args.url, chunk_dt_s=args.chunk_dt_s,
                              **{f: getattr(args, f) for f in ("preset", "obs_mapping", "action_space", "gripper",
                                                                "delta_from", "action_rotation", "action_scale",
                                                                "action_clip", "image_rotation")})
    source = RemoteSource(args.url, settings.convention_switches(),
                          ClientConfig(connect_timeout_s=3.0, connect_tries=1, request_timeout_s=CALL_TIMEOUT_S))
    found: dict = {"url": source.name, "metadata_keys": sorted(map(str, source.metadata)),
                   "convention": source.convention.name, "describe": source.describe()}
    print(f"connected to {source.name}: metadata keys {found['metadata_keys'] or 'none'}")
    print(f"  convention: {source.describe()}")
    scene = scene_settings(source)
    world = make_world(args.target, n_objects=int(scene.pop("n_objects", 2)), plane_z_m=float(scene.pop("plane_z_m", 0.0)),
                       **scene)
    try:
        obs = first_observation(world, args.seed, source.needs_image, source.adapter.model)
        sent = source.mapping.encode(obs, source._rot_nominal)
        print("  sent: " + "; ".join(f"{k} {_describe(v)}" for k, v in sent.items()))
        found["sent"] = {k: _describe(v) for k, v in sent.items()}
        status = _call(source, obs, found, reply_problems)
    finally:
        world.close()
        source.close()
    found["seconds"] = round(time.perf_counter() - t_start, 2)
    print(f"probe took {found['seconds']:.1f} s")
    return found, status


def _call(source, obs, found: dict, reply_problems) -> int:
    """One call, printed and judged; the exit status."""
    chunk, error = None, None
    try:
        chunk = source.plan(obs, timeout_s=CALL_TIMEOUT_S)
    except ValueError as exc:
        error = str(exc)
    except Exception as exc:  # noqa: BLE001 - the server's failure, in its own words
        text = getattr(exc, "text", "")
        print(f"  the server failed: {str(exc).splitlines()[0]}")
        if text:
            print("  its error text ends:\n    " + "\n    ".join(text.strip().splitlines()[-6:]))
        found.update(error=str(exc).splitlines()[0], error_text=text or None)
        return 1
    call = source.client.calls[-1]
    actions = np.asarray(source.last_actions)
    found.update(round_trip_ms=call.round_trip_ms, server_infer_ms=call.server_infer_ms,
                 actions_shape=list(actions.shape), actions_dtype=str(actions.dtype))
    timing = f"round trip {call.round_trip_ms:.1f} ms" + (f", server {call.server_infer_ms:.1f} ms"
                                                           if call.server_infer_ms is not None else "")
    print(f"  received: actions {actions.dtype} {tuple(actions.shape)} ({timing})")
    if actions.ndim >= 2 and actions.dtype.kind in "biuf":
        print("\n".join(_ranges(actions)))
    waypoints = chunk.waypoints if chunk is not None else None
    if waypoints is not None:
        print("\n".join(_chunk_lines(waypoints, obs, float(source.space.dt_s))))
    problems = reply_problems(actions, source.space, obs, waypoints, source.convention.horizon)
    if error is not None and not problems:
        problems = [error]
    found["problems"] = problems
    wrong = [p for p in problems if not p.startswith("(note)")]
    for p in problems:
        print(f"  {'note' if p.startswith('(note)') else 'looks wrong'}: {p.removeprefix('(note) ')}")
    print("  conforms: nothing looks wrong" if not wrong else f"  {len(wrong)} thing(s) look wrong")
    return 1 if wrong else 0


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        found, status = probe(args)
    except (ValueError, ConnectionError, TimeoutError, OSError, RuntimeError) as exc:
        parser.error(str(exc).splitlines()[0] if str(exc) else type(exc).__name__)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(found, f, indent=2, default=str)
        print(f"wrote {args.json}")
    return status


if __name__ == "__main__":
    sys.exit(main())
