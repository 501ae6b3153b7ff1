"""The descent governor (``StackConfig.descent_band_m``): the TCP floor as a braking curve, a guarded move where the
fingertips pass the objects' top (slow in a mode that reads the object, at a safe landing speed in one that does
not), and, where the hand is blind, the reference held near the measured TCP on the way down.

An open hand that lands on an object at the approach's speed is an impact: measured on pick at 0.4 m/s (the expert,
0.25 m/s at the fingertips' crossing of the cubes' top), 60-110 N on the robot, over the contact-force limit within
one or two ticks, before any reaction could act. And the 50 Hz MPC's plan, tracking a reference that turned at a
carrier's wall, traded 2-3 cm of height for its horizontal catch-up and drove the open fingers into the belt (160 N),
the reference it tracked staying above the floor. The governor bounds how fast the reference the QP tracks may come
down at each height:

- toward the TCP floor by a braking curve onto rest at the floor (``BRAKE_M_S2``);
- with a band, inside ``(low, high)`` at most ``speed_m_s`` (a guarded move: the force guard then stops the reference
  going on into a contact), above ``high`` by a braking curve onto that speed. In a mode that reads the object the
  band's speed is ``StackConfig.descent_speed_m_s``, slow, which only a mode that keeps the hand over the moving object
  can afford: measured on pick at 0.2 m/s (seeds 1000-1019), open loop with that band grasped 0 of 20 (where the
  object was 0.15 s earlier; 16 of 20 without it, the closing gate kept), hybrid 18 of 20; on the reversal at 0.2 m/s
  (hybrid, seeds 1000-1049) the episodes over the contact-force limit were 27 without the band, 7 with it (picks 26,
  28). A mode that does not read the object passes the band at ``StackConfig.landing_speed_m_s`` instead: the
  fastest landing that stays under the limit, with a margin (``scenarios.landing_floor``);
- in a mode that does not read the object, the reference never more than ``TCP_LEAD_S`` of the speed allowed at the
  TCP's height below the measured TCP, coming down no faster than that speed, the TCP's height judged where it will
  be ``TRACK_TAU_S`` later (``follow_tcp``). The reference's own descent is not the TCP's: a chunk that starts at the
  grasp height put the reference 10 cm below the TCP, and the tracking's pull (``kp_pos / kd_pos`` times the gap)
  drove the open hand down at 0.7 m/s, through its floor into the belt (pick at 0.4 m/s, open loop, tuning seed
  6001, 70 N); and a TCP lagging its braked reference still landed at 0.2 m/s (33 N, seed 6038 at 0.2 m/s).
  Measured on the tuning seeds (6000-6049, open loop, with the landing speed and the empty-grip gate), episodes over
  the limit / picks: linear 0.2 m/s 3 / 42 -> 0 / 41, 0.4 m/s 9 / 15 -> 6 / 12, reversal 9 / 1 -> 2 / 0; the landing
  speed alone changed nothing (the hand lags its reference and closes the gap at the approach's speed). In hybrid it
  cost picks (linear 0.2 m/s 45 -> 39 of 50, also when held only above the band: 39), so hybrid's descent is as it
  was measured before. While the robot touches something (``touching``: the measured force over the latch's
  threshold) the lead is the band's speed's, wherever the TCP is: an open finger resting on a cube's top with the TCP
  just under the band's lower edge, where the allowed speed jumps to the floor curve's, was pressed on by a 5 mm lead
  (open loop, 0.2 m/s, seed 1014, 30.8 N).

A reference going up, or coming down slower than allowed, passes unchanged (the same arrays). It reads the task's
geometry and the robot's own state only. (Leading the TCP by one tick's allowed descent, everywhere, took away the
tracking's catch-up near the floor: open loop at 0.2 m/s grasped 18 % of 50; the lead is ten ticks.)
"""

from __future__ import annotations

import math

import numpy as np

#: the deceleration of the braking curves onto the band's speed and onto the floor, m/s^2 (the Panda's Cartesian
#: limit is 13 m/s^2)
BRAKE_M_S2 = 5.0
#: the reference may lead the TCP's measured height downward by at most this long at the speed allowed at the TCP's
#: height, s (``kp_pos / kd_pos`` = 10/s: the tracking's pull then adds a tenth of that speed)
TCP_LEAD_S = 0.01
#: the tracking's time constant, s (``1 / kd_pos``): the TCP's speed is judged where it will be this much later
TRACK_TAU_S = 0.025
#: the step of the descent's integration in :meth:`DescentGovernor.lowest_z_m`, s
PREVIEW_STEP_S = 0.005


