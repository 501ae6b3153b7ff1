"""The earlier camera frame a motion-seeing source asks for (``prev_frame_gap_s`` before each query).

A policy trained on two frames (the observation's and one ``gap_s`` earlier) must get the same pair at run time.
Rendering every tick would cost ~10 ms per view per tick; instead the loop renders once, ``gap_s`` before each
scheduled query (:meth:`EarlierFrame.tick`), and hands that frame over with the query (:meth:`EarlierFrame.take`).
When a query comes earlier than scheduled, or at the start of an episode, there is no frame of the right age and
:meth:`take` returns None: the source then sees no motion, as it did in training at the start of an episode.
"""

from __future__ import annotations

from typing import Callable

import numpy as np


class EarlierFrame:
    """One frame rendered ``gap_s`` before the next scheduled query.

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
        self._frame: np.ndarray | None = None
        self._t_s = -np.inf
        self._for_plan_s = -np.inf
        #: queries that got no earlier frame (the first one of an episode, or a query earlier than scheduled)
        self.missing = 0

    def tick(self, t_s: float, next_plan_s: float) -> None:
        """Render now if ``t_s`` is ``gap_s`` before the scheduled query and that query has no frame yet."""
        if self.gap_s <= 0 or next_plan_s == self._for_plan_s:
            return
        if t_s >= next_plan_s - self.gap_s - 0.5 * self.dt_s and t_s < next_plan_s - 0.5 * self.dt_s:
            self._frame, self._t_s, self._for_plan_s = self._render(), t_s, next_plan_s

    def take(self, t_s: float) -> np.ndarray | None:
        """The frame for a query at ``t_s`` if one of about ``gap_s`` age exists (within one tick), else None."""
        if self.gap_s <= 0:
            return None
        if self._frame is not None and abs((t_s - self._t_s) - self.gap_s) <= 1.5 * self.dt_s:
            frame, self._frame = self._frame, None
            return frame
        self.missing += 1
        return None
