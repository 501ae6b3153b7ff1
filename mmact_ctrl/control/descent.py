"""The descent governor (``StackConfig.descent_band_m``): the TCP floor as a braking curve, in every mode, and in a
mode that reads the object, a guarded move where the fingertips pass the objects' top.

An open hand that lands on an object at the approach's speed is an impact: measured on pick at 0.4 m/s (the expert,
0.25 m/s at the fingertips' crossing of the cubes' top), 60-110 N on the robot, over the contact-force limit within
one or two ticks, before any reaction could act. And the 50 Hz MPC's plan, tracking a reference that turned at a
carrier's wall, traded 2-3 cm of height for its horizontal catch-up and drove the open fingers into the belt (160 N),
the reference it tracked staying above the floor. The governor bounds how fast the reference the QP tracks may come
down at each height:

- toward the TCP floor by a braking curve onto rest at the floor (``BRAKE_M_S2``);
- with a band, inside ``(low, high)`` at most ``speed_m_s`` (a guarded move: the force guard then stops the reference
  going on into a contact), above ``high`` by a braking curve onto that speed. The band costs time, which only a mode
  that keeps the hand over the moving object can afford: measured on pick at 0.2 m/s (seeds 1000-1019), open loop
  with the band grasped 0 of 20 (where the object was 0.15 s earlier; 16 of 20 without it, the closing gate kept),
  hybrid 18 of 20; on the reversal at 0.2 m/s (hybrid, seeds 1000-1049) the episodes over the contact-force limit
  were 27 without the band, 7 with it (picks 26, 28).

It limits the reference's own descent (the QP tracks it within a millimetre or two), with the allowed speed as the
velocity's floor and no downward acceleration while it governs; a reference going up, or coming down slower than
allowed, passes unchanged (the same arrays). It reads the task's geometry only. (Leading the TCP by one tick's
allowed descent instead took away the tracking's catch-up near the floor: open loop at 0.2 m/s grasped 18 % of 50.)
"""

from __future__ import annotations

import math

import numpy as np

#: the deceleration of the braking curves onto the band's speed and onto the floor, m/s^2 (the Panda's Cartesian
#: limit is 13 m/s^2)
BRAKE_M_S2 = 5.0


class DescentGovernor:
    """See the module. ``governed_ticks`` counts the ticks it slowed the reference."""

    def __init__(self, band_m: tuple[float, float] | None, speed_m_s: float, floor_m: float, dt_s: float) -> None:
        self.low_m, self.high_m = (np.inf, np.inf) if band_m is None else (float(z) for z in band_m)
        self.speed_m_s = float(speed_m_s)
        self.floor_m = float(floor_m)
        self.dt_s = float(dt_s)
        self.reset()

    def reset(self) -> None:
        self.z_m: float | None = None
        self.governed_ticks = 0

    def allowed_speed_m_s(self, z_m: float) -> float:
        """The fastest descent allowed at height ``z_m``, m/s."""
        s = math.sqrt(2.0 * BRAKE_M_S2 * max(z_m - self.floor_m, 0.0))
        if z_m > self.low_m:
            s = min(s, self.speed_m_s + math.sqrt(2.0 * BRAKE_M_S2 * max(z_m - self.high_m, 0.0)))
        return s

    def __call__(self, pos_m: np.ndarray, vel_m_s: np.ndarray,
                 acc_m_s2: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The reference (position m, velocity m/s, acceleration m/s^2) with its descent bounded."""
        z = float(pos_m[2])
        if self.z_m is None or z >= self.z_m:
            self.z_m = z
            return pos_m, vel_m_s, acc_m_s2
        top = self.z_m
        s = self.allowed_speed_m_s(top)
        z_min = max(top - s * self.dt_s, min(self.floor_m, top))  # the last step onto the floor ends on it
        if z >= z_min:
            self.z_m = z
            return pos_m, vel_m_s, acc_m_s2
        self.z_m = z_min
        self.governed_ticks += 1
        pos_m, vel_m_s, acc_m_s2 = pos_m.copy(), vel_m_s.copy(), acc_m_s2.copy()
        pos_m[2] = z_min
        vel_m_s[2] = max(vel_m_s[2], -s)
        acc_m_s2[2] = max(acc_m_s2[2], 0.0)
        return pos_m, vel_m_s, acc_m_s2
