"""The chunk source asked concurrently: one query at a time, answered in a worker thread while the 1 kHz loop runs.

The worker renders the observation's frames from the world's snapshots (``develop``: in another process, since
MuJoCo's renderer holds the GIL) and then makes the call (a ``ws://`` source: it waits on the socket, which releases
the GIL). The loop polls for the answer every tick (:meth:`AsyncQueries.poll`, a lock-free check) and never blocks.
"""

from __future__ import annotations

import dataclasses
import os
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable

from mmact_ctrl.chunk import Observation


#: how many recent round trips the latency estimate looks at
RECENT = 10


@dataclass
class Answer:
    """A finished query: the observation it answered (frames included), the outcome, and how long it took.

    ``result()`` returns the source's answer or raises what the call raised (the chunk intake counts it)."""

    observation: Observation
    value: Any
    error: BaseException | None
    round_trip_s: float

    def result(self):
        if self.error is not None:
            raise self.error
        return self.value


class AsyncQueries:
    """Asks the source in a worker thread.

    Args:
        develop: ``develop(snapshot) -> frames (V, H, W, 3)``: the world's frames of a snapshot (None: no images).
        clock: wall clock, s.
        cpus: the CPUs the worker thread runs on (empty: wherever the process runs).
    """

    def __init__(self, develop: Callable[[Any], Any] | None = None,
                 clock: Callable[[], float] = time.perf_counter, cpus: set[int] | None = None) -> None:
        self._develop = develop
        self._cpus = set(cpus or ())
        self._clock = clock
        self._cv = threading.Condition()
        self._job: tuple | None = None
        self._done: Answer | None = None
        self.in_flight = False
        self._stop = False
        self._recent_s: list[float] = []  # the last round trips, s (the latency estimate)
        self._thread = threading.Thread(target=self._run, name="chunk-source", daemon=True)
        self._thread.start()

    def submit(self, make_call: Callable[[Observation], Callable[[], Any]], observation: Observation,
               snapshots: tuple | None) -> None:
        """Ask once: ``make_call(observation with its frames)`` builds the call (the executor's request)."""
        with self._cv:
            if self.in_flight:
                raise RuntimeError("a query is already in flight")
            self.in_flight = True
            self._job = (make_call, observation, snapshots, self._clock())
            self._cv.notify_all()

    def poll(self) -> Answer | None:
        """The answer if it has come (then the next query may be submitted), else None."""
        if self._done is None:  # the common 1 kHz case: no lock taken
            return None
        with self._cv:
            done, self._done = self._done, None
            self.in_flight = False
        self._recent_s = (self._recent_s + [done.round_trip_s])[-RECENT:]
        return done

    def latency_estimate_s(self, default_s: float) -> float:
        """What the next answer will probably take: the longest of the last :data:`RECENT` round trips (as LeRobot's
        ``LatencyTracker`` does; a mode that commits waypoints during inference, such as inpainting, uses it), or
        ``default_s`` before the first answer."""
        return max(self._recent_s) if self._recent_s else float(default_s)

    def _run(self) -> None:
        if self._cpus:
            try:
                os.sched_setaffinity(0, self._cpus)  # this thread only (Linux)
            except OSError:
                pass
        while True:
            with self._cv:
                while self._job is None and not self._stop:
                    self._cv.wait()
                if self._stop:
                    return
                make_call, obs, snaps, t0 = self._job
                self._job = None
            value, error = None, None
            try:
                if snaps is not None and self._develop is not None:
                    now, prev = snaps
                    obs = dataclasses.replace(obs, image=self._develop(now),
                                              prev_image=None if prev is None else self._develop(prev))
                value = make_call(obs)()
            except BaseException as exc:  # noqa: BLE001 - every failure of the source is the intake's to count
                error = exc
            answer = Answer(obs, value, error, self._clock() - t0)
            with self._cv:
                self._done = answer

    def close(self) -> None:
        with self._cv:
            self._stop = True
            self._cv.notify_all()
        self._thread.join(timeout=2.0)
