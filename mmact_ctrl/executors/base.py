"""The chunk-executor protocol: one way of executing action chunks, as one small object.

The loop (``mmact_ctrl.loop``) and the controller (``mmact_ctrl.controller``) know no mode names: they ask the
executor of the episode

- on the source side (the loop, at the replan clock): what to ask the source (:meth:`ChunkExecutor.request`)
  and when to ask next (:meth:`~ChunkExecutor.after_request`, :meth:`~ChunkExecutor.after_activation`,
  :meth:`~ChunkExecutor.after_refusal`);
- on the control side (the controller, at 1 kHz): which control layers run under it (:attr:`~ChunkExecutor.layers`),
  the raw reference of the executed chunk(s) (:meth:`~ChunkExecutor.sample`) and a task-space correction on top
  of it (:meth:`~ChunkExecutor.offset`).

A new fix from the field is one new file: a class that satisfies this protocol (most derive from
:class:`ClockedExecutor`, which has every default), registered by name in ``mmact_ctrl.executors.registry`` or
handed to ``HybridController(config, executor=...)`` directly.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable, Protocol, runtime_checkable

import numpy as np

from mmact_ctrl.chunk import ActionChunk, ChunkSource, Observation
from mmact_ctrl.reference import ChunkReference

if TYPE_CHECKING:  # pragma: no cover
    from mmact_ctrl.control.view import ExecutorView


@dataclass(frozen=True)
class Layers:
    """Which parts of the control layer run under an executor (each further gated by ``StackConfig``).

    Attributes:
        reads_target: fuse the 100 Hz target measurements into the target estimator (and hand them to the
            executor, :meth:`ChunkExecutor.perceive`).
        smooth: Ruckig jerk-limited smoothing of the reference (``StackConfig.use_ruckig``).
        preview: the MPC between the smoother and the QP (``StackConfig.use_mpc``).
    """

    reads_target: bool = False
    smooth: bool = False
    preview: bool = False


@dataclass(frozen=True)
class QueryContext:
    """What an executor may use to build its request to the source at observation time ``t_s``.

    Attributes:
        t_s: the observation time, s.
        latency_s: the inference latency the query is expected to take, s (the configured one; in real time the
            longest of the recent measured round trips).
        scheduled: the chunk that will be executing while the new one is computed (the last one accepted, pending
            or active), or None.
        chunk_dt_s: the source's declared waypoint spacing, s (``mmact_ctrl.sources.spec.SourceSpec``; None: not
            declared).
    """

    t_s: float
    latency_s: float
    scheduled: ActionChunk | None
    chunk_dt_s: float | None = None


@runtime_checkable
class ChunkExecutor(Protocol):
    """One way of executing chunks (see the module docstring)."""

    #: the name the study and the CLI use (``--mode``).
    name: str
    #: the control layers that run under it.
    layers: Layers
    #: the optional source capabilities it needs (``mmact_ctrl.sources.contract.CAPABILITIES``), checked before an
    #: episode starts: a source without them is refused in one line, never run into a silent episode.
    needs: frozenset[str]

    def bind(self, view: "ExecutorView") -> None:
        """Called once by the controller that runs this executor, with the narrow read-only view it may know
        (``mmact_ctrl.control.view.ExecutorView``: the stack's settings, the target estimate, the TCP's state)."""
        ...

    def reset(self) -> None:
        """A new episode."""
        ...

    # ---- source side (the loop) ------------------------------------------------
    def request(self, source: ChunkSource, observation: Observation, ctx: QueryContext) -> Callable[[], ActionChunk]:
        """The call that asks ``source`` for the next chunk (the loop runs it inside the chunk intake)."""
        ...

    def after_request(self, t_s: float, chunk: ActionChunk | None, next_query_s: float, period_s: float) -> float:
        """When to query next, after the query at ``t_s`` answered ``chunk`` (None: refused at the call)."""
        ...

    def after_activation(self, t_s: float, ref: ChunkReference, next_query_s: float) -> float:
        """When to query next, after a chunk became active at ``t_s``."""
        ...

    def after_refusal(self, t_s: float, next_query_s: float) -> float:
        """When to query next, after a due chunk was refused at ``t_s``."""
        ...

    # ---- control side (the controller) -------------------------------------------
    def activate(self, ref: ChunkReference, t_s: float) -> None:
        """``ref`` becomes the active chunk at ``t_s``."""
        ...

    def perceive(self, t_capture_s: float, z_m: np.ndarray | None) -> None:
        """A target measurement of the scene at ``t_capture_s`` (None: missed); only with ``layers.reads_target``."""
        ...

    def sample(self, t_s: float, active: ChunkReference) -> tuple[np.ndarray, np.ndarray]:
        """The raw reference (action (7,), action rate (7,) per s) of the executed chunk(s) at ``t_s``."""
        ...

    def sample_positions(self, times_s: np.ndarray, active: ChunkReference) -> np.ndarray:
        """Positions (N, 3) of :meth:`sample` at many times (the MPC's preview)."""
        ...

    def offset(self, t_s: float, ref: ChunkReference) -> tuple[np.ndarray, np.ndarray]:
        """Task-space position correction (3,) m and its rate (3,) m/s added to ``ref``'s sample at ``t_s`` (``ref``
        is the active chunk, or a candidate the splice check evaluates before activation)."""
        ...

    def offsets_many(self, times_s: np.ndarray, ref: ChunkReference) -> np.ndarray | None:
        """Corrections (N, 3) of :meth:`offset` at many times, or None for none."""
        ...


#: a zero 3-vector the executors return for "no correction" (never written in place)
ZERO3 = np.zeros(3)


class ClockedExecutor:
    """Defaults for every executor: query the source on the replan clock with ``plan``, execute the newest chunk
    as it is, no correction, no control layer beyond the QP. Subclasses override what differs."""

    name = "clocked"
    layers = Layers()
    needs: frozenset[str] = frozenset()

    def __init__(self) -> None:
        self.view: "ExecutorView | None" = None

    def bind(self, view: "ExecutorView") -> None:
        self.view = view

    def reset(self) -> None:
        pass

    def request(self, source: ChunkSource, observation: Observation, ctx: QueryContext) -> Callable[[], ActionChunk]:
        return lambda: source.plan(observation)

    def after_request(self, t_s: float, chunk: ActionChunk | None, next_query_s: float, period_s: float) -> float:
        return next_query_s + period_s

    def after_activation(self, t_s: float, ref: ChunkReference, next_query_s: float) -> float:
        return next_query_s

    def after_refusal(self, t_s: float, next_query_s: float) -> float:
        return next_query_s

    def activate(self, ref: ChunkReference, t_s: float) -> None:
        pass

    def perceive(self, t_capture_s: float, z_m: np.ndarray | None) -> None:
        pass

    def sample(self, t_s: float, active: ChunkReference) -> tuple[np.ndarray, np.ndarray]:
        return active.sample(t_s)

    def sample_positions(self, times_s: np.ndarray, active: ChunkReference) -> np.ndarray:
        return active.sample_positions(times_s)

    def offset(self, t_s: float, ref: ChunkReference) -> tuple[np.ndarray, np.ndarray]:
        return ZERO3, ZERO3

    def offsets_many(self, times_s: np.ndarray, ref: ChunkReference) -> np.ndarray | None:
        return None
