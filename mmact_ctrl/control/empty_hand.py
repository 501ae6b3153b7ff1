"""The empty-hand gate (``StackConfig.empty_hand_after_s``): a closing that found nothing does not sweep the closed
hand sideways among the objects, in a mode that reads the object.

A chunk plans its lift for a grasp that happened; when the fingers closed beside the object instead, the closed hand
is low among the objects, and the hybrid layer's correction goes on pulling it toward the object it missed: measured
on pick (reversal 0.2 m/s, hybrid, tuning seeds 6000-6049), a closed hand at the grasp height pushing the cube ahead
of it at 0.57 m/s, 35 N. The chunk's next plan reopens the hand and lifts it (up to a replan period later). The gate
does that part at once: once the gripper has been closing for ``after_s`` (the fingers' travel onto the object) with
the object's estimate not between the fingers (farther than ``between_xy_m`` from the TCP horizontally), the
reference keeps the TCP's horizontal position of that moment and rises to ``safe_z_m`` (the descent band's top) at
``RISE_M_S``; it lets go once the TCP is up there, and not before, even when the gripper opens meanwhile (the
fingers take 0.4 s to open: let go at the chunk's command to reopen, a hand was swept into the cube with its
fingers still nearly closed, 45 N, read on seed 1043 of the published reversal run); a closed hand that comes down
again is held again, where it is then. It reads the object, so it is a layer of the modes that do (hybrid); open
loop, blind, gets none.
"""

from __future__ import annotations

import math

import numpy as np

from mmact_ctrl.control.capture_gate import RISE_M_S  # the held reference rises at the capture gate's rate, m/s
#: an object whose estimate is farther than this from the TCP horizontally is not between the closed fingers, m (a
#: 4.5 cm cube held off-centre is within a centimetre or so; 2 mm sensing noise)
BETWEEN_XY_M = 0.02


class EmptyHandGate:
    """See the module. ``held_ticks`` counts the ticks it held the reference; ``missed`` the closings it caught."""

    def __init__(self, after_s: float, safe_z_m: float, dt_s: float, between_xy_m: float = BETWEEN_XY_M) -> None:
        self.after_ticks = int(round(after_s / dt_s))
        self.between_xy_m = float(between_xy_m)
        self.safe_z_m = float(safe_z_m)
        self.dt_s = float(dt_s)
        self.reset()

    def reset(self) -> None:
        self.active = False
        self.held_ticks = 0
        self.missed = 0
        self._xy_m = np.zeros(2)
        self._z_m = 0.0

    def __call__(self, pos_m: np.ndarray, vel_m_s: np.ndarray, acc_m_s2: np.ndarray, tcp_pos_m: np.ndarray,
                 object_pos_m: np.ndarray | None, closing_ticks: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The reference (position m, velocity m/s, acceleration m/s^2), held over the TCP and rising while the
        closed hand is empty and low (the same arrays otherwise). ``closing_ticks``: the ticks since the gripper
        started closing (0: open)."""
        if not self.active:
            if closing_ticks == 0 or closing_ticks < self.after_ticks:  # open, or the fingers not yet past the object
                return pos_m, vel_m_s, acc_m_s2
            if object_pos_m is None or tcp_pos_m[2] >= self.safe_z_m:
                return pos_m, vel_m_s, acc_m_s2
            if math.hypot(object_pos_m[0] - tcp_pos_m[0], object_pos_m[1] - tcp_pos_m[1]) < self.between_xy_m:
                return pos_m, vel_m_s, acc_m_s2
            self.active, self.missed = True, self.missed + 1
            self._xy_m = np.array(tcp_pos_m[:2], dtype=float)
            self._z_m = float(tcp_pos_m[2])
        if tcp_pos_m[2] >= self.safe_z_m:  # up: the chunk goes on (its next plan reopens the hand); should the closed
            self.active = False  # hand come down again, it is held again where it is then
            return pos_m, vel_m_s, acc_m_s2
        self.held_ticks += 1
        self._z_m = min(self._z_m + RISE_M_S * self.dt_s, self.safe_z_m)
        pos_m, vel_m_s, acc_m_s2 = pos_m.copy(), vel_m_s.copy(), acc_m_s2.copy()
        pos_m[:2] = self._xy_m
        vel_m_s[:2] = 0.0
        acc_m_s2[:2] = 0.0
        if pos_m[2] < self._z_m:
            pos_m[2] = self._z_m
            vel_m_s[2] = max(vel_m_s[2], RISE_M_S)
            acc_m_s2[2] = max(acc_m_s2[2], 0.0)
        return pos_m, vel_m_s, acc_m_s2
