"""The QP's tasks, as mink writes them: each has gains and a weight checked at construction, and gives its cost
over the joint accelerations ``x`` at one tick, ``0.5 x' H x + c' x`` (:class:`~controllers.qp.state.Objective`).

A task that tracks a desired acceleration ``a_des`` of some quantity with Jacobian ``J`` (and drift ``dJv``) costs
``0.5 w ||J x + dJv - a_des||^2``: ``H = w J'J``, ``c = w J' (dJv - a_des)``. A new task is one new class with a
``cost(state)`` method (``tests/test_qp_tasks.py`` adds one in a few lines).

The default set (TCP position, TCP orientation, posture, regularisation) is also assembled by one compiled kernel
(``controllers.tick_kernels.assemble_qp``, the 1 kHz fast path); ``tests/test_fast_paths.py`` holds the two equal.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from controllers.qp.state import Objective, QPState
from controllers.rotations import orientation_error


class Task(Protocol):
    """Anything with a cost over the joint accelerations at one tick."""

    def cost(self, state: QPState) -> Objective:
        ...


def _check(owner: str, **values: float) -> None:
    for name, v in values.items():
        if not (np.isfinite(v) and v >= 0):
            raise ValueError(f"{owner}.{name} must be a finite number >= 0, got {v!r}")


def tracking_cost(J: np.ndarray, drift: np.ndarray, a_des: np.ndarray, weight: float) -> Objective:
    """The cost ``0.5 w ||J x + drift - a_des||^2`` as ``(H, c)``."""
    WJ = J * weight
    return Objective(J.T @ WJ, (drift - a_des) @ WJ)


@dataclass(frozen=True)
class TcpPositionTask:
    """Track the TCP position reference: PD on the error (saturated at ``pos_err_max_m``) toward a velocity capped at
    ``tcp_vel_cap_m_s``, with velocity and acceleration feed-forward.

    Attributes:
        kp, kd: gains, 1/s^2 and 1/s; weight: cost per (m/s^2)^2; pos_err_max_m: m; tcp_vel_cap_m_s: m/s.
    """

    kp: float = 400.0
    kd: float = 40.0
    weight: float = 1.0
    pos_err_max_m: float = 0.1
    tcp_vel_cap_m_s: float = 1.4

    def __post_init__(self) -> None:
        _check("TcpPositionTask", kp=self.kp, kd=self.kd, weight=self.weight)
        if not (self.kd > 0 and self.pos_err_max_m > 0 and self.tcp_vel_cap_m_s > 0):
            raise ValueError(f"TcpPositionTask: kd, pos_err_max_m and tcp_vel_cap_m_s must be > 0, got {self.kd}, "
                             f"{self.pos_err_max_m}, {self.tcp_vel_cap_m_s}")

    def desired_acc(self, state: QPState) -> np.ndarray:
        """The TCP acceleration (3,) m/s^2 the task asks for."""
        terms, ref = state.terms, state.ref
        e_pos = ref.pos_m - terms.pos_m
        e_norm = float(np.linalg.norm(e_pos))
        if e_norm > self.pos_err_max_m:
            e_pos = e_pos * (self.pos_err_max_m / e_norm)
        ref_vel, ref_acc = ref.vel_m_s, ref.acc_m_s2
        v_des = ref_vel + (self.kp / self.kd) * e_pos  # the TCP velocity the PD term steers toward
        v_norm = float(np.linalg.norm(v_des))
        if v_norm > self.tcp_vel_cap_m_s:
            scale = self.tcp_vel_cap_m_s / v_norm
            ref_vel = v_des * scale - (self.kp / self.kd) * e_pos
            ref_acc = ref_acc * scale
        return ref_acc + self.kp * e_pos + self.kd * (ref_vel - terms.vel[:3])

    def cost(self, state: QPState) -> Objective:
        t = state.terms
        return tracking_cost(t.J[:3], t.dJv[:3], self.desired_acc(state), self.weight)


@dataclass(frozen=True)
class TcpOrientationTask:
    """Track the TCP orientation reference: PD on the world-frame rotation error, with angular velocity and
    acceleration feed-forward.

    Attributes:
        kp, kd: gains, 1/s^2 and 1/s; weight: cost per (rad/s^2)^2.
    """

    kp: float = 300.0
    kd: float = 35.0
    weight: float = 0.3

    def __post_init__(self) -> None:
        _check("TcpOrientationTask", kp=self.kp, kd=self.kd, weight=self.weight)

    def desired_acc(self, state: QPState) -> np.ndarray:
        """The TCP angular acceleration (3,) rad/s^2 the task asks for."""
        terms, ref = state.terms, state.ref
        e_rot = orientation_error(ref.rot, terms.rot)
        return ref.ang_acc_rad_s2 + self.kp * e_rot + self.kd * (ref.ang_vel_rad_s - terms.vel[3:])

    def cost(self, state: QPState) -> Objective:
        t = state.terms
        return tracking_cost(t.J[3:], t.dJv[3:], self.desired_acc(state), self.weight)


@dataclass(frozen=True)
class PostureTask:
    """Pull the joints toward the reference posture (``TaskReference.q_post_rad``): in the null space of the TCP tasks,
    by their weights.

    Attributes:
        kp, kd: gains, 1/s^2 and 1/s; weight: cost per (rad/s^2)^2.
    """

    kp: float = 25.0
    kd: float = 10.0
    weight: float = 1e-3

    def __post_init__(self) -> None:
        _check("PostureTask", kp=self.kp, kd=self.kd, weight=self.weight)

    def cost(self, state: QPState) -> Objective:
        ddq_post = self.kp * (state.ref.q_post_rad - state.q_rad) - self.kd * state.dq_rad_s
        return Objective(np.eye(len(ddq_post)) * self.weight, -self.weight * ddq_post)


@dataclass(frozen=True)
class RegularisationTask:
    """``0.5 w ||x||^2``: keeps the QP strictly convex (the 7-DoF arm has one redundant direction per TCP task)."""

    weight: float = 1e-6

    def __post_init__(self) -> None:
        _check("RegularisationTask", weight=self.weight)

    def cost(self, state: QPState) -> Objective:
        n = len(state.q_rad)
        return Objective(np.eye(n) * self.weight, np.zeros(n))


#: the kinds of task the compiled kernel assembles, in its order
DEFAULT_TASK_TYPES = (TcpPositionTask, TcpOrientationTask, PostureTask, RegularisationTask)
