"""The empty-grip gate (``StackConfig.empty_grip_below_m``): in a mode that does not read the object, fingers that
closed on nothing lift the hand out from among the objects at once.

A mode that does not read the object closes where its chunk says the object will be. When the object is not there,
the fingers close past any object's width, and the closed hand, low beside the object, goes on along the chunk's
course until the chunk's next plan reopens and lifts it. Measured on pick (linear 0.4 m/s, open loop, tuning seeds
6000-6049, with the descent governor's landing speed): the hand slowing at the end of its chunk with the cube 3 cm
behind it, and the cube, carried on at 0.4 m/s, striking the closed fingers (31-48 N, 2 of the 8 episodes over the
contact-force limit). The gripper's measured opening is the robot's own sense (the Franka Hand's ``width``): once
the gripper has been commanded closed and the fingers are closer than ``below_m``, nothing is between them. The
reference then rises from the TCP's height at ``RISE_M_S`` to ``safe_z_m`` (the descent band's top: the fingertips
over the objects), keeping the chunk's horizontal course (holding the hand where it is would stop it in front of a
carried object); it lets go once the TCP is up there. A mode that reads the object has the empty-hand gate
(``mmact_ctrl.control.empty_hand``) instead.
"""

from __future__ import annotations

import numpy as np

#: the held reference rises at this speed, m/s (a closed hand low beside a carried object; up and away from
#: everything, so no contact-force risk)
RISE_M_S = 0.3


class EmptyGripGate:
    """See the module. ``held_ticks`` counts the ticks it raised the reference; ``missed`` the empty closings."""

    def __init__(self, below_m: float, safe_z_m: float, dt_s: float) -> None:
        self.below_m = float(below_m)
        self.safe_z_m = float(safe_z_m)
        self.dt_s = float(dt_s)
        self.reset()

    def reset(self) -> None:
        self.active = False
        self.held_ticks = 0
        self.missed = 0
        self._z_m = 0.0

    def __call__(self, pos_m: np.ndarray, vel_m_s: np.ndarray, acc_m_s2: np.ndarray, tcp_z_m: float,
                 gripper_m: float | None, closing_ticks: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The reference (position m, velocity m/s, acceleration m/s^2), rising while the closed hand is empty and
        low (the same arrays otherwise). ``gripper_m``: the fingers' measured opening (None: not measured);
        ``closing_ticks``: the ticks since the gripper was commanded closed (0: open)."""
        if tcp_z_m >= self.safe_z_m:  # up (or never down): the chunk goes on
            self.active = False
            return pos_m, vel_m_s, acc_m_s2
        if not self.active:
            if closing_ticks == 0 or gripper_m is None or gripper_m >= self.below_m:
                return pos_m, vel_m_s, acc_m_s2
            self.active, self.missed = True, self.missed + 1
            self._z_m = float(tcp_z_m)
        self.held_ticks += 1
        self._z_m = min(self._z_m + RISE_M_S * self.dt_s, self.safe_z_m)
        if pos_m[2] >= self._z_m:
            return pos_m, vel_m_s, acc_m_s2
        pos_m, vel_m_s, acc_m_s2 = pos_m.copy(), vel_m_s.copy(), acc_m_s2.copy()
        pos_m[2] = self._z_m
        vel_m_s[2] = max(vel_m_s[2], RISE_M_S)
        acc_m_s2[2] = max(acc_m_s2[2], 0.0)
        return pos_m, vel_m_s, acc_m_s2
