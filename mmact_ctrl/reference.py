"""The active chunk as a time-indexed reference (piecewise-linear between waypoints)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mmact_ctrl.chunk import ActionChunk

#: the last waypoint steps agree to this fraction (and absolute m) when a chunk's tail runs at a constant velocity
_TAIL_REL_TOL = 0.2
_TAIL_ABS_TOL_M = 2e-4


def terminal_velocity_m_s(chunk: ActionChunk) -> np.ndarray:
    """The velocity (3,) m/s of the chunk's last waypoint step when its last two steps agree (a constant-velocity
    tail: the chunk follows a moving target's predicted course), else zero (it decelerates to rest at its aim, or
    turns, e.g. at a workspace wall). Chunks with fewer than three waypoints: zero."""
    w = chunk.waypoints
    if w.shape[0] < 3:
        return np.zeros(3)
    d1 = w[-1, :3] - w[-2, :3]
    d0 = w[-2, :3] - w[-3, :3]
    step = float(np.linalg.norm(d1))
    if step < _TAIL_ABS_TOL_M or float(np.linalg.norm(d1 - d0)) > _TAIL_REL_TOL * step + _TAIL_ABS_TOL_M:
        return np.zeros(3)
    return d1 / chunk.dt_s


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
    def aim_vel_m_s(self) -> np.ndarray:
        """How the chunk's aim moves (3,) m/s: its terminal velocity when its last waypoints run at a constant
        velocity (a source that leads a moving target ends its chunk on the target's predicted course), else zero
        (a chunk that comes to rest at its aim). See :func:`terminal_velocity_m_s`."""
        return terminal_velocity_m_s(self.chunk)

    def aim_at(self, t_s: float) -> np.ndarray:
        """Where the chunk assumed its target to be at ``t_s`` (3,) m: the aim moved along :attr:`aim_vel_m_s`."""
        return self.aim_pos_m + self.aim_vel_m_s * (t_s - self.t_last_s)

    @property
    def t_last_s(self) -> float:
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
