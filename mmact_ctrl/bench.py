"""Benchmark of the control layer: median and p99 per component, and the real-time factor of an episode.

    python -m mmact_ctrl.bench [--json PATH] [--calls N]
    python -m mmact_ctrl.bench --floor [--floor-args "--source expert"] [--json PATH]
    python -m mmact_ctrl.bench --sweep [--sweep-args "--workers 1 2"] [--json PATH]

``--floor``: the floor of the command path (``mmact_ctrl.bench_floor``): the bare calls a tick cannot avoid
(``mj_step``, Pinocchio's terms, OSQP's warm-started solve, the safety check) timed in tight loops on the inputs of
a recorded episode of the main job, beside our tick, the episode's wall time per simulated ms and, when mink is
installed, mink's ``solve_ik`` on the same Panda, all in one run.

``--sweep``: the studies' speed (``scenarios.sweep_scaling``): the same sweep grid with 1 and 2 workers (and on Ray
with ``--sweep-args "--ray-address auto"``), its episodes per CPU-second of the whole process tree, the speed-up, and
whether the results are identical run for run.

Components: ``pinocchio`` (all robot terms for one state), ``qp`` (build + OSQP solve),
``ruckig`` (one smoother step, position and orientation), ``kf`` (one filter step),
``mpc`` (one MPC solve, when ``controllers.mpc`` is available), ``tick`` (the command path of a controller
tick in a real episode, as real time runs it), ``tick_after`` (the tick with the work real time does after the
command: fusion, chunk admission, the MPC's update), ``mj_step`` (one world step: ``mj_step``
plus writing the controls and moving the target) and ``realtime_factor`` of a hybrid episode
with the scripted source. The world and source are loaded by name (``--world``, ``--source``)
so that this module never imports the simulator.
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
import time
from pathlib import Path

import numpy as np

from controllers.qp_id import TaskReference
from controllers.target_estimator import EstimatorConfig, TargetEstimator
from mmact_ctrl.config import StackConfig
from mmact_ctrl.controller import HybridController
from mmact_ctrl.loop import run_episode


def _load(name: str):
    module, _, attr = name.partition(":")
    if not attr:
        raise ValueError(f"expected 'module:function', got {name!r}")
    return getattr(importlib.import_module(module), attr)


def _stats(samples_s: list[float] | np.ndarray) -> dict:
    us = np.asarray(samples_s, dtype=float) * 1e6
    return {"median_us": float(np.median(us)), "p99_us": float(np.percentile(us, 99)), "n": int(us.size)}


def _time(fn, n: int) -> dict:
    fn()  # warm
    samples = np.empty(n)
    for i in range(n):
        t0 = time.perf_counter()
        fn()
        samples[i] = time.perf_counter() - t0
    return _stats(samples)


def bench_components(calls: int = 2000, seed: int = 0) -> dict:
    """Per-component timings on states drawn around the home pose."""
    rng = np.random.default_rng(seed)
    controller = HybridController(StackConfig())
    model = controller.model
    q0 = model.home_q_rad
    states = [(q0 + rng.normal(0, 0.2, 7), rng.normal(0, 0.3, 7)) for _ in range(64)]
    i = [0]

    def next_state():
        i[0] = (i[0] + 1) % len(states)
        return states[i[0]]

    out = {"pinocchio": _time(lambda: model.terms(*next_state()), calls)}
    pos0, rot0 = model.fk(q0)

    def qp_call():
        q, dq = next_state()
        terms = model.terms(q, dq)
        ref = TaskReference(pos0 + 0.02, np.zeros(3), np.zeros(3), rot0, np.zeros(3), np.zeros(3), q0)
        controller.qp.reset(terms.h)  # independent states: the robot holding itself in each (its torque-rate box)
        t0 = time.perf_counter()
        controller.qp.solve(terms, q, dq, ref)
        return time.perf_counter() - t0

    qp_call()
    out["qp"] = _stats([qp_call() for _ in range(calls)])
    controller.smoother.reset(pos0, np.zeros(3))
    k = [0]

    def ruckig_call():
        k[0] += 1
        jump = 0.05 if k[0] % 200 == 0 else 0.0  # a chunk switch now and then
        ref = pos0 + np.array([0.2 * k[0] * 1e-3 % 0.3 + jump, 0.0, 0.0])
        controller.smoother.step(ref, np.array([0.2, 0.0, 0.0]), np.zeros(3), np.zeros(3))

    out["ruckig"] = _time(ruckig_call, calls)
    kf = TargetEstimator(EstimatorConfig())  # the estimator the stack runs (cv, zero latency)
    kt = [0]

    def kf_call():
        kt[0] += 1
        z = None if kt[0] % 10 == 0 else np.array([0.5, 0.2 * kt[0] * 0.01, 0.3]) + rng.normal(0, 0.002, 3)
        kf.step(kt[0] * 0.01, z)

    out["kf"] = _time(kf_call, calls)
    try:
        from controllers.mpc_bench import bench_mpc
    except ImportError:
        pass
    else:
        out["mpc"] = {k: v for k, v in bench_mpc().items() if k in ("median_us", "p99_us", "n")}
    return out


def bench_perception(world_factory: str, sensor_factory: str, frames: int = 60, seed: int = 0) -> dict:
    """One camera perception step: render + detection (``sensor.capture``) + the filter's fusion, on frames of a
    moving target; and what it costs per simulated second at the sensor's rate."""
    world = _load(world_factory)()
    sensor = _load(sensor_factory)(world)
    world.reset(seed)
    sensor.reset(seed)
    est = TargetEstimator(EstimatorConfig(dt_s=1.0 / sensor.config.rate_hz))
    sensor.capture(0.0)  # warm-up: the first capture creates the renderer
    every = int(round(1.0 / (sensor.config.rate_hz * world.dt_s)))
    step_times, render_times = [], []
    hold = np.zeros(7)
    for k in range(frames * every):
        world.step(world_hold_torque(world, hold), 0.08)
        if k % every == 0:
            t0 = time.perf_counter()
            m = sensor.capture(k * world.dt_s)
            t1 = time.perf_counter()
            est.fuse(m.t_capture_s, m.pos_m)
            step_times.append(time.perf_counter() - t0)
            render_times.append(t1 - t0)
    getattr(sensor, "close", lambda: None)()
    world.close()
    out = {"perception_step": _stats(step_times), "camera_capture": _stats(render_times)}
    out["perception_ms_per_sim_s"] = float(np.median(step_times) * 1e3 * sensor.config.rate_hz)
    return out


