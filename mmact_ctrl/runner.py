"""The multi-rate loop as an object that can be advanced: physics and control at 1 kHz, perception at its rate, the
chunk source on the executor's clock.

:class:`EpisodeRunner` runs one episode tick by tick. ``advance(until_s)`` runs the ticks before ``until_s``;
``run_episode`` (``mmact_ctrl.loop``) is ``advance`` to the end, the Gymnasium environment (``scenarios``) advances
from one query of its agent to the next, and the real-time mode paces ``advance`` to the wall clock. Nothing of the
loop is written twice.

The observation is taken at ``t0``; the chunk it produces becomes active at ``t0 + latency`` while the previous
chunk keeps running. Waypoints already in the past when a chunk arrives are skipped (the reference is indexed by
absolute time). The loop knows no mode names: when and what to ask the source, and how chunks are executed, is the
controller's executor (``mmact_ctrl.executors``).

Nothing a fault does escapes the loop: a chunk source that raises or answers garbage is rejected and counted
(:class:`~mmact_ctrl.chunk_intake.ChunkIntake`), silence is met by the watchdog's stop, a bad measurement is gated
by the filter, a missed tick holds the last torque, and every command sent is checked by the safety monitor
(``controllers.safety``). Only ``abort_after_missed_ticks`` missed ticks in a row end the episode early, as they
abort the motion of a real Panda.
"""

from __future__ import annotations

import math
import time

import numpy as np

from controllers.safety import NONFINITE, CommandLimits, SafetyMonitor
from mmact_ctrl.chunk import ActionChunk, ChunkSource, Observation
from mmact_ctrl.chunk_intake import ChunkIntake
from mmact_ctrl.controller import HybridController
from mmact_ctrl.episode_log import CommandLink, EpisodeLog
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


def _finite(value) -> float | None:
    """``value`` as a float if it is a finite real number, else None."""
    if isinstance(value, (int, float, np.floating, np.integer)) and not isinstance(value, bool):
        value = float(value)
        return value if math.isfinite(value) else None
    return None


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


