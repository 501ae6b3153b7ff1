"""The values that travel between the control stages, one tick at a time: named, with units (no bare tuples).

The chain (``mmact_ctrl.control.controller``): the executed chunk's :class:`ReferenceSample` -> raised to the floor
-> Ruckig's :class:`SmoothedSample` -> (the MPC plan's :class:`TrackedReference`) -> the QP's task reference ->
:class:`TickOutput`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np


class ReferenceSample(NamedTuple):
    """The raw task-space reference at one instant (before smoothing): TCP position m, velocity m/s, rotation vector
    relative to the nominal grasp rad and its rate rad/s, gripper opening m."""

    pos_m: np.ndarray
    vel_m_s: np.ndarray
    rotvec_rad: np.ndarray
    rotvec_rate_rad_s: np.ndarray
    gripper_m: float


class SmoothedSample(NamedTuple):
    """The reference after Ruckig (or as it is, without): TCP position m, velocity m/s, acceleration m/s^2, rotation
    (3, 3), angular velocity rad/s and acceleration rad/s^2 (world frame), gripper opening m."""

    pos_m: np.ndarray
    vel_m_s: np.ndarray
    acc_m_s2: np.ndarray
    rot: np.ndarray
    ang_vel_rad_s: np.ndarray
    ang_acc_rad_s2: np.ndarray
    gripper_m: float


class TrackedReference(NamedTuple):
    """What the QP tracks at one tick: the position part (m, m/s, m/s^2) of the MPC plan or of the smoothed
    reference, the posture (7,) rad to pull the null space toward, and the smoothed reference it came from (its
    orientation and gripper, and its position for the log)."""

    pos_m: np.ndarray
    vel_m_s: np.ndarray
    acc_m_s2: np.ndarray
    q_post_rad: np.ndarray
    smoothed: SmoothedSample


@dataclass
class TickOutput:
    """What one control tick produced: the command, and what the safety monitor and the log need.

    Attributes:
        tau_nm (7,): the torque command, N*m.
        gripper_m: gripper opening command, m.
        ref_pos_m (3,): the task-space reference the tick tracked (before the MPC), m.
        ee_pos_m (3,): the TCP position (controller's model), m.
        ddq_cmd_rad_s2 (7,): the joint acceleration the command asks for in this state (``M^-1 (tau - h)``).
        tcp_vel_m_s (3,): the TCP linear velocity (controller's model), m/s.
    """

    tau_nm: np.ndarray
    gripper_m: float
    ref_pos_m: np.ndarray
    ee_pos_m: np.ndarray
    ddq_cmd_rad_s2: np.ndarray
    tcp_vel_m_s: np.ndarray


@dataclass(frozen=True)
class ControllerCounters:
    """What the controller survived in one episode (read once, by the runner, at its end).

    Attributes:
        watchdog_stops: braking stops started because no valid chunk covered the time.
        floor_clamps: reference samples raised to the TCP floor.
        plan_resyncs: MPC plans started from the measured state because the robot left the tracked one.
        mpc_bypass_ticks: ticks that tracked the smoothed reference directly (no good MPC plan covered them).
        qp_failures / qp_rescues / rate_clamps: the QP's fallbacks, DAQP rescues and torque-rate clamps.
        smoother_failures: Ruckig's failed steps.
        mpc_failures: failed or late MPC solves.
        mpc_solve_us: each MPC solve's wall time, us.
        gated_measurements: target measurements the estimator's gates refused, per gate (non-finite, frozen, outlier).
    """

    watchdog_stops: int = 0
    floor_clamps: int = 0
    plan_resyncs: int = 0
    mpc_bypass_ticks: int = 0
    qp_failures: int = 0
    qp_rescues: int = 0
    rate_clamps: int = 0
    smoother_failures: int = 0
    mpc_failures: int = 0
    mpc_solve_us: tuple[float, ...] = ()
    gated_measurements: dict = field(default_factory=dict)
