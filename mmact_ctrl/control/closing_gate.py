"""The closing gate (``StackConfig.close_below_m``): the gripper does not start closing while the hand is too high.

A chunk closes the gripper on its own clock, at the time it planned the hand to be down at the object. When the hand
is late coming down (it passes the objects' top at a guarded move's speed: ``mmact_ctrl.control.descent``), fingers
that close on the clock close above the object, and the closed hand then comes down on its top: measured on pick at
0.4 m/s, 85-111 N; on the reversal at 0.2 m/s (hybrid, 50 seeds) the band without the gate had 33 episodes over the
contact-force limit, with it 7. The gate holds a command to close open until the TCP is below ``close_below_m``; once
the gripper has started closing, it passes every command (a held object is not let go when the hand lifts). It reads
the TCP's height only, so it is the same in every mode. None (reach, insert): the chunk's command passes unchanged.

With ``stop_descent_m`` (``StackConfig.close_stops_descent_m``; the controller gives it, with the grasp height as
``close_below_m``, only to a mode that reads the object: ``StackConfig.close_below_reading_m``; pick sets both with
``--close-at-grasp``, off by default: it costs picks, README, Contact, point 14) the hand also stops coming down
once the fingers start closing: for as long as the gripper is commanded closed the reference may not go
lower than the TCP's height at the closing's start less ``stop_descent_m``. A pad that meets the object's side while
the hand still comes down drags it down by friction (the pads' friction is 2, the belt's 1): the belt's normal force
under the object grows with the pad's push, so the object cannot slide away from the pad, and the push builds up to
the arm's stiffness, a wedge. Read on pick, reversal 0.2 m/s (hybrid, fresh seeds 6050-6249; 5 of its 9 episodes
over the contact-force limit): the carrier turned while the fingers closed, the hand went on along the fingers' axis
at about 0.2 m/s and came down at 0.1-0.17 m/s past its grasp height (the MPC's plan overshooting it by 3 mm, the TCP
by 6 mm) as a pad met the cube; the force on the hand was as much up as along the axis (seed 6058: 20 N along, 22 N
up, 34 N). A hand at rest vertically pushes the object along the belt against its weight's friction only. Stopped
only during the hold, the held cube was pressed into the belt when the chunk's reference came down to its grasp
height after it: the stop lasts the closing. Stopped where the closing started 8 mm above the grasp height, the
fingers held the cube on its upper half, and it slid out of them on the lift (tuning seeds, jump: 4 picks lost):
hence the closing from the grasp height: the reference then stops 2 mm under it and the TCP about 3 mm under it
(jump 6046: down to 27.4 mm, then 28 mm while the pads close; the cube's centre is at 24.5 mm). Blind (open loop)
the later closing cost picks (0.4 m/s, tuning seeds: 12 -> 10 of 50), so a blind mode closes as by default.
"""

from __future__ import annotations

import numpy as np

from mmact_ctrl.control.chunk_stage import GRIPPER_OPEN_M

#: a command below this closes the fingers, m (any step down from open: a chunk's closing ramps through the
#: waypoints' interpolation, and a partial closing high above the object is the closing the gate holds back)
OPEN_FROM_M = GRIPPER_OPEN_M - 1e-3

#: once the gripper starts closing, the hand does not rise for this long, s: the Franka Hand's fingers close at 0.1
#: m/s each, 0.175 s from open onto a 4.5 cm cube (a chunk that lifts on its own clock, planned for a closing that
#: the gate held back, would otherwise lift open fingers)
HOLD_S = 0.2


class ClosingGate:
    """See the module. ``held_ticks`` counts the ticks a command to close was held open."""

    def __init__(self, close_below_m: float | None, dt_s: float = 0.001, stop_descent_m: float | None = None) -> None:
        self.close_below_m = close_below_m
        self.stop_descent_m = stop_descent_m
        self.hold_ticks = int(round(HOLD_S / dt_s))
        self.reset()

    def reset(self) -> None:
        self.closing = False
        self.held_ticks = 0
        self.closing_ticks = 0  # the ticks since the closing started (0 while open)
        self._hold_left = 0
        self._hold_z_m = np.inf
        self._stop_z_m = -np.inf  # the closing's lowest reference, m (``stop_descent_m``)
        self.stopped_ticks = 0  # the ticks the closing kept the reference from coming down

    def hold(self, pos_m: np.ndarray, vel_m_s: np.ndarray,
             acc_m_s2: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The reference kept from rising above its height at the closing's start for ``HOLD_S`` after it, and, with
        ``stop_descent_m``, from coming down under the closing's lowest height while the gripper is commanded closed
        (the same arrays when neither acts)."""
        stopped = self.closing and pos_m[2] < self._stop_z_m
        if stopped:
            self.stopped_ticks += 1
            pos_m, vel_m_s, acc_m_s2 = pos_m.copy(), vel_m_s.copy(), acc_m_s2.copy()
            pos_m[2] = self._stop_z_m
            vel_m_s[2] = max(vel_m_s[2], 0.0)
            acc_m_s2[2] = max(acc_m_s2[2], 0.0)
        if self._hold_left <= 0:
            return pos_m, vel_m_s, acc_m_s2
        self._hold_left -= 1
        if self._hold_z_m == np.inf:
            self._hold_z_m = float(pos_m[2])
        if pos_m[2] <= self._hold_z_m and vel_m_s[2] <= 0.0 and acc_m_s2[2] <= 0.0:
            return pos_m, vel_m_s, acc_m_s2
        if not stopped:  # the stop's copies are already this tick's own
            pos_m, vel_m_s, acc_m_s2 = pos_m.copy(), vel_m_s.copy(), acc_m_s2.copy()
        pos_m[2] = min(pos_m[2], self._hold_z_m)
        vel_m_s[2] = min(vel_m_s[2], 0.0)
        acc_m_s2[2] = min(acc_m_s2[2], 0.0)
        return pos_m, vel_m_s, acc_m_s2

    def __call__(self, gripper_cmd_m: float, tcp_z_m: float) -> float:
        """The gripper command to pass on (m), for the chunk's (or the reflex's) ``gripper_cmd_m`` and the TCP's
        height ``tcp_z_m`` now."""
        if self.close_below_m is None:
            return gripper_cmd_m
        if gripper_cmd_m >= OPEN_FROM_M:  # open: the next closing is gated again
            self.closing = False
            self.closing_ticks = 0
            return gripper_cmd_m
        if not self.closing and tcp_z_m > self.close_below_m:
            self.held_ticks += 1
            return GRIPPER_OPEN_M
        if not self.closing:  # the closing starts: the hand stays down while the fingers close
            self._hold_left, self._hold_z_m = self.hold_ticks, np.inf
            if self.stop_descent_m is not None:  # and stops coming down (a pad sliding down a side wedges it)
                self._stop_z_m = tcp_z_m - self.stop_descent_m
        self.closing = True
        self.closing_ticks += 1
        return gripper_cmd_m
