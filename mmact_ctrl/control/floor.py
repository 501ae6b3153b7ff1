"""The floor stage: no reference below the TCP floor (``StackConfig.tcp_floor_m``, the table with a margin)."""

from __future__ import annotations

import numpy as np

from mmact_ctrl.control.samples import ReferenceSample


class FloorClamp:
    """Raises a reference sample below ``floor_m`` to it, with no downward rate left (counted in ``clamps``)."""

    def __init__(self, floor_m: float) -> None:
        self.floor_m = float(floor_m)
        self.clamps = 0

    def raise_to_floor(self, pos: np.ndarray, *rates: np.ndarray) -> tuple[np.ndarray, tuple[np.ndarray, ...]]:
        """``pos`` raised to the floor (counted), its rates (velocity, acceleration) without their downward part."""
        self.clamps += 1
        up = tuple(np.array([r[0], r[1], max(r[2], 0.0)]) for r in rates)
        return np.array([pos[0], pos[1], self.floor_m]), up

    def __call__(self, sample: ReferenceSample) -> ReferenceSample:
        pos = sample.pos_m
        if pos[2] < self.floor_m:
            pos, (vel,) = self.raise_to_floor(pos, sample.vel_m_s)
            return ReferenceSample(pos, vel, sample.rotvec_rad, sample.rotvec_rate_rad_s, sample.gripper_m)
        return sample

    def positions(self, pos: np.ndarray) -> np.ndarray:
        """Positions (N, 3) raised to the floor (not counted: a preview); a copy only when one is raised."""
        if np.any(pos[:, 2] < self.floor_m):  # a copy: the executor's array may be its own cache
            pos = pos.copy()
            pos[:, 2] = np.maximum(pos[:, 2], self.floor_m)
        return pos
