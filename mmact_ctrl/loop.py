"""The multi-rate loop: physics and control at 1 kHz, perception at 100 Hz, the chunk source at ``replan_hz``.

The observation is taken at ``t0``; the chunk it produces becomes active at ``t0 + latency``
while the previous chunk keeps running. Waypoints already in the past when a chunk arrives
are skipped (the reference is indexed by absolute time).
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from mmact_ctrl.chunk import ActionChunk, ChunkSource, Observation
from mmact_ctrl.controller import HybridController
from mmact_ctrl.reference import ChunkReference
from mmact_ctrl.world import World


@dataclass
class EpisodeLog:
    """Everything recorded in one episode (arrays sampled every control period)."""

    seed: int
    t_s: np.ndarray
    ee_pos_m: np.ndarray
    target_pos_m: np.ndarray
    ref_pos_m: np.ndarray
    q_rad: np.ndarray
    dq_rad_s: np.ndarray
    tau_cmd_nm: np.ndarray
    tick_us: np.ndarray
    chunk_active_s: list[float] = field(default_factory=list)
    plan_ms: list[float] = field(default_factory=list)
    jump_times_s: tuple[float, ...] = ()
    objects_pos_m: np.ndarray | None = None  # (n, n_objects, 3) when the world has several objects
    target_index: int = 0
    qp_failures: int = 0
    smoother_failures: int = 0
    mpc_failures: int = 0
    clipped_actions: int = 0
    wall_s: float = 0.0
    instruction: str = ""
    frames: list[np.ndarray] = field(default_factory=list)


def observe(world: World, controller: HybridController, t_s: float, with_image: bool) -> Observation:
    """What a chunk source sees at ``t_s``: robot state, one frame's worth of target, pixels if needed."""
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
    )


def receding_k(cfg, chunk: ActionChunk) -> int:
    """Waypoints a receding-horizon executor runs per chunk."""
    if cfg.receding_k:
        return min(cfg.receding_k, chunk.horizon)
    return int(min(chunk.horizon, max(1, round(1.0 / (cfg.replan_hz * chunk.dt_s)))))


def known_prefix(controller: HybridController, pending, t_s: float, latency_s: float, source) -> np.ndarray:
    """Inpainting: the waypoints (n, 7) that will run while the next chunk is computed, taken from the
    chunk that will be executing then (the last one scheduled), at the new chunk's waypoint times."""
    scheduled = pending[-1][1] if pending else (controller.active.chunk if controller.active else None)
    if scheduled is None:
        return np.zeros((0, 7))
    dt = getattr(source, "chunk_dt_s", scheduled.dt_s)
    n_known = int(np.ceil(latency_s / dt - 1e-9))
    ref = ChunkReference(chunk=scheduled, t_active_s=t_s, target_at_obs_m=None)
    return np.array([ref.sample(t_s + (i + 1) * dt)[0] for i in range(n_known)]).reshape(n_known, 7)


def run_episode(
    world: World,
    source: ChunkSource,
    controller: HybridController,
    seed: int,
    video_fps: float = 0.0,
    progress=None,
) -> EpisodeLog:
    """Run one episode of ``controller.config.duration_s`` and return its log.

    Args:
        video_fps: when > 0, render camera frames at this rate into ``EpisodeLog.frames``.
        progress: optional callable(fraction) for progress reporting.
    """
    cfg = controller.config
    dt = cfg.dt_s
    n = int(round(cfg.duration_s / dt))
    state = world.reset(seed)
    controller.reset(state.q_rad)
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
        instruction=world.instruction,
    )
    objects_fn = getattr(world, "objects_pos_m", None)  # optional part of the world: distractors
    n_objects = len(objects_fn()) if objects_fn is not None else 1
    if n_objects > 1:
        log.objects_pos_m = np.empty((n, n_objects, 3))
        log.target_index = int(getattr(world, "target_index", 0))
    pending: deque[tuple[float, ActionChunk, np.ndarray | None]] = deque()
    next_plan_s = 0.0
    mode = cfg.mode
    frame_every = int(round(1.0 / (video_fps * dt))) if video_fps > 0 else 0
    render_video = getattr(world, "render_video", None)  # optional part of a world: a larger frame for videos
    perception_every = cfg.perception_every
    wall0 = time.perf_counter()
    for k in range(n):
        t = k * dt
        state = world.state()
        perceive = k % perception_every == 0
        z = world.measure_target() if perceive else None
        if perceive:  # fuse before planning so a chunk observed now records the estimate of now
            tick0 = time.perf_counter()
            controller.perceive(t, z)
            perception_us = (time.perf_counter() - tick0) * 1e6
        else:
            perception_us = 0.0
        if t >= next_plan_s - eps:
            obs = observe(world, controller, t, with_image=source.needs_image)
            p0 = time.perf_counter()
            if mode == "inpaint":
                chunk = source.plan_inpaint(obs, known_prefix(controller, pending, t, latency_s, source))
            else:
                chunk = source.plan(obs)
            log.plan_ms.append((time.perf_counter() - p0) * 1e3)
            log.clipped_actions += chunk.n_clipped
            delay_s = log.plan_ms[-1] / 1e3 if cfg.measured_latency else latency_s
            pending.append((t + delay_s, chunk, controller.target_estimate()))
            if mode == "receding":  # the next query is set when this chunk starts running
                next_plan_s = float("inf")
            else:
                next_plan_s += replan_period_s
        tick0 = time.perf_counter()
        while pending and pending[0][0] <= t + eps:
            t_act, chunk, target_at_obs = pending.popleft()
            controller.activate(chunk, t, target_at_obs)
            log.chunk_active_s.append(t)
            if mode == "receding":  # query again once k waypoints of this chunk have run
                next_plan_s = t + receding_k(cfg, chunk) * chunk.dt_s
        out = controller.tick(t, state.q_rad, state.dq_rad_s)
        log.tick_us[k] = (time.perf_counter() - tick0) * 1e6 + perception_us
        log.ee_pos_m[k] = state.ee_pos_m
        log.target_pos_m[k] = world.target_pos_m()
        if log.objects_pos_m is not None:
            log.objects_pos_m[k] = objects_fn()
        log.ref_pos_m[k] = out.ref_pos_m
        log.q_rad[k] = state.q_rad
        log.dq_rad_s[k] = state.dq_rad_s
        log.tau_cmd_nm[k] = out.tau_nm
        if frame_every and k % frame_every == 0:
            log.frames.append(render_video() if render_video else world.render()[0])
        world.step(out.tau_nm, out.gripper_m)
        if progress is not None and k % 500 == 0:
            progress(k / n)
    log.wall_s = time.perf_counter() - wall0
    log.qp_failures = controller.qp.failures
    log.smoother_failures = controller.smoother.failures
    if controller.mpc is not None:
        log.mpc_failures = controller.mpc.failures + controller.mpc.late
    log.jump_times_s = tuple(t for t in world.target_jump_times_s() if t <= cfg.duration_s)
    return log
