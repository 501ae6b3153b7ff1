"""The active chunk as a time-indexed reference (piecewise-linear between waypoints)."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from mmact_ctrl.chunk import ActionChunk

#: a chunk whose last waypoint step is slower than this comes to rest at its aim, m/s
REST_SPEED_M_S = 0.02


def tail_speed_m_s(chunk: ActionChunk) -> float:
    """The speed of the chunk's last waypoint step, m/s (0 for a one-waypoint chunk): about zero for a chunk that
    comes to rest at its aim, the target's predicted speed for a source that leads a moving target."""
    w = chunk.waypoints
    if w.shape[0] < 2:
        return 0.0
    return float(np.linalg.norm(w[-1, :3] - w[-2, :3])) / chunk.dt_s


@dataclass(frozen=True)
class ChunkReference:
    """A chunk once it is active.

    Attributes:
        chunk: the chunk.
        t_active_s: when it became active (observation time + latency), s.
        target_at_obs_m: filtered target estimate at the chunk's observation time (None if no estimate yet).
    """

    chunk: ActionChunk
    t_active_s: float
    target_at_obs_m: np.ndarray | None

    @property
    def aim_pos_m(self) -> np.ndarray:
        """Where the chunk aims: its last waypoint's position."""
        return self.chunk.waypoints[-1, :3]

    @property
    def at_rest(self) -> bool:
        """Whether the chunk comes to rest at its aim (its last step slower than ``REST_SPEED_M_S``); a chunk that
        is still moving at its end follows a moving target's predicted course (or has not finished its approach)."""
        return tail_speed_m_s(self.chunk) < REST_SPEED_M_S

    @cached_property
    def t_last_s(self) -> float:
        """The time of the chunk's last waypoint, s (read every tick by the watchdog; the chunk is immutable)."""
        return float(self.chunk.times_s[-1])

    def sample(self, t_s: float) -> tuple[np.ndarray, np.ndarray]:
        """(action (7,), action rate (7,) per s) at ``t_s``.

        Linear interpolation between waypoints; the first waypoint is held before its time
        and the last after its time (zero rate). Waypoints already past are skipped implicitly.
        """
        w = self.chunk.waypoints
        times = self.chunk.times_s
        if t_s <= times[0]:
            return w[0], np.zeros(7)
        if t_s >= times[-1]:
            return w[-1], np.zeros(7)
        i = int(np.searchsorted(times, t_s, side="right"))  # times[i-1] <= t < times[i]
        span = times[i] - times[i - 1]
        s = (t_s - times[i - 1]) / span
        rate = (w[i] - w[i - 1]) / span
        return w[i - 1] + s * (w[i] - w[i - 1]), rate

    def sample_positions(self, times_s: np.ndarray) -> np.ndarray:
        """Positions (N, 3) at many times at once: :meth:`sample`'s interpolation, vectorized."""
        w = self.chunk.waypoints
        times = self.chunk.times_s
        return np.stack([np.interp(times_s, times, w[:, i]) for i in range(3)], axis=1)
