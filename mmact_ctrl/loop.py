"""The multi-rate loop: physics and control at 1 kHz, perception at 100 Hz, the chunk source at ``replan_hz``.

The observation is taken at ``t0``; the chunk it produces becomes active at ``t0 + latency``
while the previous chunk keeps running. Waypoints already in the past when a chunk arrives
are skipped (the reference is indexed by absolute time).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from controllers.safety import NONFINITE, CommandLimits, SafetyMonitor
from mmact_ctrl.chunk import ChunkSource, Observation
from mmact_ctrl.chunk_intake import ChunkIntake
from mmact_ctrl.controller import HybridController
from mmact_ctrl.executors import QueryContext
from mmact_ctrl.frame_history import EarlierFrame
from mmact_ctrl.perception import OracleSensor, TargetSensor
from mmact_ctrl.sources.contract import require_capabilities
from mmact_ctrl.world import World

#: the earlier frame a chunk source is shown beside the current one (``Observation.target_prev_pos_m``), s
FRAME_GAP_S = 0.1
#: the timing a source may report in ``ActionChunk.info`` (a remote source: its round trip and the server's own
#: inference time), ms; collected per chunk into ``EpisodeLog.source_timing_ms``
SOURCE_TIMING_KEYS: tuple[str, ...] = ("round_trip_ms", "server_infer_ms", "policy_infer_ms")


@dataclass
class EpisodeLog:
    """Everything recorded in one episode (arrays sampled every control period; shorter than the episode
    when it was aborted).

    Safety (``controllers.safety``): ``safety_counts`` ticks flagged per kind, ``safety_mask`` the per-tick
    bitmask, ``torque_rate_max_nm_s`` the largest torque rate sent. Faults survived: ``rejections`` chunks
    rejected per reason (``mmact_ctrl.chunk_intake``), ``watchdog_stops``, ``gated_measurements`` (per gate),
    ``missed_ticks``; ``abort`` is ``{"t_s", "reason"}`` when the robot would have aborted the motion.
    ``events`` lists ``(t_s, what, detail)`` of every fault handled. ``change_times_s``: when the target's motion
    changed course (``World.target_change_times_s``); ``delay_steps``: per activated chunk, the waypoints of the
    running chunk consumed while it was computed (activation time minus observation time, in chunk steps: the
    inference delay d of RTC, as it actually ran).
    """

    seed: int
    t_s: np.ndarray
    ee_pos_m: np.ndarray
    target_pos_m: np.ndarray
    ref_pos_m: np.ndarray
    q_rad: np.ndarray
    dq_rad_s: np.ndarray
    tau_cmd_nm: np.ndarray
    tick_us: np.ndarray
    safety_mask: np.ndarray | None = None
    chunk_active_s: list[float] = field(default_factory=list)
    plan_ms: list[float] = field(default_factory=list)
    jump_times_s: tuple[float, ...] = ()
    change_times_s: tuple[float, ...] = ()
    delay_steps: list[float] = field(default_factory=list)
    source_timing_ms: dict[str, list[float]] = field(default_factory=dict)
    objects_pos_m: np.ndarray | None = None  # (n, n_objects, 3) when the world has several objects
    target_index: int = 0
    qp_failures: int = 0
    smoother_failures: int = 0
    mpc_failures: int = 0
    clipped_actions: int = 0
    wall_s: float = 0.0
    instruction: str = ""
    frames: list[np.ndarray] = field(default_factory=list)
    safety_counts: dict[str, int] = field(default_factory=dict)
    torque_rate_max_nm_s: float = 0.0
    rejections: dict[str, int] = field(default_factory=dict)
    watchdog_stops: int = 0
    gated_measurements: dict[str, int] = field(default_factory=dict)
    perception_errors: int = 0
    measurements: int = 0
    measurements_lost: int = 0
    sensor_wall_s: float = 0.0
    sensor_stats: dict = field(default_factory=dict)
    missed_ticks: int = 0
    rate_clamps: int = 0
    qp_rescues: int = 0
    plan_resyncs: int = 0
    floor_clamps: int = 0
    mpc_bypass_ticks: int = 0
    abort: dict | None = None
    events: list[tuple[float, str, str]] = field(default_factory=list)

    def truncate(self, n: int) -> None:
        """Keep the first ``n`` samples (an aborted episode)."""
        for name in ("t_s", "ee_pos_m", "target_pos_m", "ref_pos_m", "q_rad", "dq_rad_s", "tau_cmd_nm", "tick_us",
                     "safety_mask", "objects_pos_m"):
            value = getattr(self, name)
            if value is not None:
                setattr(self, name, value[:n])


class CommandLink(Protocol):
    """The link from the controller to the robot: whether the command of tick ``k`` reaches it."""

    def delivered(self, k: int, t_s: float) -> bool:
        ...


def observe(world: World, controller: HybridController, t_s: float, with_image: bool,
            target_prev_pos_m: np.ndarray | None = None, frame_gap_s: float = 0.0,
            prev_image: np.ndarray | None = None) -> Observation:
    """What a chunk source sees at ``t_s``: robot state, the target in this frame (and, when given, in the frame
    ``frame_gap_s`` earlier), pixels if needed."""
    state = world.state()
    ee_pos, ee_rotvec = controller.ee_pose(state.q_rad)
    return Observation(
        t0_s=t_s,
        q_rad=state.q_rad.copy(),
        dq_rad_s=state.dq_rad_s.copy(),
        ee_pos_m=ee_pos,
        ee_rotvec_rad=ee_rotvec,
        gripper_m=state.gripper_m,
        target_pos_m=world.target_pos_m().copy(),
        image=world.render() if with_image else None,
        instruction=world.instruction,
        target_prev_pos_m=None if target_prev_pos_m is None else np.asarray(target_prev_pos_m, dtype=float).copy(),
        frame_gap_s=float(frame_gap_s),
        prev_image=prev_image,
    )


def run_episode(
    world: World,
    source: ChunkSource,
    controller: HybridController,
    seed: int,
    video_fps: float = 0.0,
    progress=None,
    link: CommandLink | None = None,
    initial_dq_rad_s: np.ndarray | None = None,
    sensor: TargetSensor | None = None,
) -> EpisodeLog:
    """Run one episode of ``controller.config.duration_s`` and return its log.

    The loop knows no mode names: when and what to ask the source, and how chunks are executed, is the
    controller's executor (``mmact_ctrl.executors``).

    Nothing a fault does escapes this loop: a chunk source that raises or answers garbage is rejected and
    counted (:class:`~mmact_ctrl.chunk_intake.ChunkIntake`), silence is met by the watchdog's stop, a bad
    measurement is gated by the filter, a missed tick holds the last torque, and every command sent is checked
    by the safety monitor (``controllers.safety``). Only ``abort_after_missed_ticks`` missed ticks in a row end
    the episode early, as they abort the motion of a real Panda.

    Args:
        video_fps: when > 0, render camera frames at this rate into ``EpisodeLog.frames``.
        progress: optional callable(fraction) for progress reporting.
        link: whether each tick's command reaches the robot (None: always).
        initial_dq_rad_s: joint velocities (7,) the robot has at the start (None: at rest).
        sensor: where target measurements come from (``mmact_ctrl.perception``; None: the world's own channel at
            ``config.perception_hz`` with no latency, :class:`~mmact_ctrl.perception.OracleSensor`).
    """
    cfg = controller.config
    dt = cfg.dt_s
    n = int(round(cfg.duration_s / dt))
    executor = controller.executor
    # a mode that needs what the source cannot do is refused before the episode, in one line (never a silent episode)
    require_capabilities(source, getattr(executor, "needs", ()), executor.name)
    state = world.reset(seed)
    if initial_dq_rad_s is not None:
        state = world.set_arm_state(state.q_rad, initial_dq_rad_s)
    tau_start = controller.reset(state.q_rad, state.dq_rad_s)
    monitor = SafetyMonitor(CommandLimits(dt_s=dt))
    monitor.reset(tau_start)
    intake = ChunkIntake(cfg.splice_radius_m, getattr(source, "action_token_range", None))
    latency_s = cfg.latency_ms / 1000.0
    replan_period_s = 1.0 / cfg.replan_hz
    eps = 0.5 * dt

    log = EpisodeLog(
        seed=seed,
        t_s=np.arange(n) * dt,
        ee_pos_m=np.empty((n, 3)),
        target_pos_m=np.empty((n, 3)),
        ref_pos_m=np.empty((n, 3)),
        q_rad=np.empty((n, 7)),
        dq_rad_s=np.empty((n, 7)),
        tau_cmd_nm=np.empty((n, 7)),
        tick_us=np.empty(n),
        safety_mask=np.zeros(n, dtype=np.uint16),
        instruction=world.instruction,
    )
    objects_fn = getattr(world, "objects_pos_m", None)  # optional part of the world: distractors
    n_objects = len(objects_fn()) if objects_fn is not None else 1
    if n_objects > 1:
        log.objects_pos_m = np.empty((n, n_objects, 3))
        log.target_index = int(getattr(world, "target_index", 0))
    next_plan_s = 0.0
    last_arrival_s = 0.0  # the watchdog's clock: the last valid chunk (or the start)
    source_reset = getattr(source, "reset", None)
    if callable(source_reset):  # a new episode for the source (a LeRobot policy clears its action queue)
        try:
            source_reset()
        except Exception as exc:  # noqa: BLE001 - a source fault: counted, the episode runs (its chunks may be refused)
            log.events.append((0.0, "source_reset_raised", f"{type(exc).__name__}: {exc}"[:200]))
    gap_ticks = int(round(FRAME_GAP_S / dt))
    frame_every = int(round(1.0 / (video_fps * dt))) if video_fps > 0 else 0
    render_video = getattr(world, "render_video", None)  # optional part of a world: a larger frame for videos
    if sensor is None:
        sensor = OracleSensor(world, cfg.perception_hz, 0.0, dt)
    sensor.reset(seed)
    # a source that sees motion (two frames) gets the frame rendered prev_frame_gap_s before each query
    earlier = EarlierFrame(world.render, float(getattr(source, "prev_frame_gap_s", 0.0) or 0.0), dt)
    missed_in_row = 0
    n_done = n
    wall0 = time.perf_counter()
    for k in range(n):
        t = k * dt
        state = world.state()
        # fuse what has arrived before planning, so a chunk observed now records the estimate of now
        s0 = time.perf_counter()
        try:
            arrived = sensor.poll(t)
        except Exception as exc:  # noqa: BLE001 - a crashed sensor is a lost measurement
            arrived = []
            log.perception_errors += 1
            log.events.append((t, "perception_error", f"{type(exc).__name__}: {exc}"[:200]))
        tick0 = time.perf_counter()
        log.sensor_wall_s += tick0 - s0
        for m in arrived:
            controller.perceive(m.t_capture_s, m.pos_m)
            log.measurements += 1
            log.measurements_lost += m.pos_m is None
        perception_us = (time.perf_counter() - tick0) * 1e6 if arrived else 0.0
        earlier.tick(t, next_plan_s, replan_period_s)
        if t >= next_plan_s - eps:
            if k >= gap_ticks:  # the frame FRAME_GAP_S earlier (the target positions recorded so far)
                prev, gap_s = log.target_pos_m[k - gap_ticks], gap_ticks * dt
            else:  # no earlier frame yet: the first one
                prev, gap_s = (log.target_pos_m[0], k * dt) if k > 0 else (None, 0.0)
            obs = observe(world, controller, t, with_image=source.needs_image, target_prev_pos_m=prev, frame_gap_s=gap_s,
                          prev_image=earlier.take(t) if earlier.gap_s > 0 else None)
            scheduled = intake.pending[-1].chunk if intake.pending else (controller.active.chunk if controller.active else None)
            call = executor.request(source, obs, QueryContext(t_s=t, latency_s=latency_s, scheduled=scheduled))
            p0 = time.perf_counter()
            chunk = intake.request(call, obs)
            log.plan_ms.append((time.perf_counter() - p0) * 1e3)
            if chunk is not None:
                log.clipped_actions += chunk.n_clipped
                for key in SOURCE_TIMING_KEYS:
                    if key in chunk.info:
                        log.source_timing_ms.setdefault(key, []).append(float(chunk.info[key]))
                delay_s = log.plan_ms[-1] / 1e3 if cfg.measured_latency else latency_s
                delay_s = max(delay_s, float(chunk.info.get("arrival_delay_s", 0.0)))  # a source that knows it is late
                intake.submit(t + delay_s, chunk, controller.target_estimate(t), obs.ee_pos_m)
            next_plan_s = executor.after_request(t, chunk, next_plan_s, replan_period_s)
        tick0 = time.perf_counter()
        for entry in intake.due(t + eps):
            gap_m = controller.splice_distance_m(entry.chunk, t, entry.target_at_obs_m, entry.ee_at_obs_m)
            if intake.admit(entry, t, controller.active, gap_m=gap_m):
                controller.activate(entry.chunk, t, entry.target_at_obs_m)
                log.chunk_active_s.append(t)
                log.delay_steps.append((t - entry.chunk.t0_s) / entry.chunk.dt_s)
                last_arrival_s = t
                next_plan_s = executor.after_activation(t, controller.active, next_plan_s)
            else:
                next_plan_s = executor.after_refusal(t, next_plan_s)
        if controller.stop is None and (not controller.covered(t) or t - last_arrival_s > cfg.chunk_timeout_s):
            controller.watchdog(t)
            log.events.append((t, "watchdog_stop", ""))
        if link is None or link.delivered(k, t):
            missed_in_row = 0
            out = controller.tick(t, state.q_rad, state.dq_rad_s)
        else:
            missed_in_row += 1
            log.missed_ticks += 1
            out = controller.missed_tick(state.q_rad, state.dq_rad_s)
        mask = monitor.check(out.tau_nm, state.q_rad, state.dq_rad_s, out.ddq_cmd_rad_s2, out.tcp_vel_m_s)
        tau = out.tau_nm if not mask & NONFINITE else controller.qp.tau_last  # never send a non-finite torque
        log.safety_mask[k] = mask
        log.tick_us[k] = (time.perf_counter() - tick0) * 1e6 + perception_us
        log.ee_pos_m[k] = state.ee_pos_m
        log.target_pos_m[k] = world.target_pos_m()
        if log.objects_pos_m is not None:
            log.objects_pos_m[k] = objects_fn()
        log.ref_pos_m[k] = out.ref_pos_m
        log.q_rad[k] = state.q_rad
        log.dq_rad_s[k] = state.dq_rad_s
        log.tau_cmd_nm[k] = tau
        if missed_in_row >= cfg.abort_after_missed_ticks:
            log.abort = {"t_s": float(t), "reason": "communication_constraints_violation"}
            log.events.append((t, "abort", f"{missed_in_row} missed ticks in a row"))
            n_done = k + 1
            break
        if frame_every and k % frame_every == 0:
            log.frames.append(render_video() if render_video else world.render()[0])
        world.step(tau, out.gripper_m)
        if progress is not None and k % 500 == 0:
            progress(k / n)
    log.wall_s = time.perf_counter() - wall0
    if n_done < n:
        log.truncate(n_done)
    log.qp_failures = controller.qp.failures
    log.rate_clamps = controller.qp.rate_clamps
    log.qp_rescues = controller.qp.rescues
    log.smoother_failures = controller.smoother.failures
    if controller.mpc is not None:
        log.mpc_failures = controller.mpc.failures + controller.mpc.late
    log.plan_resyncs = controller.plan_resyncs
    log.floor_clamps = controller.floor_clamps
    log.mpc_bypass_ticks = controller.mpc_bypass_ticks
    log.safety_counts = monitor.counts
    log.torque_rate_max_nm_s = monitor.torque_rate_max_nm_s
    log.rejections = dict(intake.rejections)
    log.events = sorted(log.events + intake.events)
    log.watchdog_stops = controller.watchdog_stops
    f = controller.filter
    log.gated_measurements = {"nonfinite": f.gated_nonfinite, "frozen": f.gated_frozen, "outlier": f.gated_outlier}
    log.sensor_stats = dict(getattr(sensor, "stats", {}))
    log.jump_times_s = tuple(t for t in world.target_jump_times_s() if t <= cfg.duration_s)
    changes_fn = getattr(world, "target_change_times_s", None)  # a world without it: the jumps are the changes
    changes = changes_fn() if changes_fn is not None else log.jump_times_s
    log.change_times_s = tuple(t for t in changes if t <= cfg.duration_s)
    return log