class EpisodeRunner:
    """One episode of ``controller.config.duration_s``, advanced in steps.

    Args:
        world, source, controller: the world, the chunk source, the control layer (its executor says how chunks run).
        seed: the episode's seed (target motion, noise).
        video_fps: when > 0, render camera frames at this rate into ``EpisodeLog.frames``.
        progress: optional callable(fraction) for progress reporting.
        link: whether each tick's command reaches the robot (None: always).
        initial_dq_rad_s: joint velocities (7,) the robot has at the start (None: at rest).
        sensor: where target measurements come from (``mmact_ctrl.perception``; None: the world's own channel at
            ``config.perception_hz`` with no latency, :class:`~mmact_ctrl.perception.OracleSensor`).
        pause_at_queries: when True, :meth:`advance` stops at each query that falls due, before the source is
            called (:attr:`pending_query` holds its observation); the next :meth:`advance` calls the source and goes
            on. An agent that answers from outside (the Gymnasium environment) sets the answer in between.
        async_queries: real time: a :class:`~mmact_ctrl.realtime.async_source.AsyncQueries` that asks the source in
            a worker while the ticks go on (one query in flight; the observation's frames are rendered there from a
            snapshot of the world, ``world.snapshot()``); each chunk is accepted on the tick it arrives and shapes
            the commands from the next one: its latency is what it took.
        deadline: real time: an object whose ``missed(k)`` says, once tick ``k``'s command is computed, whether it
            is ready too late for its cycle; such a command never reaches the robot (it re-applies the last torque:
            counted in ``missed_ticks`` and ``late_commands``, and 20 in a row abort as on the robot). With a
            deadline, only what the command needs runs before it (the state, the controller's tick, the safety
            check); the rest of the tick's work runs once it is out (:meth:`_after_command`: fusing the measurements
            that arrived, admitting the chunks due by the next tick, the MPC's update). Simulated time keeps the old
            order (its results are unchanged) and records the same work apart (``EpisodeLog.after_us``), so
            ``tick_us`` is the command path as real time runs it in both.
        record: also keep what a recording shows (``EpisodeLog.recording``: the target estimate at 100 Hz, each
            activated chunk's waypoints, each MPC plan's TCP preview, the frames each query was answered from).

    The episode starts at construction (``world.reset(seed)``); a mode that needs what the source cannot do
    (``ChunkExecutor.needs``) is refused here, in one line, before any tick.
    """

    def __init__(self, world: World, source: ChunkSource, controller: HybridController, seed: int,
                 video_fps: float = 0.0, progress=None, link: CommandLink | None = None,
                 initial_dq_rad_s: np.ndarray | None = None, sensor: TargetSensor | None = None,
                 pause_at_queries: bool = False, async_queries=None, deadline=None, record: bool = False) -> None:
        cfg = controller.config
        self.world, self.source, self.controller, self.config = world, source, controller, cfg
        self.executor = executor = controller.executor
        # a mode that needs what the source cannot do is refused before the episode, in one line
        require_capabilities(source, getattr(executor, "needs", ()), executor.name)
        self.dt_s = dt = cfg.dt_s
        self.n_ticks = n = int(round(cfg.duration_s / dt))
        self.link, self.progress, self.pause_at_queries = link, progress, bool(pause_at_queries)
        self.async_queries, self.deadline = async_queries, deadline
        if async_queries is not None and pause_at_queries:
            raise ValueError("pause_at_queries and async_queries exclude each other")
        self._inflight: tuple[float, float] | None = None  # async: (query time, next query time it replaced)
        state = world.reset(seed)
        if initial_dq_rad_s is not None:
            state = world.set_arm_state(state.q_rad, initial_dq_rad_s)
        tau_start = controller.reset(state.q_rad, state.dq_rad_s)
        self.monitor = SafetyMonitor(CommandLimits(dt_s=dt))
        self.monitor.reset(tau_start)
        self.intake = ChunkIntake(cfg.splice_radius_m, getattr(source, "action_token_range", None))
        self.latency_s = cfg.latency_ms / 1000.0
        self.replan_period_s = 1.0 / cfg.replan_hz
        self._eps = 0.5 * dt
        self.log = log = EpisodeLog(
            seed=seed,
            t_s=np.arange(n) * dt,
            ee_pos_m=np.empty((n, 3)),
            target_pos_m=np.empty((n, 3)),
            ref_pos_m=np.empty((n, 3)),
            q_rad=np.empty((n, 7)),
            dq_rad_s=np.empty((n, 7)),
            tau_cmd_nm=np.empty((n, 7)),
            tick_us=np.empty(n),
            after_us=np.zeros(n),
            safety_mask=np.zeros(n, dtype=np.uint16),
            instruction=world.instruction,
        )
        self._objects_fn = getattr(world, "objects_pos_m", None)  # optional part of the world: distractors
        n_objects = len(self._objects_fn()) if self._objects_fn is not None else 1
        if n_objects > 1:
            log.objects_pos_m = np.empty((n, n_objects, 3))
            log.target_index = int(getattr(world, "target_index", 0))
        self.next_plan_s = 0.0
        self.last_arrival_s = 0.0  # the watchdog's clock: the last valid chunk (or the start)
        source_reset = getattr(source, "reset", None)
        if callable(source_reset):  # a new episode for the source (a LeRobot policy clears its action queue)
            try:
                source_reset()
            except Exception as exc:  # noqa: BLE001 - a source fault: counted, the episode runs
                log.events.append((0.0, "source_reset_raised", f"{type(exc).__name__}: {exc}"[:200]))
        self._gap_ticks = int(round(FRAME_GAP_S / dt))
        self._frame_every = int(round(1.0 / (video_fps * dt))) if video_fps > 0 else 0
        self._render_video = getattr(world, "render_video", None)  # optional part of a world: a larger frame
        if sensor is None:
            sensor = OracleSensor(world, cfg.perception_hz, 0.0, dt)
        sensor.reset(seed)
        self.sensor = sensor
        # a source that sees motion (two frames) gets the frame rendered prev_frame_gap_s before each query (in real
        # time a snapshot of the world then, rendered with the query's off the 1 kHz path)
        grab = world.snapshot if async_queries is not None else world.render
        self.earlier = EarlierFrame(grab, float(getattr(source, "prev_frame_gap_s", 0.0) or 0.0), dt)
        self.missed_in_row = 0
        self.k = 0  # the next tick
        self.aborted = False
        self.pending_query: Observation | None = None
        self._resume = False  # the tick k stopped at its query: resume there
        self._state = None
        self._after_us = 0.0  # this tick's work that real time does after the command (fusion, the MPC update), us
        self._deferred_measurements: list = []  # real time: arrived this tick, fused once the command is out
        self._wall_s = 0.0
        self._finished: EpisodeLog | None = None
        self.record = bool(record)
        if self.record:
            log.recording = {"estimate": [], "chunks": [], "frames": [], "mpc": []}
        controller.recorded_plans = log.recording["mpc"] if self.record else None
        self._est_every = max(1, int(round(0.01 / dt)))

    # ---- where the episode stands ---------------------------------------------------------------
    @property
    def t_s(self) -> float:
        """Time of the next tick, s."""
        return self.k * self.dt_s

    @property
    def done(self) -> bool:
        """Whether the episode is over (its duration reached, or aborted)."""
        return self.aborted or self.k >= self.n_ticks

    # ---- running -------------------------------------------------------------------------------------
    def advance(self, until_s: float = math.inf) -> None:
        """Run the ticks at times before ``until_s`` (all of them: ``inf``), or until the episode ends, or (with
        ``pause_at_queries``) until a query falls due: then :attr:`pending_query` is set and the tick waits there."""
        wall0 = time.perf_counter()
        try:
            limit = until_s - 1e-9 * self.dt_s
            while not self.done:
                if self._resume:
                    self._resume = False
                    self._query(self.pending_query)
                    self.pending_query = None
                    self._finish_tick()
                    continue
                if self.k * self.dt_s >= limit:
                    break
                if self._begin_tick():  # paused at a due query
                    return
                self._finish_tick()
        finally:
            self._wall_s += time.perf_counter() - wall0

    def _begin_tick(self) -> bool:
        """The first part of tick ``k``: measurements, and the query when one is due; True when it pauses there."""
        k, log, t = self.k, self.log, self.k * self.dt_s
        self._state = self.world.state()
        s0 = time.perf_counter()
        try:
            arrived = self.sensor.poll(t)
        except Exception as exc:  # noqa: BLE001 - a crashed sensor is a lost measurement
            arrived = []
            log.perception_errors += 1
            log.events.append((t, "perception_error", f"{type(exc).__name__}: {exc}"[:200]))
        tick0 = time.perf_counter()
        log.sensor_wall_s += tick0 - s0
        self._after_us = 0.0
        if arrived:
            if self.deadline is None:
                # simulated time fuses here, before the command (results as they always were); real time fuses after
                # the command (:meth:`_after_command`), so this time is kept off the command path's and recorded apart
                self._fuse(arrived)
                self._after_us = (time.perf_counter() - tick0) * 1e6
            else:
                self._deferred_measurements.extend(arrived)
        if self.async_queries is not None:
            self._collect(t)
        self.earlier.tick(t, self.next_plan_s, self.replan_period_s)
        query_due = t >= self.next_plan_s - self._eps
        if query_due:
            if self.async_queries is not None:
                self._ask(k, t)
                return False
            obs = self._observe(k, t)
            if self.pause_at_queries:
                self.pending_query = obs
                self._resume = True
                return True
            self._query(obs)
        return False

    def _fuse(self, arrived: list) -> None:
        """Fuse the measurements that have arrived into the controller's target estimate."""
        log = self.log
        for m in arrived:
            self.controller.perceive(m.t_capture_s, m.pos_m)
            log.measurements += 1
            log.measurements_lost += m.pos_m is None

    def _after_command(self, t: float) -> float:
        """Real time, once the command of the tick at ``t`` is out: fuse what arrived at this tick, admit the chunks
        due by the next tick (active from it: the command they first shape is the next one), then the controller's
        MPC update (its reference and problem, handed to the MPC process). Returns the time it took, us (simulated
        time does the first two before the command: 0 here)."""
        if self.deadline is None:
            return self.controller.end_tick()
        a0 = time.perf_counter()
        # a tick that built an observation for the source has had its share of work: its measurements wait a tick
        # (the filter fuses each at its capture time, so only when the estimate has them moves, by 1 ms)
        asked_now = self._inflight is not None and self._inflight[0] == t  # this tick handed the worker a query
        if self._deferred_measurements and not asked_now:
            arrived, self._deferred_measurements = self._deferred_measurements, []
            self._fuse(arrived)
        admitted = self._admit_due(t + self.dt_s)
        # a tick that admitted a chunk has had its share of work: the MPC's next stage waits a tick
        return (time.perf_counter() - a0) * 1e6 + self.controller.end_tick(spare=admitted == 0)

    def _admit_due(self, t: float) -> int:
        """Admit the chunks due by ``t`` (the splice check against the reference at ``t``) and activate them at
        ``t``; returns how many were due (admitted or refused)."""
        log, controller, executor = self.log, self.controller, self.executor
        due = self.intake.due(t + self._eps)
        for entry in due:
            gap_m = controller.splice_distance_m(entry.chunk, t, entry.target_at_obs_m, entry.ee_at_obs_m)
            if self.intake.admit(entry, t, controller.active, gap_m=gap_m):
                controller.activate(entry.chunk, t, entry.target_at_obs_m)
                log.chunk_active_s.append(t)
                if self.record:
                    log.recording["chunks"].append((t, entry.chunk.times_s.copy(), entry.chunk.waypoints.copy()))
                log.delay_steps.append((t - entry.chunk.t0_s) / entry.chunk.dt_s)
                self.last_arrival_s = t
                self.next_plan_s = executor.after_activation(t, controller.active, self.next_plan_s)
            else:
                self.next_plan_s = executor.after_refusal(t, self.next_plan_s)
        return len(due)

    def _observe(self, k: int, t: float) -> Observation:
        log, gap = self.log, self._gap_ticks
        if k >= gap:  # the frame FRAME_GAP_S earlier (the target positions recorded so far)
            prev, gap_s = log.target_pos_m[k - gap], gap * self.dt_s
        else:  # no earlier frame yet: the first one
            prev, gap_s = (log.target_pos_m[0], k * self.dt_s) if k > 0 else (None, 0.0)
        return observe(self.world, self.controller, t, with_image=self.source.needs_image, target_prev_pos_m=prev,
                       frame_gap_s=gap_s, prev_image=self.earlier.take(t) if self.earlier.gap_s > 0 else None)

    def _ask(self, k: int, t: float) -> None:
        """Real time: hand the query to the worker (its frames rendered there); no other query until it answers."""
        aq = self.async_queries
        log, gap = self.log, self._gap_ticks
        if k >= gap:
            prev, gap_s = log.target_pos_m[k - gap], gap * self.dt_s
        else:
            prev, gap_s = (log.target_pos_m[0], k * self.dt_s) if k > 0 else (None, 0.0)
        obs = observe(self.world, self.controller, t, with_image=False, target_prev_pos_m=prev, frame_gap_s=gap_s)
        snaps = None
        if self.source.needs_image:
            snaps = (self.world.snapshot(), self.earlier.take(t) if self.earlier.gap_s > 0 else None)
        intake, controller = self.intake, self.controller
        scheduled = intake.pending[-1].chunk if intake.pending else (controller.active.chunk if controller.active else None)
        # the latency is what answers have taken, not the configured one (which does not apply in real time)
        ctx = QueryContext(t_s=t, latency_s=aq.latency_estimate_s(self.latency_s), scheduled=scheduled)
        executor, source = self.executor, self.source
        aq.submit(lambda o: executor.request(source, o, ctx), obs, snaps)
        self._inflight = (t, self.next_plan_s)
        self.next_plan_s = math.inf

    def _collect(self, t: float) -> None:
        """Real time: take the worker's answer if it has come; its chunk is checked and active at once."""
        answer = self.async_queries.poll()
        if answer is None:
            return
        t_query, next_before = self._inflight
        self._inflight = None
        obs = answer.observation
        chunk = self.intake.request(answer.result, obs)
        self.log.plan_ms.append(answer.round_trip_s * 1e3)
        if self.record and obs.image is not None:
            self.log.recording["frames"].append((obs.t0_s, obs.image))
        if chunk is not None:
            self.accept(chunk, obs, t - obs.t0_s)
        self.next_plan_s = self.executor.after_request(t_query, chunk, next_before, self.replan_period_s)

    def _query(self, obs: Observation) -> None:
        """Ask the source (through the executor and the intake) and queue what it answers."""
        t, log, intake, controller = obs.t0_s, self.log, self.intake, self.controller
        scheduled = intake.pending[-1].chunk if intake.pending else (controller.active.chunk if controller.active else None)
        ctx = QueryContext(t_s=t, latency_s=self.latency_s, scheduled=scheduled)
        executor, source = self.executor, self.source
        p0 = time.perf_counter()
        # the request is built inside the intake's guard too: what it reads of the source (its chunk_dt_s for an
        # inpainting prefix) is the source's, and may be wrong
        chunk = intake.request(lambda: executor.request(source, obs, ctx)(), obs)
        log.plan_ms.append((time.perf_counter() - p0) * 1e3)
        if self.record and obs.image is not None:
            log.recording["frames"].append((t, obs.image))
        if chunk is not None:
            delay_s = log.plan_ms[-1] / 1e3 if self.config.measured_latency else self.latency_s
            self.accept(chunk, obs, delay_s)
        self.next_plan_s = self.executor.after_request(t, chunk, self.next_plan_s, self.replan_period_s)

    def accept(self, chunk: ActionChunk, obs: Observation, delay_s: float) -> None:
        """Queue a valid ``chunk`` (answered to ``obs``) to become active ``delay_s`` after its observation (or later,
        when the source says it is late: ``info["arrival_delay_s"]``)."""
        log = self.log
        n_clipped = chunk.n_clipped
        log.clipped_actions += int(n_clipped) if isinstance(n_clipped, (int, np.integer)) and n_clipped > 0 else 0
        info = chunk.info if isinstance(chunk.info, dict) else {}  # a source's own notes: never trusted to be well formed
        for key in SOURCE_TIMING_KEYS:  # what the source says of its timing: numbers only (a server may say None)
            value = _finite(info.get(key))
            if value is not None:
                log.source_timing_ms.setdefault(key, []).append(value)
        delay_s = max(delay_s, _finite(info.get("arrival_delay_s")) or 0.0)  # a source that knows it is late
        self.intake.submit(obs.t0_s + delay_s, chunk, self.controller.target_estimate(obs.t0_s), obs.ee_pos_m)

    def _finish_tick(self) -> None:
        """The rest of tick ``k``: due chunks, the watchdog, the command and its check, the log, the physics step."""
        k, log, controller, executor, cfg = self.k, self.log, self.controller, self.executor, self.config
        t = k * self.dt_s
        state = self._state
        tick0 = time.perf_counter()
        if self.deadline is None:  # simulated time admits at the tick; real time once the command is out
            a0 = time.perf_counter()
            self._admit_due(t)
            admit_us = (time.perf_counter() - a0) * 1e6
            tick0 += admit_us * 1e-6  # kept off the command path's time as real time runs it, recorded in after_us
            self._after_us += admit_us
        if controller.stop is None and (not controller.covered(t) or t - self.last_arrival_s > cfg.chunk_timeout_s):
            controller.watchdog(t)
            log.events.append((t, "watchdog_stop", ""))
        if self.link is None or self.link.delivered(k, t):
            before = controller.command_state() if self.deadline is not None else None
            out = controller.tick(t, state.q_rad, state.dq_rad_s)
            if before is not None and self.deadline.missed(k):  # ready after its cycle: the robot never got it
                out = controller.late_tick(before, out)
                self.missed_in_row += 1
                log.missed_ticks += 1
                log.late_commands += 1
            else:
                self.missed_in_row = 0
        else:
            self.missed_in_row += 1
            log.missed_ticks += 1
            out = controller.missed_tick(state.q_rad, state.dq_rad_s)
        mask = self.monitor.check(out.tau_nm, state.q_rad, state.dq_rad_s, out.ddq_cmd_rad_s2, out.tcp_vel_m_s)
        tau = out.tau_nm if not mask & NONFINITE else controller.qp.tau_last  # never send a non-finite torque
        log.safety_mask[k] = mask
        # the 1 kHz path's time: what runs beside it on a robot (an inline MPC solve) is recorded apart
        # the command path (state -> checked command) as real time runs it: the MPC update and the fusion, which real
        # time does after the command, are recorded in after_us (the MPC solve, in its own process, in mpc_solve_us)
        log.tick_us[k] = (time.perf_counter() - tick0) * 1e6 - controller.offpath_us
        self._after_us += controller.after_us
        log.ee_pos_m[k] = state.ee_pos_m
        log.target_pos_m[k] = self.world.target_pos_m()
        if log.objects_pos_m is not None:
            log.objects_pos_m[k] = self._objects_fn()
        log.ref_pos_m[k] = out.ref_pos_m
        log.q_rad[k] = state.q_rad
        log.dq_rad_s[k] = state.dq_rad_s
        log.tau_cmd_nm[k] = tau
        if self.record and k % self._est_every == 0:
            est = controller.target_estimate(t)
            if est is not None:
                log.recording["estimate"].append((t, np.array(est, dtype=float)))
        self.k = k + 1
        if self.missed_in_row >= cfg.abort_after_missed_ticks:
            log.abort = {"t_s": float(t), "reason": "communication_constraints_violation"}
            log.events.append((t, "abort", f"{self.missed_in_row} missed ticks in a row"))
            self.aborted = True
            return
        if self._frame_every and k % self._frame_every == 0:
            log.frames.append(self._render_video() if self._render_video else self.world.render()[0])
        self.world.step(tau, out.gripper_m)
        log.after_us[k] = self._after_us + self._after_command(t)
        if self.progress is not None and k % 500 == 0:
            self.progress(k / self.n_ticks)

    # ---- the log ---------------------------------------------------------------------------------------
    def finish(self) -> EpisodeLog:
        """The episode's log with every counter filled in (the ticks run so far; call once the episode is done)."""
        if self._finished is not None:
            return self._finished
        log, controller, cfg, world = self.log, self.controller, self.config, self.world
        log.wall_s = self._wall_s
        if self.k < self.n_ticks:
            log.truncate(self.k)
        log.qp_failures = controller.qp.failures
        log.rate_clamps = controller.qp.rate_clamps
        log.qp_rescues = controller.qp.rescues
        log.smoother_failures = controller.smoother.failures
        if controller.mpc is not None:
            worker = controller.mpc_worker
            log.mpc_failures = int(worker.failures + worker.late)
            log.mpc_solve_us = list(getattr(worker, "solve_us", []))
        log.plan_resyncs = controller.plan_resyncs
        log.floor_clamps = controller.floor_clamps
        log.mpc_bypass_ticks = controller.mpc_bypass_ticks
        log.safety_counts = self.monitor.counts
        log.torque_rate_max_nm_s = self.monitor.torque_rate_max_nm_s
        log.rejections = dict(self.intake.rejections)
        log.source_errors = [dict(e) for e in self.intake.source_errors]
        log.events = sorted(log.events + self.intake.events)
        log.watchdog_stops = controller.watchdog_stops
        f = controller.filter
        log.gated_measurements = {"nonfinite": f.gated_nonfinite, "frozen": f.gated_frozen, "outlier": f.gated_outlier}
        log.sensor_stats = dict(getattr(self.sensor, "stats", {}))
        log.jump_times_s = tuple(t for t in world.target_jump_times_s() if t <= cfg.duration_s)
        changes_fn = getattr(world, "target_change_times_s", None)  # a world without it: the jumps are the changes
        changes = changes_fn() if changes_fn is not None else log.jump_times_s
        log.change_times_s = tuple(t for t in changes if t <= cfg.duration_s)
        self._finished = log
        return log
