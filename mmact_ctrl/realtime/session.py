"""Episodes in real time: the runner paced on the wall clock, the source and the MPC answering beside the loop.

:class:`RealtimeSession` holds what outlives one episode (the source's worker thread, the MPC's process) and runs
episodes with :meth:`RealtimeSession.episode`. Nothing slow is on the 1 kHz path:

- the chunk source is asked in a worker thread (``mmact_ctrl.realtime.async_source``); for a source in another
  process (``ws://``) the thread waits on the socket; the observation's frames are rendered from a world snapshot by
  the world's render process (``world.render_snapshot``);
- the MPC is solved in a process of its own (``mmact_ctrl.mpc_worker.ProcessMPC``); the QP takes the newest plan;
- Python hands the GIL between threads every ``switch_interval_s`` instead of every 5 ms, so the worker thread's
  short Python stretches (encoding an observation) never hold the loop up for long.

The episode's log carries the deadline statistics (``EpisodeLog.deadline``, ``mmact_ctrl.realtime.pacer``).
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field

from mmact_ctrl.episode_log import EpisodeLog
from mmact_ctrl.mpc_worker import InlineMPC, ProcessMPC
from mmact_ctrl.realtime.async_source import AsyncQueries
from mmact_ctrl.realtime.loop_thread import cpu_split, loop_thread
from mmact_ctrl.realtime.pacer import PacerConfig, WallClockPacer
from mmact_ctrl.runner import EpisodeRunner


@dataclass(frozen=True)
class RealtimeConfig:
    """Attributes:
    pacer: the wall-clock pacing.
    mpc_process: solve the MPC in a process of its own (False: inline, on the 1 kHz path: for comparison only).
    switch_interval_s: Python's GIL switch interval while an episode runs, s.
    drain_timeout_s: at the end of an episode, how long to wait for a query still in flight, s.
    fifo_priority: > 0: run the loop's thread under SCHED_FIFO at this priority while an episode runs (Linux, needs
        the right to; best effort: refused, it runs at normal priority and ``priority_refused`` says so).
    no_gc: keep Python's cyclic garbage collector off while an episode runs (a full collection takes milliseconds);
        it runs between episodes.
    loop_cpu: pin the loop's thread to this CPU while an episode runs, and the session's workers (the source's
        thread, the MPC process, the world's render process) to the others (None, or a machine with one CPU: no
        pinning). Without it, waking the MPC process at every solve let it take the loop's CPU for the whole solve
        (measured here: sending a problem took 0.8 ms median, 1.6 us pinned).
    """

    pacer: PacerConfig = field(default_factory=PacerConfig)
    mpc_process: bool = True
    switch_interval_s: float = 0.0002
    drain_timeout_s: float = 15.0
    fifo_priority: int = 0
    no_gc: bool = True
    loop_cpu: int | None = 0

    def __post_init__(self) -> None:
        if not 0 < self.switch_interval_s <= 0.005:
            raise ValueError(f"switch_interval_s must be in (0, 0.005] s, got {self.switch_interval_s!r}")
        if not 0 <= self.fifo_priority <= 99:
            raise ValueError(f"fifo_priority must be in [0, 99], got {self.fifo_priority!r}")


class RealtimeSession:
    """Runs episodes of ``controller`` in ``world`` with ``source`` on the wall clock.

    Args:
        world: the world (with ``snapshot`` / ``render_snapshot`` when the source needs images).
        source: the chunk source (in real time usually a ``RemoteSource``: the policy in its own process).
        controller: the control layer (its MPC is moved to a process of its own for the session).
        config: real-time settings.
    """

    def __init__(self, world, source, controller, config: RealtimeConfig = RealtimeConfig()) -> None:
        self.world, self.source, self.controller, self.config = world, source, controller, config
        if source.needs_image and not callable(getattr(world, "render_snapshot", None)):
            raise ValueError("a source that needs images in real time needs a world with snapshot/render_snapshot")
        self.loop_cpus, self.worker_cpus = cpu_split(config.loop_cpu)
        self.queries = AsyncQueries(develop=world.render_snapshot if source.needs_image else None,
                                    cpus=self.worker_cpus)
        self._inline = controller.mpc_worker
        if controller.mpc is not None and config.mpc_process:
            mpc_cfg = controller.config.mpc
            controller.use_mpc_worker(ProcessMPC(mpc_cfg, controller.model.home_q_rad))
        self._closed = False
        with loop_thread(config.fifo_priority, no_gc=False) as thread:  # known before the first episode
            self.priority_refused = thread.priority_refused
        self.warm_up()
        self._pin_workers()

    def _pin_workers(self) -> None:
        """The MPC and render processes (started by now) on the worker CPUs."""
        if not self.worker_cpus:
            return
        for proc in (getattr(self.controller.mpc_worker, "_proc", None),
                     getattr(getattr(self.world, "_render_process", None), "_proc", None)):
            if proc is not None and proc.pid:
                pin_process(proc.pid, self.worker_cpus)

    def warm_up(self, duration_s: float = 0.3, seed: int = 0) -> None:
        """Run the stack once off the clock (compiled kernels, solver set-ups, the MPC process's first solves, the
        source's first answer), so the paced episodes start warm."""
        runner = EpisodeRunner(self.world, self.source, self.controller, seed, async_queries=self.queries)
        end = time.perf_counter() + 5.0
        runner.advance(duration_s)
        while (self.queries.in_flight or getattr(self.controller.mpc_worker, "_asked", None) is not None) \
                and time.perf_counter() < end:
            runner.advance(runner.t_s + 0.001)  # a few more ticks while the first answers come back
        self._drain()

    def episode(self, seed: int, sensor=None, record: bool = False) -> EpisodeLog:
        """One episode on the wall clock; its log (with ``deadline``)."""
        pacer = WallClockPacer(self.controller.config.dt_s, self.config.pacer)
        runner = EpisodeRunner(self.world, self.source, self.controller, seed, sensor=sensor,
                               async_queries=self.queries, deadline=pacer, record=record)
        try:
            with loop_thread(self.config.fifo_priority, self.loop_cpus, self.config.switch_interval_s,
                             self.config.no_gc) as thread:
                self.priority_refused = thread.priority_refused
                stats = pacer.run(runner)
        finally:
            self._drain()
        log = runner.finish()
        log.deadline = stats
        log.rt_exec_us, log.rt_jitter_us, log.rt_late_ticks = pacer.exec_us, pacer.jitter_us, pacer.late_ticks
        log.rt_cpu_us = pacer.cpu_us
        return log

    def _drain(self) -> None:
        """Wait for a query still in flight (its answer belongs to the episode that ended: dropped)."""
        end = time.perf_counter() + self.config.drain_timeout_s
        while self.queries.in_flight and time.perf_counter() < end:
            if self.queries.poll() is not None:
                break
            time.sleep(0.001)

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self.queries.close()
        worker = self.controller.mpc_worker
        if worker is not self._inline and self._inline is not None:
            self.controller.use_mpc_worker(self._inline)  # closes the process
        elif isinstance(worker, ProcessMPC):
            worker.close()

    def __enter__(self) -> "RealtimeSession":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def pin_process(pid: int, cpus: set[int]) -> None:
    """Best effort: ``pid`` on ``cpus``."""
    try:
        os.sched_setaffinity(pid, cpus)
    except OSError:
        pass


__all__ = ["InlineMPC", "RealtimeConfig", "RealtimeSession", "pin_process"]