class DescentGovernor:
    """See the module. ``governed_ticks`` counts the ticks it slowed the reference."""

    def __init__(self, band_m: tuple[float, float] | None, speed_m_s: float, floor_m: float, dt_s: float,
                 follow_tcp: bool = False) -> None:
        self.low_m, self.high_m = (np.inf, np.inf) if band_m is None else (float(z) for z in band_m)
        #: whether the reference is also held near the measured TCP (``__call__``'s ``tcp_z_m``)
        self.follow_tcp = bool(follow_tcp)
        self.speed_m_s = float(speed_m_s)
        self.floor_m = float(floor_m)
        self.dt_s = float(dt_s)
        self.reset()

    def reset(self) -> None:
        self.z_m: float | None = None
        self.governed_ticks = 0
        #: the ticks the reference was held up to the TCP's lead
        self.tcp_governed_ticks = 0

    def allowed_speed_m_s(self, z_m: float) -> float:
        """The fastest descent allowed at height ``z_m``, m/s."""
        s = math.sqrt(2.0 * BRAKE_M_S2 * max(z_m - self.floor_m, 0.0))
        if z_m > self.low_m:
            s = min(s, self.speed_m_s + math.sqrt(2.0 * BRAKE_M_S2 * max(z_m - self.high_m, 0.0)))
        return s

    def lowest_z_m(self, delays_s: np.ndarray) -> np.ndarray | None:
        """The lowest heights (m) the reference can reach ``delays_s`` (increasing, s) from now, coming down from
        where it is now at the fastest descent allowed on the way; None before the first tick. The MPC's preview is
        held above them (:class:`~mmact_ctrl.control.plan_tracker.PlanTracker`): a plan that counts on a descent the
        governor will not allow trades the other axes for it (see ``docs/ARCHITECTURE.md``)."""
        if self.z_m is None:
            return None
        out = np.empty(len(delays_s))
        z, t_s = self.z_m, 0.0
        for i, delay_s in enumerate(delays_s):
            while t_s < delay_s - 1e-12:
                h = min(PREVIEW_STEP_S, delay_s - t_s)
                z = max(z - self.allowed_speed_m_s(z) * h, min(self.floor_m, z))
                t_s += h
            out[i] = z
        return out

    def __call__(self, pos_m: np.ndarray, vel_m_s: np.ndarray, acc_m_s2: np.ndarray,
                 tcp_z_m: float | None = None, tcp_vz_m_s: float = 0.0,
                 touching: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The reference (position m, velocity m/s, acceleration m/s^2) with its descent bounded; following the TCP,
        with its measured height ``tcp_z_m`` (m) and vertical velocity ``tcp_vz_m_s`` (m/s), also never more than
        ``TCP_LEAD_S`` of the speed allowed at the TCP's height below it, and, while the robot ``touching`` something
        (the measured force over the latch's threshold), of no more than the band's speed."""
        z = float(pos_m[2])
        if self.z_m is None or z >= self.z_m:
            out = pos_m, vel_m_s, acc_m_s2
        else:
            top = self.z_m
            s = self.allowed_speed_m_s(top)
            z_min = max(top - s * self.dt_s, min(self.floor_m, top))  # the last step onto the floor ends on it
            if z >= z_min:
                out = pos_m, vel_m_s, acc_m_s2
            else:
                z = z_min
                self.governed_ticks += 1
                out = self._bounded(pos_m, vel_m_s, acc_m_s2, z_min, s)
        if tcp_z_m is not None and self.follow_tcp:
            # the speed allowed where the TCP will be once the tracking has caught up (its time constant)
            s_tcp = self.allowed_speed_m_s(tcp_z_m + min(tcp_vz_m_s, 0.0) * TRACK_TAU_S)
            if touching:  # resting on something: a landing's lead, not the floor curve's under the band
                s_tcp = min(s_tcp, self.speed_m_s)
            z_lead = tcp_z_m - s_tcp * TCP_LEAD_S
            if (z < z_lead and z_lead > self.floor_m) or out[1][2] < -s_tcp:
                z = max(z, z_lead) if z_lead > self.floor_m else z
                self.tcp_governed_ticks += 1
                out = self._bounded(*out, z, s_tcp)
        self.z_m = z
        return out

    @staticmethod
    def _bounded(pos_m: np.ndarray, vel_m_s: np.ndarray, acc_m_s2: np.ndarray, z_m: float,
                 speed_m_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Copies of the reference held at height ``z_m``, coming down at most at ``speed_m_s``, not accelerating
        downward."""
        pos_m, vel_m_s, acc_m_s2 = pos_m.copy(), vel_m_s.copy(), acc_m_s2.copy()
        pos_m[2] = z_m
        vel_m_s[2] = max(vel_m_s[2], -speed_m_s)
        acc_m_s2[2] = max(acc_m_s2[2], 0.0)
        return pos_m, vel_m_s, acc_m_s2
