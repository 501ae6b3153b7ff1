"""Faults of the chunk source: :class:`FaultySource` (a source whose answers in the window raise, carry NaN or
garbage tokens, are offset, missing or late) and the builders of the ``source`` and ``wire`` faults of the registry."""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from mmact_ctrl.chunk import ActionChunk
from scenarios.faults.clock import in_window

if TYPE_CHECKING:
    from scenarios.faults.spec import Injection

#: the offset of ``splice_offset``'s chunks, m (along +x).
SPLICE_OFFSET_M = 0.25
#: ``garbage_tokens``: an action token id far outside any vocabulary.
GARBAGE_TOKEN = 10**9


class FaultySource:
    """A chunk source whose answers to observations in ``window`` are spoiled by ``behaviour``:

    ``raise`` (RuntimeError), ``nan`` (tries to build an ``ActionChunk`` with NaN waypoints: its constructor
    raises ValueError), ``tokens`` (out-of-range integer tokens, or float tokens), ``splice`` (waypoints offset
    by :data:`SPLICE_OFFSET_M`), ``silent`` (None: nothing arrives), ``late`` (``info["arrival_delay_s"]`` set
    to ``delay_s``). Observations outside the window get the wrapped source's answer unchanged."""

    def __init__(self, inner, behaviour: str, window: tuple[float, float], delay_s: float = 0.0) -> None:
        if behaviour not in ("raise", "nan", "tokens", "splice", "silent", "late"):
            raise ValueError(f"unknown source fault behaviour {behaviour!r}")
        self._inner = inner
        self._behaviour = behaviour
        self._window = window
        self._delay_s = float(delay_s)
        self.faulty_calls = 0

    def __getattr__(self, name: str):  # everything else is the wrapped source's
        return getattr(self._inner, name)

    @property
    def needs_image(self) -> bool:
        return self._inner.needs_image

    @property
    def declared_capabilities(self) -> frozenset[str]:
        """The wrapped source's (it inpaints only if that one does)."""
        from mmact_ctrl.sources.contract import capabilities

        return capabilities(self._inner)

    @property
    def chunk_dt_s(self) -> float:
        return self._inner.chunk_dt_s

    @property
    def action_token_range(self):
        return getattr(self._inner, "action_token_range", None)

    def plan(self, observation):
        return self._answer(observation, lambda: self._inner.plan(observation))

    def plan_inpaint(self, observation, known):
        return self._answer(observation, lambda: self._inner.plan_inpaint(observation, known))

    def _answer(self, observation, call):
        if not in_window(self._window, observation.t0_s):
            return call()
        self.faulty_calls += 1
        b = self._behaviour
        if b == "raise":
            raise RuntimeError(f"injected fault: the chunk source crashed at t={observation.t0_s:.3f} s")
        if b == "silent":
            return None
        chunk = call()
        if chunk is None:
            return None
        if b == "nan":
            w = np.array(chunk.waypoints, dtype=np.float64)
            w[:, :3] = np.nan
            return ActionChunk(waypoints=w, dt_s=chunk.dt_s, t0_s=chunk.t0_s, tokens=chunk.tokens, info=chunk.info)
        if b == "tokens":
            shape = np.asarray(chunk.waypoints).shape
            if self.action_token_range is not None and self.faulty_calls % 2 == 1:
                tokens = np.full(shape, GARBAGE_TOKEN, dtype=np.int64)  # ids far outside the vocabulary
            else:
                tokens = np.full(shape, 0.5, dtype=np.float64)  # not integers at all
            return dataclasses.replace(chunk, tokens=tokens)
        if b == "splice":
            w = np.array(chunk.waypoints, dtype=np.float64)
            w[:, 0] += SPLICE_OFFSET_M
            return dataclasses.replace(chunk, waypoints=w)
        # late
        return dataclasses.replace(chunk, info={**chunk.info, "arrival_delay_s": self._delay_s})


# ---- builders of the registry -------------------------------------------------------------------------------


def source_fault(behaviour: str):
    def build(spec, world, source, controller, inj: Injection) -> None:
        delay = 10.0 * controller.config.latency_ms / 1000.0 if behaviour == "late" else 0.0
        inj.source = FaultySource(source, behaviour, inj.window_s, delay_s=delay)

    return build


def wire_fault(behaviour: str):
    """The source served over openpi's protocol on 127.0.0.1 with the wire failing in the window
    (``scenarios.faults.wire``); the server stops when the injection is closed."""

    def build(spec, world, source, controller, inj: Injection) -> None:
        from scenarios.faults.wire import WireServed

        served = WireServed(source, behaviour, inj.window_s, scene={"n_objects": int(getattr(world, "n_objects", 2))})
        inj.source = served
        inj._undo.append(served.close)

    return build
