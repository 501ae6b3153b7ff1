"""What the insert task counts while an episode runs (a few comparisons a step) and reports at its end: the success
predicate (seated at least 20 mm) and the task's figures."""

from __future__ import annotations

import math

import numpy as np

#: a jam: the peg in contact with the fixture, above the seat, not descending faster than this for this long
JAM_SPEED_M_S, JAM_S = 0.002, 0.3


class InsertProgress:
    """The insert task's predicate and figures.

    Args:
        seat_m: how deep the peg's bottom must go below the hole's mouth, m (20 mm).
        hole_half_m: half the hole's width, m (the peg's axis must be inside it to count as in the hole).
        dt_s: the step, s.
    """

    def __init__(self, seat_m: float, hole_half_m: float, dt_s: float) -> None:
        self.seat_m, self.hole_half_m, self.dt_s = seat_m, hole_half_m, dt_s
        self.reset(np.zeros(3))

    def reset(self, peg_in_tcp_m: np.ndarray) -> None:
        """A new episode; ``peg_in_tcp_m``: the peg's bottom relative to the TCP at the start (its slip is measured from
        there)."""
        self.peg_in_tcp0 = np.asarray(peg_in_tcp_m, dtype=float).copy()
        self.seat_s = math.nan
        self.depth_m = -math.inf
        self.lateral_at_contact_m = math.nan
        self.jams = 0
        self.peak_force_n = 0.0
        self.slip_m = 0.0
        self._stuck_s = 0.0
        self._jammed = False
        self._last_z = math.nan

    def update(self, t_s: float, peg_bottom_m: np.ndarray, peg_in_tcp_m: np.ndarray, mouth_m: np.ndarray,
               touching: bool, force_n: float) -> None:
        """One step at ``t_s``: the peg's bottom centre (world), the same relative to the TCP, the hole's mouth centre
        (world), whether the peg touches the fixture, the contact force on the robot."""
        self.peak_force_n = max(self.peak_force_n, force_n)
        self.slip_m = max(self.slip_m, float(np.linalg.norm(peg_in_tcp_m - self.peg_in_tcp0)))
        lateral = float(np.hypot(*(peg_bottom_m[:2] - mouth_m[:2])))
        if touching and math.isnan(self.lateral_at_contact_m):
            self.lateral_at_contact_m = lateral
        depth = float(mouth_m[2] - peg_bottom_m[2])
        inside = max(abs(peg_bottom_m[0] - mouth_m[0]), abs(peg_bottom_m[1] - mouth_m[1])) < self.hole_half_m
        if inside:
            self.depth_m = max(self.depth_m, depth)
        if inside and depth >= self.seat_m and math.isnan(self.seat_s):
            self.seat_s = t_s
        descending = not math.isnan(self._last_z) and (self._last_z - peg_bottom_m[2]) / self.dt_s > JAM_SPEED_M_S
        self._last_z = float(peg_bottom_m[2])
        stuck = touching and math.isnan(self.seat_s) and not descending and depth > -0.005
        self._stuck_s = self._stuck_s + self.dt_s if stuck else 0.0
        if self._stuck_s >= JAM_S and not self._jammed:
            self.jams += 1
        self._jammed = self._stuck_s >= JAM_S

    def report(self) -> dict:
        """The figures: success, time to seat, the depth reached, lateral error at first contact, jams, peak force,
        peg slip in the fingers."""
        return {"task": "insert", "success": not math.isnan(self.seat_s), "time_to_seat_s": self.seat_s,
                "depth_m": self.depth_m if math.isfinite(self.depth_m) else math.nan,
                "lateral_error_at_contact_m": self.lateral_at_contact_m, "jams": self.jams,
                "peak_contact_force_n": self.peak_force_n, "peg_slip_m": self.slip_m}
