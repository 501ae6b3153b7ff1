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
import time
from pathlib import Path

import numpy as np

from mmact_ctrl.controller import HybridController
from mmact_ctrl.loop import run_episode
from mmact_ctrl.metrics import episode_metrics, summarize
from mmact_ctrl.report import format_table, write_json
from policy.checkpoint import CheckpointError
from mmact_ctrl.executors import make_executor
from mmact_ctrl.sources.contract import require_capabilities
from scenarios.moving_target_args import (DEFAULT_SOURCE, MAX_REPLAN_HZ, MAX_SPEED_M_S, PER_TICK_KEYS, PROG,  # noqa: F401
                                          build_parser, filter_accel_setting,
                                          mpc_phase_ms, perception_hz, perception_latency_ms, qp_max_iter, stack_config)
from scenarios.sources import build_source, close_source, connect_check, scene_settings, settings_from_args
from scenarios.world.factory import make_world

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
    world_kw = dict(noise_m=args.noise_m, dropout=args.dropout, instruction=args.instruction,
                    task=getattr(args, "task", "reach"), clearance_mm=getattr(args, "clearance_mm", 1.0))
    if settings.kind == "expert":
        plane_z_m = 0.0 if args.plane_z_m == "auto" else args.plane_z_m
        world = make_world(args.target, args.speed, n_objects=args.objects or 2, plane_z_m=plane_z_m, **world_kw)
        return build_source(settings, world), world
    if settings.kind == "policy" and world_kw["task"] != "reach":  # said, not refused: a study may want the figure
        print(f"note: the shipped policy is trained for reach only; with --task {world_kw['task']} it runs outside "
              f"its training (README, 'Contact')", file=sys.stderr)
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
    if getattr(args, "grasp_reflex", False):
        from mmact_ctrl.control.grasp_reflex import reflex_refusal

        for mode in args.mode:
            if not make_executor(mode).layers.reads_target:
                raise ValueError(reflex_refusal(mode))
    filter_accel_setting(args)  # --filter-accel-m-s2 with a model that has no such noise: one line, before any work
    if getattr(args, "mpc_delay_ms", None) is not None:
        if args.realtime:
            raise ValueError("--mpc-delay-ms is for simulated time: --realtime solves the MPC in its own process already")
        if args.no_mpc:
            raise ValueError("--mpc-delay-ms delays the MPC's plans: not with --no-mpc")
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
    argv = serve_argv(settings)
    if settings.kind == "expert":  # the expert of the task being run
        argv += ["--task", getattr(args, "task", "reach")]
    served = ServedSource(argv, cpus=workers)
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
    lookahead = not getattr(args, "no_lookahead", False)
    return lambda seed, record, fps: run_episode(world, source, controller, seed=seed, video_fps=fps, sensor=sensor,
                                                 record=record, lookahead=lookahead)


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
            runs[mode], first_logs[mode] = _run_mode(args, mode, cfg, world, source, sensor, bar)
    payload = _payload(args, runs, world, source, connect)
    payload["_logs"] = first_logs
    payload["_connect"] = connect
    return payload


def _run_mode(args: argparse.Namespace, mode: str, cfg, world, source, sensor, bar) -> tuple[dict, object]:
    """One mode's episodes on the seeds: ``({"config", "summary", "episodes"}, the first episode's log)``."""
    controller = HybridController(cfg)
    episodes, ticks, afters, first = [], [], [], None
    with contextlib.ExitStack() as mode_stack:
        mode_stack.callback(controller.close)  # the MPC's process, if --mpc-delay-ms
        episode = _episode_runner(args, world, source, controller, sensor, mode_stack)
        for i in range(args.episodes):
            log = episode(args.seed + i, bool(args.rerun) and i == 0, 30.0 if (args.video and i == 0) else 0.0)
            m = episode_metrics(log)
            m["mode"] = mode
            episodes.append(m)
            ticks.append(log.tick_us)
            afters.append(log.after_us)
            first = log if i == 0 else first
            _say_source_errors(bar, mode, i, args.seed + i, m, bool(args.json))
            bar.set_postfix(mode=mode, success=f"{np.mean([e['success'] for e in episodes]):.0%}")
            bar.update(1)
    summary = summarize(episodes, np.concatenate(ticks), np.concatenate(afters))
    for e in episodes:  # per-tick lists: pooled into the summary, too long for the JSON (medians stay)
        for key in PER_TICK_KEYS:
            e.pop(key, None)
    return {"config": dataclasses.asdict(cfg), "summary": summary, "episodes": episodes}, first


def _payload(args: argparse.Namespace, runs: dict, world, source, connect) -> dict:
    """The JSON: ``{"config", "summary", "episodes"}`` of the last mode, and ``runs`` of every mode."""
    last = args.mode[-1]
    return {
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
