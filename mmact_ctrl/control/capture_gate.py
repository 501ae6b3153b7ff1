"""The capture gate (``StackConfig.capture_tol_m``): the open fingers go down past the object's top only where the
object will pass between them, in a mode that reads the object.

Pick's remaining contact-force violations after the guarded descent (``mmact_ctrl.control.descent``) were fingers
at the grasp height beside the object rather than around it: the hand, still catching up after a carrier's turn,
came down on the chunk's clock 2-3 cm from the cube, and then a finger struck the cube's side as the hand swept on
(37-52 N within one tick of the first touch, at 0.16 m/s relative), or a finger closed onto the cube's top edge
and wedged it against the belt (43 N). Measured on the reversal at 0.2 m/s (hybrid, seeds 1000-1049): 5 of its 6
episodes over the contact-force limit were of this kind. No reaction to the measured force can stop an impact that reaches
the limit in one tick: the hand must not be there.

The fingers open along the hand's y axis. An object whose centre is off the TCP by ``a`` along that axis and ``b``
across it touches an open finger at its own height when ``|a| > capture_tol_m`` (its side meets a pad) and
``|b| < clear_m`` (within the fingers' width); with ``|a|`` within the tolerance it passes between the pads whatever
``b`` (the hand catching up from behind scoops it). While the estimate of the object (the filter's, predicted to
now) is in that zone, the reference may not be under ``safe_z_m`` (the descent band's top: the fingertips 4 mm above
the objects' top): a reference under it rises at ``RISE_M_S``; once the estimate is out of the zone by
``HYSTERESIS_M`` the gate lets go, and the descent governor brings the hand down through the band at its guarded
speed. Before the first measurement it lets every reference pass (nothing is known to avoid). It reads the object,
so it is a layer of the modes that do (hybrid); open loop, blind, gets none.

The tolerance is the geometry's, without a margin: the grasps that succeed came down with the cube 12-18 mm off the
axis (the hand lagged it), and the pad is met at 19 mm. That lag was the MPC's plan trading the other axes for a
descent the governor would not allow; since the preview is held above what the governor allows (README, Contact,
point 10) the hand comes down 1-4 mm off, and a 15 mm tolerance neither cost nor bought anything on the tuning seeds
(reversal, hybrid: 3 episodes over the limit and 37 picks of 50 either way). Measured (hybrid, seeds 1000-1049, 1 Hz, 200 ms; episodes
over the contact-force limit / picks, without -> with the gate at 18.5 mm): linear 0.2 m/s 0/46 -> 0/45, 0.4 m/s
6/23 -> 2/23, reversal 6/28 -> 3/29, jump 6/34 -> 5/34 (four of the five a finger on the other cube, which the gate
does not see; with the carrier jumping both cubes, as the pick world now does, 1/39). With a margin it cost picks: 12 mm took 10 of 28 on the reversal, 15 mm 5 of 46 at 0.2 m/s; checking the
offset 50 and 100 ms ahead at the estimated relative velocity took 13 of 46 at 0.2 m/s (the velocity estimate is
noisy).
"""

from __future__ import annotations

import numpy as np

#: the gate lets go once the object is this much closer to the fingers' axis than the tolerance, m (no chatter at
#: the edge under 2 mm sensing noise)
HYSTERESIS_M = 0.003
#: how fast a reference under the safe height is raised, m/s (24 mm, from the grasp height to the safe one, in 0.16 s)
RISE_M_S = 0.15


class CaptureGate:
    """See the module. ``raised_ticks`` counts the ticks it held the reference up."""

    def __init__(self, capture_tol_m: float, clear_m: float, safe_z_m: float, dt_s: float) -> None:
        self.capture_tol_m = float(capture_tol_m)
        self.clear_m = float(clear_m)
        self.safe_z_m = float(safe_z_m)
        self.dt_s = float(dt_s)
        self.reset()

    def reset(self) -> None:
        self.closed = False  # whether the gate holds the hand up now
        self.raised_ticks = 0
        self._z_m = -np.inf  # the raised reference's height now, m

    def off_axis_m(self, tcp_pos_m: np.ndarray, tcp_rot: np.ndarray, object_pos_m: np.ndarray) -> float:
        """The object's centre off the TCP along the fingers' axis (the hand's y axis), m."""
        d = np.asarray(object_pos_m, dtype=float) - tcp_pos_m
        y = tcp_rot[:, 1]
        return float(d[0] * y[0] + d[1] * y[1])

    def danger(self, a_m: float, b_m: float) -> bool:
        """Whether an object off the TCP by ``a_m`` along the fingers' axis and ``b_m`` across it would touch an open
        finger at the object's height: not between the pads, and not clear of the fingers' width."""
        return abs(a_m) > self.capture_tol_m and abs(b_m) < self.clear_m

    def __call__(self, pos_m: np.ndarray, vel_m_s: np.ndarray, acc_m_s2: np.ndarray, tcp_pos_m: np.ndarray,
                 tcp_rot: np.ndarray, object_pos_m: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The reference (position m, velocity m/s, acceleration m/s^2), kept at or rising to the safe height while
        the object would touch a finger (the same arrays when the gate is open)."""
        if object_pos_m is None:
            return pos_m, vel_m_s, acc_m_s2
        dx, dy = float(object_pos_m[0] - tcp_pos_m[0]), float(object_pos_m[1] - tcp_pos_m[1])  # no array a tick
        a = dx * tcp_rot[0, 1] + dy * tcp_rot[1, 1]
        b = dx * tcp_rot[0, 0] + dy * tcp_rot[1, 0]
        slack = -HYSTERESIS_M if self.closed else 0.0  # let go only well clear of the edge
        hit = self.danger(abs(a) - slack, abs(b) + slack)
        if hit and not self.closed:
            self.closed, self._z_m = True, float(pos_m[2])
        elif not hit and self.closed:
            self.closed, self._z_m = False, -np.inf
        if not self.closed or pos_m[2] >= self.safe_z_m:
            return pos_m, vel_m_s, acc_m_s2
        rising = self._z_m < self.safe_z_m
        self._z_m = min(max(self._z_m, float(pos_m[2])) + (RISE_M_S * self.dt_s if rising else 0.0), self.safe_z_m)
        if pos_m[2] >= self._z_m:
            return pos_m, vel_m_s, acc_m_s2
        self.raised_ticks += 1
        pos_m, vel_m_s, acc_m_s2 = pos_m.copy(), vel_m_s.copy(), acc_m_s2.copy()
        pos_m[2] = self._z_m
        vel_m_s[2] = max(vel_m_s[2], RISE_M_S if rising else 0.0)
        acc_m_s2[2] = max(acc_m_s2[2], 0.0)
        return pos_m, vel_m_s, acc_m_s2
