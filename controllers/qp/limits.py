"""The QP's limits, as mink writes them: each builds its rows ``lower <= A x <= upper`` over the joint accelerations
at one tick (:class:`~controllers.qp.state.Constraint`) and carries a priority: when the rows cannot all hold (a
state the torque rate does not let the controller leave in one tick), the limits of the highest priority are relaxed
first (``controllers.qp.solve``), and priority 0, the robot's own conditions, never.

- :class:`EffortRateLimit` (priority 0): ``|tau| <= tau_max`` and ``|tau - tau_last| <= dtau`` on ``tau = M x + h``,
  the Panda's one necessary condition in torque control beyond finite values;
- :class:`AccelerationJerkLimit` (priority 1): ``|x| <= a_max`` intersected with ``x_last +- j_max dt`` (the commanded
  acceleration's jerk, backward Euler);
- :class:`ViabilityLimit` (priority 2): the velocity after one step, and braking to rest before the position limits
  (``controllers.limits.JointAccelerationBounds``, with the rate-limited jerk).

A new limit (the next issue's contact force) is one new class with ``rows(state)`` and a ``priority``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from controllers.limits import JointAccelerationBounds
from controllers.qp.state import Constraint, QPState
from controllers.tick_kernels import jerk_box, rate_box


class Limit(Protocol):
    """Anything that builds rows over the joint accelerations at one tick, with a priority (0: never relaxed)."""

    priority: int

    def rows(self, state: QPState) -> Constraint:
        ...


def effective_jerk_rad_s3(M: np.ndarray, ddq_step_rad_s2: np.ndarray, dtau_step_nm: float, dt_s: float) -> np.ndarray:
    """How fast each joint's commanded acceleration can change, rad/s^3 (``tick_kernels.effective_jerk``)."""
    return np.minimum(ddq_step_rad_s2, 0.5 * dtau_step_nm / np.diag(M)) / dt_s


@dataclass(frozen=True)
class EffortRateLimit:
    """Effort and torque rate on ``tau = M x + h``: within ``tau_lim_nm`` and within ``dtau_step_nm`` of the last
    torque the robot received (the rate always wins over the effort bound).

    Attributes:
        tau_lim_nm (7,): the effort limit the QP may use, N*m; dtau_step_nm: the torque change allowed per step, N*m.
    """

    tau_lim_nm: np.ndarray
    dtau_step_nm: float
    priority: int = 0

    def rows(self, state: QPState) -> Constraint:
        n = len(state.q_rad)
        lo, hi = np.empty(n), np.empty(n)
        rate_box(state.tau_last_nm, self.tau_lim_nm, self.dtau_step_nm, lo, hi)
        h = state.terms.h
        return Constraint(state.terms.M, lo - h, hi - h, self.priority)


@dataclass(frozen=True)
class AccelerationJerkLimit:
    """``|x| <= a_max`` intersected with ``x_last +- ddq_step`` (the nearest point of the jerk box when they do not
    meet). Attributes: a_max_rad_s2 (7,); ddq_step_rad_s2 (7,): the jerk limit's step per tick."""

    a_max_rad_s2: np.ndarray
    ddq_step_rad_s2: np.ndarray
    priority: int = 1

    def box(self, ddq_last_rad_s2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        lo, hi = -self.a_max_rad_s2.copy(), self.a_max_rad_s2.copy()
        jerk_box(ddq_last_rad_s2, self.ddq_step_rad_s2, lo, hi)
        return lo, hi

    def rows(self, state: QPState) -> Constraint:
        lo, hi = self.box(state.ddq_last_rad_s2)
        return Constraint(np.eye(len(lo)), lo, hi, self.priority)


@dataclass(frozen=True)
class ViabilityLimit:
    """The velocity after one step within its limit, and braking to rest before the position limits still possible,
    with the acceleration ramped at the rate-limited jerk (``JointAccelerationBounds``).

    Attributes:
        bounds: the precomputed joint acceleration bounds; ddq_step_rad_s2 (7,), dtau_step_nm, dt_s: for the
        effective jerk (:func:`effective_jerk_rad_s3`)."""

    bounds: JointAccelerationBounds
    ddq_step_rad_s2: np.ndarray
    dtau_step_nm: float
    dt_s: float
    priority: int = 2

    def bounds_at(self, state: QPState) -> tuple[np.ndarray, np.ndarray]:
        j_eff = effective_jerk_rad_s3(state.terms.M, self.ddq_step_rad_s2, self.dtau_step_nm, self.dt_s)
        return self.bounds(state.q_rad, state.dq_rad_s, j_eff)

    def rows(self, state: QPState) -> Constraint:
        lo, hi = self.bounds_at(state)
        return Constraint(np.eye(len(lo)), lo, hi, self.priority)


@dataclass(frozen=True)
class DefaultLimits:
    """The three limits of every tick, as the compiled kernel merges them: the effort/rate rows on ``M x``, and one
    box on ``x`` (the viability bounds intersected with the jerk box)."""

    effort_rate: EffortRateLimit
    accel_jerk: AccelerationJerkLimit
    viability: ViabilityLimit
    all: tuple = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "all", (self.effort_rate, self.accel_jerk, self.viability))

    def merged(self, state: QPState) -> tuple[np.ndarray, np.ndarray]:
        """``(lower, upper)`` (14,) of ``lower <= [M; I] x <= upper``: the kernel's rows, in numpy (its reference)."""
        torque = self.effort_rate.rows(state)
        lb, ub = self.viability.bounds_at(state)
        jerk_box(state.ddq_last_rad_s2, self.accel_jerk.ddq_step_rad_s2, lb, ub)
        return np.concatenate([torque.lower, lb]), np.concatenate([torque.upper, ub])
