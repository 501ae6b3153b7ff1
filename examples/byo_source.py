"""A complete chunk source written against the contract alone: the README's "Bring your own policy" example.

    python -m scenarios.moving_target --source examples/byo_source.py:make_source --mode open_loop hybrid
    python -m scenarios.sweep --quick --source examples.byo_source:make_source --out out/byo
    python -m scenarios.faults --quick --source examples.byo_source:make_source --out out/byo_faults

It sees what a two-frame policy sees (the target where the frame at ``t0`` shows it and where the frame
``frame_gap_s`` earlier showed it), estimates the target's velocity, and plans a minimum-jerk path from the TCP to
where the target will be. It imports nothing of the stack but the two contract types.
"""

from __future__ import annotations

import numpy as np

from mmact_ctrl.chunk import ActionChunk, Observation


class LeadingSource:
    """Aims each waypoint where the target will be at that waypoint's time.

    Args:
        horizon: waypoints per chunk (any H >= 1).
        dt_s: their spacing, s: waypoint ``i`` is for ``observation.t0_s + (i + 1) * dt_s``.
        speed_m_s: average TCP speed of the approach, m/s.
    """

    needs_image = False  # it reads the target positions of the two frames, not the pixels

    def __init__(self, horizon: int = 16, dt_s: float = 0.1, speed_m_s: float = 0.4) -> None:
        if horizon < 1 or not dt_s > 0 or not speed_m_s > 0:
            raise ValueError(f"horizon >= 1, dt_s > 0 and speed_m_s > 0, got {horizon}, {dt_s}, {speed_m_s}")
        self.horizon, self.dt_s, self.speed_m_s = int(horizon), float(dt_s), float(speed_m_s)
        self.name = "byo-leading"

    @property
    def chunk_dt_s(self) -> float:
        return self.dt_s

    def plan(self, observation: Observation) -> ActionChunk:
        start = np.asarray(observation.ee_pos_m, dtype=float)
        target = np.asarray(observation.target_pos_m, dtype=float)
        vel = np.zeros(3)
        if observation.target_prev_pos_m is not None and observation.frame_gap_s > 0:
            vel = (target - observation.target_prev_pos_m) / observation.frame_gap_s
            if np.linalg.norm(vel) > 0.8:  # faster than any target moves: a jump between the frames, not a motion
                vel = np.zeros(3)
        times = self.dt_s * np.arange(1, self.horizon + 1)  # since t0: waypoint i is for t0 + (i + 1) dt
        goals = target + times[:, None] * vel
        duration = max(0.5, float(np.linalg.norm(goals[-1] - start)) / self.speed_m_s)
        s = np.clip(times / duration, 0.0, 1.0)[:, None]
        s = s**3 * (10.0 - 15.0 * s + 6.0 * s**2)  # minimum jerk
        waypoints = np.zeros((self.horizon, 7))
        waypoints[:, :3] = start + s * (goals - start)  # world frame, m
        waypoints[:, 3:6] = 0.0  # rotation vector relative to the nominal grasp (hand pointing down), rad
        waypoints[:, 6] = 0.08  # gripper opening, m
        return ActionChunk(waypoints=waypoints, dt_s=self.dt_s, t0_s=observation.t0_s)


def make_source(horizon: int = 16, dt_s: float = 0.1, speed_m_s: float = 0.4) -> LeadingSource:
    """The factory ``--source examples/byo_source.py:make_source`` calls (``--source-arg horizon=50`` ...)."""
    return LeadingSource(horizon=horizon, dt_s=dt_s, speed_m_s=speed_m_s)
