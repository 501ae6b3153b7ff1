"""The small protocol through which the stack knows the world (implemented in ``scenarios``)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np


@dataclass(frozen=True)
class RobotState:
    """Measured robot state at time ``t_s``.

    Attributes:
        t_s: simulation time, s.
        q_rad: arm joint positions (7,), rad.
        dq_rad_s: arm joint velocities (7,), rad/s.
        gripper_m: gripper opening (sum of both finger joints), m.
        ee_pos_m: measured TCP position (3,), world frame, m (for metrics; controllers use their own FK).
        wrench_ext: the external wrench on the robot at the TCP (6,): force N and torque N m, world frame (a real
            Panda reports it as ``O_F_ext_hat_K``); None where nothing can touch the robot (the reach scenes).
        gripper_cmd_m: the opening the gripper is being driven to now, m (a gripper squeezing an object is driven
            below its measured opening: holding the measured opening would let go); None where not reported.
    """

    t_s: float
    q_rad: np.ndarray
    dq_rad_s: np.ndarray
    gripper_m: float
    ee_pos_m: np.ndarray
    wrench_ext: np.ndarray | None = None
    gripper_cmd_m: float | None = None

    def gripper_hold_m(self) -> float:
        """The gripper command that keeps the gripper as it is: its current command where reported, else the measured
        opening, m."""
        return self.gripper_m if self.gripper_cmd_m is None else self.gripper_cmd_m


class World(Protocol):
    """A robot with a moving target: simulated (``scenarios``) or, in principle, real."""

    #: physics step, s.
    dt_s: float
    #: the instruction of the current episode ("" if none).
    instruction: str

    def reset(self, seed: int) -> RobotState:
        """Start a new episode (robot at home, target motion drawn from ``seed``)."""
        ...

    def state(self) -> RobotState:
        """Current measured robot state."""
        ...

    def step(self, tau_nm: np.ndarray, gripper_m: float) -> None:
        """Apply arm torques (7,) N*m and a gripper opening target (m), advance one ``dt_s``."""
        ...

    def target_pos_m(self) -> np.ndarray:
        """Ground-truth position of the instructed target now (what a camera frame shows)."""
        ...

    def measure_target(self) -> np.ndarray | None:
        """One perception measurement of the target (noisy), or None when it is missed (dropout)."""
        ...

    def render(self) -> np.ndarray:
        """Camera frame(s) ``(V, H, W, 3)`` uint8."""
        ...

    def target_jump_times_s(self) -> tuple[float, ...]:
        """Times at which the target teleported this episode (empty unless the motion jumps)."""
        ...

    def target_change_times_s(self) -> tuple[float, ...]:
        """Times (s) at which the target's course changes abruptly this episode: teleports, velocity
        flips, turns, set-offs from rest (``scenarios.world.targets``); wall bounces do not count."""
        ...
