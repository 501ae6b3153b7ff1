"""What a contact task counts while an episode runs, one step at a time (a few comparisons a step), and reports at
its end: the success predicate and the task's figures."""

from __future__ import annotations

import math

import numpy as np

#: a cube this far above its resting height is off the carrier (grasped or falling), m
OFF_CARRIER_M = 0.01
#: a gripper command below this is a closing one, m
CLOSED_BELOW_M = 0.06


class PickProgress:
    """The pick task's predicate and figures.

    Args:
        lift_m: how far above the carrier the instructed cube must be lifted, m.
        hold_s: for how long, s.
        rest_z_m: a cube's centre height at rest on the carrier, m.
        dt_s: the step, s.
    """

    def __init__(self, lift_m: float, hold_s: float, rest_z_m: float, dt_s: float) -> None:
        self.lift_m, self.hold_s, self.rest_z_m, self.dt_s = lift_m, hold_s, rest_z_m, dt_s
        self.reset()

    def reset(self, target_index: int = 0) -> None:
        self.target_index = target_index
        self.held_s = 0.0  # how long the instructed cube has been lifted enough, without a break
        self.success_s = math.nan
        self.grasp_s = math.nan
        self.speed_at_grasp_m_s = math.nan
        self.closings = 0
        self.drops = 0
        self.others_lifted = False
        self.peak_force_n = 0.0
        self._off = False
        self._last_cmd = 1.0

    def update(self, t_s: float, cube_z_m: np.ndarray, gripper_cmd_m: float, carrier_speed_m_s: float,
               force_n: float) -> None:
        """One step at ``t_s``: the cubes' centre heights, the gripper command, the carrier's speed, the contact force
        on the robot."""
        if self._last_cmd >= CLOSED_BELOW_M > gripper_cmd_m:
            self.closings += 1
        self._last_cmd = gripper_cmd_m
        self.peak_force_n = max(self.peak_force_n, force_n)
        height = cube_z_m - self.rest_z_m
        mine = float(height[self.target_index])
        off = mine > OFF_CARRIER_M
        if off and not self._off and math.isnan(self.grasp_s):
            self.grasp_s, self.speed_at_grasp_m_s = t_s, carrier_speed_m_s
        if self._off and mine < 0.003:  # it was off the carrier and is back on it: dropped
            self.drops += 1
        self._off = off if (off or mine < 0.003) else self._off
        self.others_lifted |= bool(np.any(np.delete(height, self.target_index) > OFF_CARRIER_M))
        self.held_s = self.held_s + self.dt_s if mine >= self.lift_m else 0.0
        if self.held_s >= self.hold_s - 1e-9 and math.isnan(self.success_s):
            self.success_s = t_s

    def report(self, target_index: int | None = None) -> dict:
        """The figures: success, time to grasp, closings, drops, wrong object, speed at the grasp, peak force."""
        return {"task": "pick", "success": not math.isnan(self.success_s), "time_to_grasp_s": self.grasp_s,
                "time_to_success_s": self.success_s, "closings": self.closings, "drops": self.drops,
                "wrong_object": self.others_lifted, "object_speed_at_grasp_m_s": self.speed_at_grasp_m_s,
                "peak_contact_force_n": self.peak_force_n}
