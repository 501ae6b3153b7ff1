"""What travels into and out of the QP's parts: the reference, the state a task or limit reads, a task's cost and
a limit's rows."""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from controllers.robot_model import RobotTerms


@dataclass(frozen=True)
class TaskReference:
    """Task-space reference at one instant.

    Attributes:
        pos_m (3,), vel_m_s (3,), acc_m_s2 (3,): TCP position, velocity, acceleration, world frame.
        rot (3,3): desired TCP rotation; ang_vel_rad_s (3,), ang_acc_rad_s2 (3,) world frame.
        q_post_rad (7,): posture to pull the null space toward.
    """

    pos_m: np.ndarray
    vel_m_s: np.ndarray
    acc_m_s2: np.ndarray
    rot: np.ndarray
    ang_vel_rad_s: np.ndarray
    ang_acc_rad_s2: np.ndarray
    q_post_rad: np.ndarray


class QPState(NamedTuple):
    """What a task's cost and a limit's rows are computed from at one tick.

    Attributes:
        terms: the robot's terms (M, h, J, dJv, TCP pose and twist) at the measured state.
        q_rad, dq_rad_s: the measured joint state (7,).
        ref: the task-space reference.
        tau_last_nm: the last torque the robot received (7,), N*m (the rate limit is measured against it).
        ddq_last_rad_s2: the acceleration the last command asked for (7,) (the jerk limit is measured against it).
        contact_normal: the measured external force's direction at the TCP (3,), unit, world frame (the direction the
            world pushes the robot), or None: no contact measured (``TaskSpaceQP.set_contact``).
    """

    terms: RobotTerms
    q_rad: np.ndarray
    dq_rad_s: np.ndarray
    ref: TaskReference
    tau_last_nm: np.ndarray
    ddq_last_rad_s2: np.ndarray
    contact_normal: np.ndarray | None = None


class Objective(NamedTuple):
    """A task's cost over the joint accelerations ``x``: ``0.5 x' H x + c' x`` (plus a constant)."""

    H: np.ndarray
    c: np.ndarray


class Constraint(NamedTuple):
    """A limit's rows: ``lower <= A x <= upper`` over the joint accelerations ``x``; ``priority`` 0 is never relaxed
    (the robot's own conditions), a higher one is relaxed first when the rows cannot all hold."""

    A: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    priority: int
