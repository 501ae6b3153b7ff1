"""The runner's source side: building what a chunk source sees, asking it (in this process; in simulated time, where
nothing can tell, in a worker until its chunk is due, ``mmact_ctrl.lookahead``; in real time in a worker while the
ticks go on), and queuing what it answers to become active after its latency.

:class:`SourceQueries` is a part of :class:`~mmact_ctrl.runner.EpisodeRunner` (it reads the runner's world, source,
controller, executor, intake and log); it is kept apart because it is the one half of the loop a newcomer reads
when the question is "what does the policy see, and when does its chunk start?".
"""

from __future__ import annotations

import math
import time

import numpy as np

from mmact_ctrl.chunk import ActionChunk, Observation
from mmact_ctrl.executors import QueryContext
from mmact_ctrl.lookahead import AheadQuery

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


def observe(world, controller, t_s: float, with_image: bool, target_prev_pos_m: np.ndarray | None = None,
            frame_gap_s: float = 0.0, prev_image: np.ndarray | None = None) -> Observation:
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


class SourceQueries:
    """The source side of :class:`~mmact_ctrl.runner.EpisodeRunner` (see the module)."""

    def _earlier_target(self, k: int) -> tuple[np.ndarray | None, float]:
        """(the target FRAME_GAP_S before tick ``k``, the gap s): recorded so far; the first frame before that."""
        log, gap = self.log, self._gap_ticks
        if k >= gap:
            return log.target_pos_m[k - gap], gap * self.dt_s
        return (log.target_pos_m[0], k * self.dt_s) if k > 0 else (None, 0.0)

    def _observe(self, k: int, t: float) -> Observation:
        prev, gap_s = self._earlier_target(k)
        return observe(self.world, self.controller, t, with_image=self.spec.needs_image, target_prev_pos_m=prev,
                       frame_gap_s=gap_s, prev_image=self.earlier.take(t) if self.earlier.gap_s > 0 else None)

    def _scheduled(self) -> ActionChunk | None:
        """The chunk that runs while the next is computed: the last one accepted, pending or active."""
        intake, active = self.intake, self.controller.active
        return intake.pending[-1].chunk if intake.pending else (active.chunk if active else None)

    def _context(self, t_s: float) -> QueryContext:
        """What the executor's request reads of the loop at a query at ``t_s`` (simulated time's latency)."""
        return QueryContext(t_s=t_s, latency_s=self.latency_s, scheduled=self._scheduled(),
                            chunk_dt_s=self.spec.chunk_dt_s)

    def asked_at(self, t_s: float) -> bool:
        """Real time: whether the tick at ``t_s`` handed the worker a query (its share of work is had)."""
        return self._inflight is not None and self._inflight[0] == t_s

    def _ask(self, k: int, t: float) -> None:
        """Real time: hand the query to the worker (its frames rendered there); no other query until it answers."""
        aq = self.async_queries
        prev, gap_s = self._earlier_target(k)
        obs = observe(self.world, self.controller, t, with_image=False, target_prev_pos_m=prev, frame_gap_s=gap_s)
        snaps = None
        if self.spec.needs_image:
            snaps = (self.world.snapshot(), self.earlier.take(t) if self.earlier.gap_s > 0 else None)
        # the latency is what answers have taken, not the configured one (which does not apply in real time)
        ctx = QueryContext(t_s=t, latency_s=aq.latency_estimate_s(self.latency_s), scheduled=self._scheduled(),
                           chunk_dt_s=self.spec.chunk_dt_s)
        executor, source = self.executor, self.source
        aq.submit(lambda o: executor.request(source, o, ctx), obs, snaps)
        self._inflight = (t, self.next_plan_s)
        self.next_plan_s = math.inf

    def _collect(self, t: float) -> None:
        """Real time: take the worker's answer if it has come; its chunk is checked and active at once."""
        answer = self.async_queries.poll()
        if answer is None:
            return
        _, next_before = self._inflight
        self._inflight = None
        t0 = answer.observation.t0_s
        self._handle(answer, next_before, t - t0, self.controller.target_estimate(t0))

    def _handle(self, answer, next_before_s: float, delay_s: float, target_at_obs_m: np.ndarray | None) -> None:
        """A worker's answer (``Answer``) handled as one in line: checked and counted by the intake, its chunk
        queued ``delay_s`` after its observation, the next query set from the one it replaced."""
        obs = answer.observation
        chunk = self.intake.request(answer.result, obs)
        self.log.plan_ms.append(answer.round_trip_s * 1e3)
        if self.record and obs.image is not None:
            self.log.recording["frames"].append((obs.t0_s, obs.image))
        if chunk is not None:
            self.accept(chunk, obs, delay_s, target_at_obs_m)
        self.next_plan_s = self.executor.after_request(obs.t0_s, chunk, next_before_s, self.replan_period_s)

    def _query(self, obs: Observation) -> None:
        """Ask the source (through the executor and the intake) and queue what it answers."""
        if self.lookahead is not None:
            self._ask_ahead(obs)
            return
        t, log, intake = obs.t0_s, self.log, self.intake
        ctx = self._context(t)
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
            self.accept(chunk, obs, delay_s, self.controller.target_estimate(t))
        self.next_plan_s = self.executor.after_request(t, chunk, self.next_plan_s, self.replan_period_s)

    # ---- simulated time, asked ahead (``mmact_ctrl.lookahead``) ---------------------------------------------------
    def _ask_ahead(self, obs: Observation) -> None:
        """Hand the call to the worker at ``t0``, with what the answer's handling reads of ``t0`` (the target
        estimate, the next query time); no other query until :meth:`_take_ahead`."""
        t = obs.t0_s
        ctx = self._context(t)
        executor, source = self.executor, self.source
        answer = self.lookahead.submit(obs, lambda: executor.request(source, obs, ctx)())
        self._ahead = AheadQuery(self.controller.target_estimate(t), self.next_plan_s, t + self.latency_s, answer)
        self.next_plan_s = math.inf

    def _ahead_due(self, t: float) -> bool:
        """Whether the answer in flight is needed by tick ``t``: its chunk's activation, or any chunk's admission
        (an admission may move the next query's time, which the answer's handling sets)."""
        q = self._ahead
        if q is None:
            return False
        pending = self.intake.pending
        return t >= q.needed_at_s - self._eps or (bool(pending) and pending[0].t_active_s <= t + self._eps)

    def _take_ahead(self) -> None:
        """The answer in flight (waited for if it has not come), handled as :meth:`_query` handles one at ``t0``."""
        q, self._ahead = self._ahead, None
        self._handle(q.answer.result(), q.next_before_s, self.latency_s, q.target_at_obs_m)

    def accept(self, chunk: ActionChunk, obs: Observation, delay_s: float,
               target_at_obs_m: np.ndarray | None) -> None:
        """Queue a valid ``chunk`` (answered to ``obs``) to become active ``delay_s`` after its observation (or later,
        when the source says it is late: ``info["arrival_delay_s"]``); ``target_at_obs_m``: the target estimate at
        the observation's time (None before the first measurement)."""
        log = self.log
        n_clipped = chunk.n_clipped
        log.clipped_actions += int(n_clipped) if isinstance(n_clipped, (int, np.integer)) and n_clipped > 0 else 0
        info = chunk.info if isinstance(chunk.info, dict) else {}  # a source's own notes: never trusted to be well formed
        for key in SOURCE_TIMING_KEYS:  # what the source says of its timing: numbers only (a server may say None)
            value = _finite(info.get(key))
            if value is not None:
                log.source_timing_ms.setdefault(key, []).append(value)
        delay_s = max(delay_s, _finite(info.get("arrival_delay_s")) or 0.0)  # a source that knows it is late
        self.intake.submit(obs.t0_s + delay_s, chunk, target_at_obs_m, obs.ee_pos_m)