def world_hold_torque(world, out: np.ndarray) -> np.ndarray:
    """Gravity compensation of the world's arm (the bench only needs it to stand still while frames are taken)."""
    if not hasattr(world_hold_torque, "_model"):
        from controllers.robot_model import PandaModel

        world_hold_torque._model = PandaModel()
    state = world.state()
    out[:] = world_hold_torque._model.terms(state.q_rad, state.dq_rad_s).h
    return out


def bench_episode(world_factory: str, source_factory: str, duration_s: float = 6.0, seed: int = 0,
                  sensor_factory: str | None = None) -> dict:
    """Whole-tick and world-step timings, and the real-time factor, of one hybrid episode (with the target
    measured by ``sensor_factory``'s sensor when given)."""
    world = _load(world_factory)()
    source = _load(source_factory)()
    sensor = _load(sensor_factory)(world) if sensor_factory else None
    controller = HybridController(StackConfig(duration_s=duration_s,
                                              perception_hz=sensor.config.rate_hz if sensor else 100.0))
    step_times: list[float] = []
    inner = world.step

    def timed_step(tau, gripper):
        t0 = time.perf_counter()
        inner(tau, gripper)
        step_times.append(time.perf_counter() - t0)

    world.step = timed_step  # instrument the world step only
    log = run_episode(world, source, controller, seed=seed, sensor=sensor)
    getattr(sensor, "close", lambda: None)()
    world.close()
    return {
        "tick": _stats(log.tick_us * 1e-6),
        "tick_after": _stats((log.tick_us + log.after_us) * 1e-6),
        "mpc_solve": _stats(np.asarray(log.mpc_solve_us) * 1e-6) if log.mpc_solve_us else None,
        "mj_step": _stats(step_times),
        "realtime_factor": float(duration_s / log.wall_s),
        "sensor_s_per_sim_s": float(log.sensor_wall_s / duration_s),
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m mmact_ctrl.bench", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--calls", type=int, default=2000, help="calls per component")
    p.add_argument("--duration-s", type=float, default=6.0, help="length of the timed hybrid episode, s")
    p.add_argument("--world", default="scenarios.world.factory:make_world", help="module:function that builds the world")
    p.add_argument("--source", default="scenarios.world.factory:make_expert", help="module:function that builds the chunk source")
    p.add_argument("--sensor", default="scenarios.world.camera_sensor:make_camera_sensor",
                   help="module:function(world) that builds the camera sensor timed as the perception step ('' to skip)")
    p.add_argument("--json", metavar="PATH", help="write {component: {median_us, p99_us}, realtime_factor: x}")
    p.add_argument("--floor", action="store_true",
                   help="the floor of the command path beside our tick, the episode and mink (see above)")
    p.add_argument("--floor-args", default="", metavar="SWITCHES",
                   help="--floor: more switches of scenarios.moving_target for the main job's episodes "
                        "(default: its own defaults, hybrid, linear target)")
    p.add_argument("--floor-episodes", type=int, default=3, help="--floor: timed episodes (seeds 3, 4, ...)")
    p.add_argument("--floor-recorder", default="scenarios.bench_floor:record_main_job",
                   help="--floor: module:function(extra_args, episodes, seed, duration_s) -> FloorRecording")
    p.add_argument("--sweep", action="store_true",
                   help="the sweep's episodes per CPU-second and its scaling over workers (see above)")
    p.add_argument("--sweep-args", default="", metavar="SWITCHES",
                   help="--sweep: switches of python -m scenarios.sweep_scaling (default: the --quick grid, 1 and 2 "
                        "workers)")
    p.add_argument("--sweep-runner", default="scenarios.sweep_scaling:main", help="--sweep: module:function(argv)")
    args = p.parse_args(argv)
    if args.sweep:
        import shlex

        return _load(args.sweep_runner)(shlex.split(args.sweep_args) + (["--json", args.json] if args.json else []))
    if args.calls < 10 or args.duration_s <= 0:
        p.error(f"--calls must be >= 10 and --duration-s > 0, got {args.calls} and {args.duration_s}")
    if args.floor:
        return _floor_main(args, p)
    results = bench_components(args.calls)
    results.update(bench_episode(args.world, args.source, args.duration_s))
    if args.sensor:
        results.update(bench_perception(args.world, args.sensor))
        camera = bench_episode(args.world, args.source, args.duration_s, sensor_factory=args.sensor)
        results["realtime_factor_camera"] = camera["realtime_factor"]
        results["camera_sensor_s_per_sim_s"] = camera["sensor_s_per_sim_s"]
    print(f"{'component':<12}{'median [us]':>14}{'p99 [us]':>12}")
    for name, r in results.items():
        if isinstance(r, dict):
            print(f"{name:<12}{r['median_us']:>14.1f}{r['p99_us']:>12.1f}")
    print("tick: the 1 kHz command path of the hybrid episode as real time runs it (state -> checked command); "
          "tick_after: with the work real time does after the command on the same thread (fusing measurements, "
          "admitting chunks, the MPC's 50 Hz update); the MPC's solve runs beside both (mpc_solve)")
    source_name = "scripted source" if args.source == "scenarios.world.factory:make_expert" else f"source {args.source}"
    print(f"{f'real-time factor (hybrid episode, {source_name})':<12}: {results['realtime_factor']:.1f}x")
    if "realtime_factor_camera" in results:
        print(f"camera perception: {results['perception_ms_per_sim_s']:.0f} ms per simulated second at the sensor rate; "
              f"hybrid episode with the camera: {results['realtime_factor_camera']:.1f}x real time "
              f"(sensor {1e3 * results['camera_sensor_s_per_sim_s']:.0f} ms per simulated second)")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(results, indent=2))
        print(f"wrote {args.json}")
    return 0


def _floor_main(args: argparse.Namespace, p: argparse.ArgumentParser) -> int:
    from mmact_ctrl.bench_floor import floor_report, format_floor

    if args.floor_episodes < 1:
        p.error(f"--floor-episodes must be >= 1, got {args.floor_episodes}")
    try:
        rec = _load(args.floor_recorder)(args.floor_args, args.floor_episodes, 3, args.duration_s)
    except SystemExit as exc:  # a bad switch in --floor-args: argparse said which
        p.error(f"--floor-args {args.floor_args!r} was refused (above), exit {exc.code}")
    report = floor_report(rec)
    print(format_floor(report))
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(report, indent=2))
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
