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

from controllers.contact_safety import CONTACT_FORCE, ContactForceMonitor
from controllers.safety import NONFINITE, CommandLimits, SafetyMonitor
from mmact_ctrl.chunk import ChunkSource, Observation
from mmact_ctrl.chunk_intake import ChunkIntake
from mmact_ctrl.controller import HybridController
from mmact_ctrl.episode_log import CommandLink, EpisodeLog
from mmact_ctrl.frame_history import EarlierFrame
from mmact_ctrl.lookahead import AheadQuery, LookaheadWorker, can_look_ahead
from mmact_ctrl.perception import OracleSensor, TargetSensor
from mmact_ctrl.runner_queries import FRAME_GAP_S, SOURCE_TIMING_KEYS, SourceQueries, observe
from mmact_ctrl.sources.contract import require_capabilities
from mmact_ctrl.sources.spec import SourceSpec
from mmact_ctrl.tick_order import make_order
from mmact_ctrl.world import World

__all__ = ["FRAME_GAP_S", "SOURCE_TIMING_KEYS", "EpisodeRunner", "observe"]


class EpisodeRunner(SourceQueries):
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
            check); the rest of the tick's work runs once it is out (fusing the measurements that arrived, admitting
            the chunks due by the next tick, the MPC's update): ``mmact_ctrl.tick_order.DeadlineOrder``. Without,
            simulated time's order (``SimulatedOrder``: its results are unchanged) records the same work apart
            (``EpisodeLog.after_us``), so ``tick_us`` is the command path as real time runs it in both.
        record: also keep what a recording shows (``EpisodeLog.recording``: the target estimate at 100 Hz, each
            activated chunk's waypoints, each MPC plan's TCP preview, the frames each query was answered from).
        lookahead: simulated time: let the source's call run in a worker until its chunk is due, where nothing can
            tell the difference (``mmact_ctrl.lookahead``; results unchanged bit for bit). False: always in line.

    The episode starts at construction (``world.reset(seed)``); a mode that needs what the source cannot do
    (``ChunkExecutor.needs``) is refused here, in one line, before any tick.
    """

    def __init__(self, world: World, source: ChunkSource, controller: HybridController, seed: int,
                 video_fps: float = 0.0, progress=None, link: CommandLink | None = None,
                 initial_dq_rad_s: np.ndarray | None = None, sensor: TargetSensor | None = None,
                 pause_at_queries: bool = False, async_queries=None, deadline=None, record: bool = False,
                 lookahead: bool = True) -> None:
        cfg = controller.config
        self.world, self.source, self.controller, self.config = world, source, controller, cfg
        self.spec = SourceSpec.of(source)  # what the source declares, read once
        self.executor = executor = controller.executor
        # a mode that needs what the source cannot do is refused before the episode, in one line
        require_capabilities(source, getattr(executor, "needs", ()), executor.name)
        self.dt_s = dt = cfg.dt_s
        self.n_ticks = int(round(cfg.duration_s / dt))
        self.link, self.progress, self.pause_at_queries = link, progress, bool(pause_at_queries)
        self.async_queries, self.deadline = async_queries, deadline
        if async_queries is not None and pause_at_queries:
            raise ValueError("pause_at_queries and async_queries exclude each other")
        self.order = make_order(deadline)
        controller.defer_mpc_updates(self.order.defers_mpc)
        self._inflight: tuple[float, float] | None = None  # async: (query time, next query time it replaced)
        # simulated time: the source's call runs ahead in a worker where nothing can tell (``mmact_ctrl.lookahead``)
        ahead = lookahead and async_queries is None and can_look_ahead(
            self.spec.answers_concurrently, cfg.latency_ms / 1000.0, 1.0 / cfg.replan_hz, self.spec.prev_frame_gap_s,
            dt, cfg.measured_latency, self.pause_at_queries)
        self.lookahead = LookaheadWorker() if ahead else None
        self._ahead: AheadQuery | None = None
        state = world.reset(seed)
        if initial_dq_rad_s is not None:
            state = world.set_arm_state(state.q_rad, initial_dq_rad_s)
        tau_start = controller.reset(state.q_rad, state.dq_rad_s, state.gripper_hold_m())
        self.monitor = SafetyMonitor(CommandLimits(dt_s=dt))
        self.monitor.reset(tau_start)
        self.contact = ContactForceMonitor(cfg.contact_force_limit_n)
        self.intake = ChunkIntake(cfg.splice_radius_m, self.spec.action_token_range)
        self.latency_s = cfg.latency_ms / 1000.0
        self.replan_period_s = 1.0 / cfg.replan_hz
        self._eps = 0.5 * dt
        self.log = self._new_log(seed)
        self.next_plan_s = 0.0
        self.last_arrival_s = 0.0  # the watchdog's clock: the last valid chunk (or the start)
        self._reset_source()
        self._gap_ticks = int(round(FRAME_GAP_S / dt))
        self._frame_every = int(round(1.0 / (video_fps * dt))) if video_fps > 0 else 0
        self._render_video = getattr(world, "render_video", None)  # optional part of a world: a larger frame
        self.sensor = sensor if sensor is not None else OracleSensor(world, cfg.perception_hz, 0.0, dt)
        self.sensor.reset(seed)
        # a source that sees motion (two frames) gets the frame rendered prev_frame_gap_s before each query (in real
        # time a snapshot of the world then, rendered with the query's off the 1 kHz path)
        self.earlier = EarlierFrame(world.snapshot if async_queries is not None else world.render,
                                    self.spec.prev_frame_gap_s, dt)
        self.missed_in_row = 0
        self.k = 0  # the next tick
        self.aborted = False
        self.pending_query: Observation | None = None
        self._resume = False  # the tick k stopped at its query: resume there
        self._state = None
        self._after_us = 0.0  # this tick's work that real time does after the command (fusion, the MPC update), us
        self._wall_s = 0.0
        self._finished: EpisodeLog | None = None
        self.record = bool(record)
        if self.record:
            self.log.recording = {"estimate": [], "chunks": [], "frames": [], "mpc": []}
        controller.recorded_plans = self.log.recording["mpc"] if self.record else None
        self._est_every = max(1, int(round(0.01 / dt)))

    def _new_log(self, seed: int) -> EpisodeLog:
        """The episode's empty log, sized for its ticks."""
        n, dt, world = self.n_ticks, self.dt_s, self.world
        log = EpisodeLog(seed=seed, t_s=np.arange(n) * dt, ee_pos_m=np.empty((n, 3)), target_pos_m=np.empty((n, 3)),
                         ref_pos_m=np.empty((n, 3)), q_rad=np.empty((n, 7)), dq_rad_s=np.empty((n, 7)),
                         tau_cmd_nm=np.empty((n, 7)), tick_us=np.empty(n), after_us=np.zeros(n),
                         safety_mask=np.zeros(n, dtype=np.uint16), instruction=world.instruction)
        self._objects_fn = getattr(world, "objects_pos_m", None)  # optional part of the world: distractors
        n_objects = len(self._objects_fn()) if self._objects_fn is not None else 1
        if n_objects > 1:
            log.objects_pos_m = np.empty((n, n_objects, 3))
            log.target_index = int(getattr(world, "target_index", 0))
        return log

    def _reset_source(self) -> None:
        """A new episode for the source (a LeRobot policy clears its action queue); a fault there is counted."""
        source_reset = getattr(self.source, "reset", None)
        if callable(source_reset):
            try:
                source_reset()
            except Exception as exc:  # noqa: BLE001 - a source fault: counted, the episode runs
                self.log.events.append((0.0, "source_reset_raised", f"{type(exc).__name__}: {exc}"[:200]))

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
        if self._state.wrench_ext is not None:  # a contact task's world measures the wrench (reach's does not)
            self.contact.check(self._state.wrench_ext)
            self.controller.sense_wrench(self._state.wrench_ext, self._state.gripper_m)
        s0 = time.perf_counter()
        try:
            arrived = self.sensor.poll(t)
        except Exception as exc:  # noqa: BLE001 - a crashed sensor is a lost measurement
            arrived = []
            log.perception_errors += 1
            log.events.append((t, "perception_error", f"{type(exc).__name__}: {exc}"[:200]))
        tick0 = time.perf_counter()
        log.sensor_wall_s += tick0 - s0
        # the tick order fuses them now (simulated) or once the command is out (deadline); the time of the former is
        # kept off the command path's and recorded apart
        self._after_us = self.order.on_arrival(self, arrived, tick0) if arrived else 0.0
        if self.async_queries is not None:
            self._collect(t)
        elif self._ahead is not None and self._ahead_due(t):
            self._take_ahead()
        self.earlier.tick(t, self.next_plan_s, self.replan_period_s)
        if t >= self.next_plan_s - self._eps:  # a query is due
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

    def fuse(self, arrived: list) -> None:
        """Fuse the measurements that have arrived into the controller's target estimate."""
        log = self.log
        for m in arrived:
            self.controller.perceive(m.t_capture_s, m.pos_m)
            log.measurements += 1
            log.measurements_lost += m.pos_m is None

    def admit_due(self, t: float) -> int:
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

    def _finish_tick(self) -> None:
        """The rest of tick ``k``: due chunks, the watchdog, the command and its check, the log, the physics step."""
        k, log, controller, cfg = self.k, self.log, self.controller, self.config
        t = k * self.dt_s
        state = self._state
        # simulated time admits here, real time after the command: kept off the command path's time as real time
        # runs it (the clock starts once it is done), recorded in after_us
        admit_us = self.order.before_command(self, t)
        tick0 = time.perf_counter()
        self._after_us += admit_us
        if controller.stop is None and (not controller.covered(t) or t - self.last_arrival_s > cfg.chunk_timeout_s):
            controller.watchdog(t)
            log.events.append((t, "watchdog_stop", ""))
        if self.link is None or self.link.delivered(k, t):
            out = self.order.command(self, k, t, state)
        else:  # the link lost it: the robot re-applies the last torque
            self.missed_in_row += 1
            log.missed_ticks += 1
            out = controller.missed_tick(state.q_rad, state.dq_rad_s)
        mask = self.monitor.check(out.tau_nm, state.q_rad, state.dq_rad_s, out.ddq_cmd_rad_s2, out.tcp_vel_m_s)
        tau = out.tau_nm if not mask & NONFINITE else controller.last_torque_nm  # never send a non-finite torque
        log.safety_mask[k] = mask
        # the command path (state -> checked command) as real time runs it: the MPC update and the fusion, which real
        # time does after the command, are recorded in after_us (the MPC solve, in its own process, in mpc_solve_us)
        log.tick_us[k] = (time.perf_counter() - tick0) * 1e6 - controller.offpath_us
        self._after_us += controller.after_us
        self._log_tick(k, t, state, out.ref_pos_m, tau)
        self.k = k + 1
        if self.missed_in_row >= cfg.abort_after_missed_ticks:
            log.abort = {"t_s": float(t), "reason": "communication_constraints_violation"}
            log.events.append((t, "abort", f"{self.missed_in_row} missed ticks in a row"))
            self.aborted = True
            return
        if self._frame_every and k % self._frame_every == 0:
            log.frames.append(self._render_video() if self._render_video else self.world.render()[0])
        self.world.step(tau, out.gripper_m)
        log.after_us[k] = self._after_us + self.order.after_command(self, t)
        if self.progress is not None and k % 500 == 0:
            self.progress(k / self.n_ticks)

    def _log_tick(self, k: int, t: float, state, ref_pos_m: np.ndarray, tau: np.ndarray) -> None:
        log = self.log
        log.ee_pos_m[k] = state.ee_pos_m
        log.target_pos_m[k] = self.world.target_pos_m()
        if log.objects_pos_m is not None:
            log.objects_pos_m[k] = self._objects_fn()
        log.ref_pos_m[k] = ref_pos_m
        log.q_rad[k] = state.q_rad
        log.dq_rad_s[k] = state.dq_rad_s
        log.tau_cmd_nm[k] = tau
        if self.record and k % self._est_every == 0:
            est = self.controller.target_estimate(t)
            if est is not None:
                log.recording["estimate"].append((t, np.array(est, dtype=float)))

    # ---- the log ---------------------------------------------------------------------------------------
    def finish(self) -> EpisodeLog:
        """The episode's log with every counter filled in (the ticks run so far; call once the episode is done)."""
        if self._finished is not None:
            return self._finished
        log, cfg, world = self.log, self.config, self.world
        if self._ahead is not None:  # asked ahead near the end: its answer is handled as it was in line
            w0 = time.perf_counter()
            self._take_ahead()
            self._wall_s += time.perf_counter() - w0
        if self.lookahead is not None:
            self.lookahead.close()
        log.wall_s = self._wall_s
        if self.k < self.n_ticks:
            log.truncate(self.k)
        c = self.controller.counters()
        log.qp_failures, log.rate_clamps, log.qp_rescues = c.qp_failures, c.rate_clamps, c.qp_rescues
        log.smoother_failures, log.mpc_failures, log.mpc_solve_us = c.smoother_failures, c.mpc_failures, list(c.mpc_solve_us)
        log.plan_resyncs, log.floor_clamps, log.mpc_bypass_ticks = c.plan_resyncs, c.floor_clamps, c.mpc_bypass_ticks
        log.watchdog_stops, log.gated_measurements = c.watchdog_stops, dict(c.gated_measurements)
        log.safety_counts = self.monitor.counts
        if self.contact.violations:  # a kind of its own, counted only where it happened (reach's counts unchanged)
            log.safety_counts[CONTACT_FORCE] = self.contact.violations
        task_report = getattr(world, "task_report", None)  # a contact task's world reports its own figures
        log.task = task_report() if task_report is not None else None
        log.torque_rate_max_nm_s = self.monitor.torque_rate_max_nm_s
        log.rejections = dict(self.intake.rejections)
        log.source_errors = [dict(e) for e in self.intake.source_errors]
        log.events = sorted(log.events + self.intake.events)
        log.sensor_stats = dict(getattr(self.sensor, "stats", {}))
        log.jump_times_s = tuple(t for t in world.target_jump_times_s() if t <= cfg.duration_s)
        changes_fn = getattr(world, "target_change_times_s", None)  # a world without it: the jumps are the changes
        changes = changes_fn() if changes_fn is not None else log.jump_times_s
        log.change_times_s = tuple(t for t in changes if t <= cfg.duration_s)
        self._finished = log
        return log
