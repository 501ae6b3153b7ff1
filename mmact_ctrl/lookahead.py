"""Simulated time, the chunk source asked ahead: its call runs in a worker thread while the ticks before its chunk's
activation go on, and its answer is taken at the tick that needs it.

In simulated time a query at ``t0`` is answered at once and its chunk waits ``latency`` before it becomes active; the
ticks in between do not read the answer. So the call may run beside them: the observation (its frames included) is
taken at ``t0`` on the loop's thread, the call (``executor.request(source, obs, ctx)()``) runs in a worker, and the
loop takes the answer, waiting for it if it has to, at the first tick at or after ``t0 + latency`` (before that tick
admits its chunks), then handles it exactly as an answer at ``t0``: the same checks and counts, the same target
estimate (taken at ``t0``), the same activation time, the same next query. Every result is unchanged bit for bit
(``scenarios.golden``); only the wall clock differs: the policy's forward pass (about 18 ms of a 6 s episode's 0.7 s
per query here) runs while the arm is simulated.

Only where nothing can tell the difference (:func:`can_look_ahead`): a source that declares its ``plan`` a pure
function of the observation, safe to call from another thread (``answers_concurrently = True``: the shipped policy
does); the configured latency (not the measured one, which is the call's own wall time); a latency of at least two
ticks, shorter than the replan period; no earlier frame (``prev_frame_gap_s`` 0: its render time would fall in the
window); not stepping query by query (the Gymnasium environment) and not in real time (which has its own worker).
"""

from __future__ import annotations

import time
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from mmact_ctrl.chunk import Observation
from mmact_ctrl.realtime.async_source import Answer


def can_look_ahead(answers_concurrently: bool, latency_s: float, period_s: float, prev_frame_gap_s: float,
                   dt_s: float, measured_latency: bool, stepped: bool) -> bool:
    """Whether a query's call may run ahead in a worker (see the module)."""
    return (answers_concurrently and not measured_latency and not stepped and prev_frame_gap_s <= 0.0
            and 2.0 * dt_s <= latency_s < period_s)


@dataclass(frozen=True)
class AheadQuery:
    """A query in flight: what the in-line path would have read at ``t0`` (the target estimate, the next query time it
    replaced), when its answer is needed, and the answer to come (its observation in it)."""

    target_at_obs_m: np.ndarray | None
    next_before_s: float
    needed_at_s: float
    answer: Future


class LookaheadWorker:
    """One worker thread, one call at a time (made on the first query; :meth:`close` ends it)."""

    def __init__(self) -> None:
        self._pool: ThreadPoolExecutor | None = None

    def submit(self, observation: Observation, call: Callable[[], Any]) -> Future:
        """Run ``call`` (the request for ``observation``) in the worker; the future's result is its
        :class:`~mmact_ctrl.realtime.async_source.Answer` (the value or what it raised, and its wall time)."""
        if self._pool is None:
            self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="chunk-source-ahead")
        return self._pool.submit(_answer, observation, call)

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None


def _answer(observation: Observation, call: Callable[[], Any]) -> Answer:
    t0 = time.perf_counter()
    try:
        value, error = call(), None
    except BaseException as exc:  # noqa: BLE001 - every failure of the source is the intake's to count
        value, error = None, exc
    return Answer(observation, value, error, time.perf_counter() - t0)
