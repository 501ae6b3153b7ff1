"""The earlier camera frame a motion-seeing source asks for (``prev_frame_gap_s`` before each query).

A policy trained on two frames (the observation's and one ``gap_s`` earlier) must get the same pair at run time.
Rendering every tick would cost ~10 ms per view per tick; instead the loop renders once, ``gap_s`` before each
scheduled query (:meth:`EarlierFrame.tick`), and hands that frame over with the query (:meth:`EarlierFrame.take`).
When a query comes earlier than scheduled, or at the start of an episode, there is no frame of the right age and
:meth:`take` returns None: the source then sees no motion, as it did in training at the start of an episode.
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np


class EarlierFrame:
    """Frames rendered ``gap_s`` before the scheduled queries.

    When the gap is longer than the replan period (a 0.4 s gap at 5 Hz), the frame of a query is due before the
    query ahead of it has run: with ``period_s`` given, :meth:`tick` renders for the next ``ceil(gap_s / period_s)``
    queries of the nominal schedule, and :meth:`take` hands each query the frame of the right age. A query whose
    schedule moved (an executor that replans on activation) finds none, and counts as ``missing``.

    Args:
        render: returns the frame(s) ``(V, H, W, 3)`` uint8 of the world's cameras.
        gap_s: how long before a query its earlier frame is taken, s (0: never render).
        dt_s: the loop's tick, s (the frame's age may differ from ``gap_s`` by up to one tick).
    """

    def __init__(self, render: Callable[[], np.ndarray], gap_s: float, dt_s: float) -> None:
        if not np.isfinite(gap_s) or gap_s < 0:
            raise ValueError(f"gap_s must be finite and >= 0, got {gap_s!r}")
        self._render, self.gap_s, self.dt_s = render, float(gap_s), float(dt_s)
        self.reset()

    def reset(self) -> None:
        #: rendered frames: (render time s, frame), oldest first
        self._frames: list[tuple[float, np.ndarray]] = []
        self._served: set[int] = set()  # the queries already rendered for, as their time in ticks
        #: queries that got no earlier frame (the first one of an episode, or a query off its schedule)
        self.missing = 0

    def tick(self, t_s: float, next_plan_s: float, period_s: float = float("inf")) -> None:
        """Render now if ``t_s`` is ``gap_s`` before a scheduled query (the next one, and with ``period_s`` the ones
        after it that the gap reaches) that has no frame yet; at most one render per tick."""
        if self.gap_s <= 0:
            return
        # a gap up to the period needs only the next query (the frame is due after the query ahead of it ran)
        longer = math.isfinite(period_s) and period_s > 0 and self.gap_s > period_s + 0.5 * self.dt_s
        ahead = math.ceil(self.gap_s / period_s) if longer else 0
        for k in range(ahead + 1):
            q = next_plan_s + k * period_s if k else next_plan_s
            if not math.isfinite(q):  # no query scheduled (an executor that stopped asking)
                break
            key = round(q / self.dt_s)
            if key in self._served:
                continue
            if q - self.gap_s - 0.5 * self.dt_s <= t_s < q - 0.5 * self.dt_s:
                if not self._frames or self._frames[-1][0] != t_s:
                    self._forget_before(t_s - self.gap_s - 2.0 * self.dt_s)  # on a render only: no work per tick
                    self._frames.append((t_s, self._render()))
                self._served.add(key)

    def _forget_before(self, t_s: float) -> None:
        """Drop the frames rendered before ``t_s`` (too old for any query) and the queries before it."""
        while self._frames and self._frames[0][0] < t_s:
            self._frames.pop(0)
        self._served = {k for k in self._served if k * self.dt_s >= t_s}  # queries that can still come

    def take(self, t_s: float) -> np.ndarray | None:
        """The frame for a query at ``t_s`` if one of about ``gap_s`` age exists (within 1.5 ticks), else None."""
        if self.gap_s <= 0:
            return None
        for i, (t_r, frame) in enumerate(self._frames):
            if abs((t_s - t_r) - self.gap_s) <= 1.5 * self.dt_s:
                del self._frames[: i + 1]
                return frame
        self.missing += 1
        return None
