"""The simulator side of the floor benchmark (``python -m mmact_ctrl.bench --floor``): the main job's episodes timed,
one of them recorded (states, torques, the QP each tick assembled), the bare ``mj_step`` of its scene replayed, and
``mink.solve_ik`` on the same Panda at its states when mink is installed (``pip install 'mmact-ctrl[bench]'``).

The main job is ``python -m scenarios.moving_target --mode hybrid --target linear`` on its defaults (our policy, the
camera it looks at, 1 Hz, 200 ms); ``--floor-args`` passes other switches of that command (``--source expert``,
``--task pick``, ...).
"""

from __future__ import annotations

import shlex
import time

import mujoco
import numpy as np

from mmact_ctrl.bench_floor import FloorRecording
from mmact_ctrl.controller import HybridController
from mmact_ctrl.loop import run_episode

#: mink's solve_ik is timed at this many of the episode's states
MINK_CALLS = 2000


def _recording_qp(controller: HybridController) -> list:
    """Wrap the controller's QP fast path so that each tick's assembled problem and solution are kept."""
    qp, rows = controller.qp, []
    inner = qp._solve_fast

    def solve_fast(terms, q_rad, dq_rad_s, ref, tau):
        ddq, ok = inner(terms, q_rad, dq_rad_s, ref, tau)
        rows.append((qp.assembled(), np.array(ddq, dtype=float)))
        return ddq, ok

    qp._solve_fast = solve_fast
    return rows


def replay_mj_step(world, seed: int, tau_nm: np.ndarray, gripper_m: float = 0.08) -> np.ndarray:
    """The bare ``mujoco.mj_step`` of ``world``'s scene, replaying ``tau_nm`` (n, 7) from the episode's start, s per
    step."""
    world.reset(seed)
    m, d = world.model, world.data
    arm, grip = world._arm_act, world._grip_act
    out = np.empty(len(tau_nm))
    for i in range(len(tau_nm)):
        d.ctrl[arm] = tau_nm[i]
        d.ctrl[grip] = gripper_m
        t0 = time.perf_counter()
        mujoco.mj_step(m, d)
        out[i] = time.perf_counter() - t0
    return out


def mink_solve_ik(world, q_rad: np.ndarray, calls: int = MINK_CALLS) -> np.ndarray | None:
    """``mink.solve_ik`` (a frame task on the TCP site, mink's default configuration limits, DAQP) at ``calls`` of
    the recorded arm states, the target 2 cm from the TCP; s per call. None when mink is not installed."""
    try:
        import mink
    except ImportError:
        return None
    from scenarios.world.panda_scene import TCP_SITE

    model = world.model
    config = mink.Configuration(model)
    task = mink.FrameTask(frame_name=TCP_SITE, frame_type="site", position_cost=1.0, orientation_cost=1.0)
    arm_q = world._arm_qpos
    q_full = model.qpos0.copy()
    picks = np.linspace(0, len(q_rad) - 1, min(calls, len(q_rad))).astype(int)
    out = np.empty(len(picks))
    for n, i in enumerate(picks):
        q_full[arm_q] = q_rad[i]
        config.update(q_full)
        pose = config.get_transform_frame_to_world(TCP_SITE, "site")
        task.set_target(mink.SE3.from_translation(np.array([0.02, 0.0, 0.0])) @ pose)
        t0 = time.perf_counter()
        mink.solve_ik(config, [task], 0.001, "daqp", damping=1e-3)
        out[n] = time.perf_counter() - t0
    return out


def record_main_job(extra_args: str = "", episodes: int = 3, seed: int = 3, duration_s: float = 6.0) -> FloorRecording:
    """Time ``episodes`` hybrid episodes of the main job (``extra_args``: more switches of ``scenarios.moving_target``),
    then record one more on the first seed for the floor's inputs."""
    from scenarios.moving_target import make_sensor
    from scenarios.moving_target_args import build_parser, stack_config
    from scenarios.sources import close_source
    from scenarios.moving_target import make_source_and_world

    argv = ["--mode", "hybrid", "--target", "linear", "--duration-s", str(duration_s), "--quiet"]
    args = build_parser().parse_args(argv + shlex.split(extra_args))
    cfg = stack_config(args, "hybrid")
    source, world = make_source_and_world(args)
    try:
        sensor = make_sensor(args, world, cfg.dt_s)
        ticks, afters, rtf, wall = [], [], [], 0.0
        for i in range(episodes):
            log = run_episode(world, source, HybridController(cfg), seed=seed + i, sensor=sensor)
            ticks.append(log.tick_us)
            afters.append(log.tick_us + log.after_us)
            rtf.append(cfg.duration_s / log.wall_s)
            wall += log.wall_s
        controller = HybridController(cfg)
        rows = _recording_qp(controller)
        log = run_episode(world, source, controller, seed=seed, sensor=sensor)
        n = min(len(rows), len(log.q_rad))
        qp_data = tuple(np.array([r[0][k] for r in rows[:n]]) for k in range(5))
        ddq = np.array([r[1] for r in rows[:n]])
        q, dq, tau = log.q_rad[:n], log.dq_rad_s[:n], log.tau_cmd_nm[:n]
        mj = replay_mj_step(world, seed, tau)
        mink_s = mink_solve_ik(world, q)
        getattr(sensor, "close", lambda: None)()
    finally:
        world.close()
        close_source(source)
    label = f"hybrid, {args.source}, {args.target} {args.speed} m/s, task {args.task}"
    return FloorRecording(q_rad=q, dq_rad_s=dq, tau_nm=tau, ddq_rad_s2=ddq, qp_data=qp_data, mj_step_s=mj,
                          tick_us=np.concatenate(ticks), tick_after_us=np.concatenate(afters),
                          realtime_factors=tuple(rtf), sim_s=episodes * cfg.duration_s, wall_s=wall, label=label,
                          mink_solve_ik_s=mink_s)
