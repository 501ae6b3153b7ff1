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

With the fingers' measured opening a closing is also known to have missed before that time (``opening_tol_m``, the
open fingers' capture tolerance along their axis, the task's ``capture_tol_m``; ``beside_m``): the pads' inner faces
close in by half the opening's shrinking, so an object whose centre is off the fingers' axis by more than
``opening_tol_m`` less that can no longer pass between them; if it is then also off the TCP across the axis by more
than ``beside_m`` (an object's half-width and a finger's: beside the fingers, not between the pads) the closing
found nothing, and where it comes closer across the axis (the object's velocity less the TCP's) the correction can
only bring the fingers' side onto it. Read on the reversal at 0.2 m/s (hybrid,
fresh seeds 6050-6249, 7 of its 15 episodes over the contact-force limit): the carrier turned while the hand came
down, the fingers closed on the chunk's clock with the cube 36-64 mm across the fingers' axis, and the hybrid layer's
correction, catching up, swept the closing fingers (28-49 mm open, narrower than the cube with its offset along the
axis) into the cube's side at 0.2-0.3 m/s (30-98 N) before the 0.25 s had run out. An object that slid out between
the closing pads goes away across the axis, and a regrasp may still take it: tuning seed 6035, the cube out of the
pads at 30 mm across, and the next chunk's regrasp, with the hand still low, picked it; held up there, the hand lost
it.
"""

from __future__ import annotations

import math

import numpy as np

from mmact_ctrl.control.capture_gate import RISE_M_S  # the held reference rises at the capture gate's rate, m/s
from mmact_ctrl.control.chunk_stage import GRIPPER_OPEN_M
from mmact_ctrl.control.fingers import OPENING_CLOSES_M_S
#: an object whose estimate is farther than this from the TCP horizontally is not between the closed fingers, m (a
#: 4.5 cm cube held off-centre is within a centimetre or so; 2 mm sensing noise)
BETWEEN_XY_M = 0.02
#: an object beside the closing fingers comes closer across their axis faster than this, m/s (the impacts read came at
#: 0.2-0.3 m/s; a cube sliding out between the pads goes away)
APPROACH_M_S = 0.05
#: the verdict looks this far ahead at most, s: at a closing's start the correction that brings the hand to the object
#: is still speeding up (tuning seed 6035, a regrasp: 0.12 m/s across the axis at the closing's first tick, 0.27 m/s
#: on average over the 0.16 s it took to reach the cube, which the pads then held)
HORIZON_S = 0.1
#: a pad's edge meeting the object's side this far over its inner face pushes a light object aside, m: the regrasp of
#: tuning seed 6035 met the cube 1.5-3 mm over it at 1-5 N and held it; fresh seed 6219 met it 6 mm over it (30 N)
GLANCE_M = 0.003


class EmptyHandGate:
    """See the module. ``held_ticks`` counts the ticks it held the reference; ``missed`` the closings it caught."""

    def __init__(self, after_s: float, safe_z_m: float, dt_s: float, between_xy_m: float = BETWEEN_XY_M,
                 opening_tol_m: float | None = None, beside_m: float = 0.0) -> None:
        self.after_ticks = int(round(after_s / dt_s))
        self.opening_tol_m = None if opening_tol_m is None else float(opening_tol_m)
        self.beside_m = float(beside_m)
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

    def missed_on_opening(self, tcp_pos_m: np.ndarray, tcp_rot: np.ndarray, object_pos_m: np.ndarray,
                          opening_m: float | None, rel_vel_m_s: np.ndarray | None) -> bool:
        """Whether an object beside the closing fingers (off the TCP across their axis, the hand's x axis, by more
        than ``beside_m``) and coming closer across it (``rel_vel_m_s``, the object's velocity less the TCP's, at
        more than ``APPROACH_M_S``) will find them too narrow to pass between when it gets there: its centre then
        (at the same relative velocity) off the fingers' axis (the hand's y axis) by more than the capture tolerance
        less half the closing by then, and ``GLANCE_M`` more (from the measured ``opening_m``, closing freely on at
        ``OPENING_CLOSES_M_S``), and getting there within ``HORIZON_S``. False without a tolerance, an opening or a
        velocity."""
        if self.opening_tol_m is None or opening_m is None or rel_vel_m_s is None:
            return False
        dx, dy = float(object_pos_m[0] - tcp_pos_m[0]), float(object_pos_m[1] - tcp_pos_m[1])  # no array a tick
        b = dx * tcp_rot[0, 0] + dy * tcp_rot[1, 0]
        if abs(b) <= self.beside_m:
            return False
        vx, vy = float(rel_vel_m_s[0]), float(rel_vel_m_s[1])
        approach = -math.copysign(1.0, b) * (vx * tcp_rot[0, 0] + vy * tcp_rot[1, 0])
        if approach < APPROACH_M_S:  # still, or going away: the fingers' side is not on its way
            return False
        arrives_s = (abs(b) - self.beside_m) / approach  # the object's side at the fingers' then
        if arrives_s > HORIZON_S:  # too far ahead to tell: the correction is still speeding up
            return False
        opening_then_m = max(opening_m - OPENING_CLOSES_M_S * arrives_s, 0.0)  # the fingers close on meanwhile
        a_then = dx * tcp_rot[0, 1] + dy * tcp_rot[1, 1] + (vx * tcp_rot[0, 1] + vy * tcp_rot[1, 1]) * arrives_s
        return abs(a_then) > self.opening_tol_m - 0.5 * (GRIPPER_OPEN_M - opening_then_m) + GLANCE_M

    def __call__(self, pos_m: np.ndarray, vel_m_s: np.ndarray, acc_m_s2: np.ndarray, tcp_pos_m: np.ndarray,
                 object_pos_m: np.ndarray | None, closing_ticks: int, tcp_rot: np.ndarray | None = None,
                 opening_m: float | None = None,
                 rel_vel_m_s: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The reference (position m, velocity m/s, acceleration m/s^2), held over the TCP and rising while the
        closed hand is empty and low (the same arrays otherwise). ``closing_ticks``: the ticks since the gripper
        started closing (0: open); ``tcp_rot`` (3, 3) and ``opening_m`` (the fingers' measured opening, m; None:
        not measured) and ``rel_vel_m_s`` (the object's velocity less the TCP's, m/s; None: not known) for
        :meth:`missed_on_opening`."""
        if not self.active:
            if closing_ticks == 0 or object_pos_m is None or tcp_pos_m[2] >= self.safe_z_m:  # open, or up
                return pos_m, vel_m_s, acc_m_s2
            if closing_ticks < self.after_ticks:  # the fingers not yet past the object, unless they measure a miss
                if tcp_rot is None or not self.missed_on_opening(tcp_pos_m, tcp_rot, object_pos_m, opening_m,
                                                                 rel_vel_m_s):
                    return pos_m, vel_m_s, acc_m_s2
            elif math.hypot(object_pos_m[0] - tcp_pos_m[0], object_pos_m[1] - tcp_pos_m[1]) < self.between_xy_m:
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
