"""Compliance as one QP task (``StackConfig.compliance``, ``--compliance``): the TCP as a spring-damper about its
reference, stiff or soft per axis of the tool frame, whose force is capped.

Stiff tracking (``TcpPositionTask``: 400 1/s^2 on the error, saturated at 10 cm) asks the arm for whatever force
closes the error: a waypoint quantized a few millimetres into a surface becomes a push of up to about 100 N. The
impedance task asks for the acceleration that makes the TCP behave like a spring ``K`` (N/m, per tool axis) and a
damper on the robot's own task-space inertia ``Lambda = (J M^-1 J')^-1``: ``a_des = Lambda^-1 f`` with
``f = sat(Lambda a_ref + K e + D e_dot)``: the force that carries the reference's acceleration plus the spring-damper's,
scaled down to ``force_max_n`` where its magnitude exceeds it (``a_ref + Lambda^-1 sat(K e + D e_dot)`` capped only
the spring: a peg held on the chamfer while the hybrid layer's reference accelerated down was pushed with Lambda
a_ref = 26 N more, 31.5 N in all). Held still by a contact, the torque the QP sends (``M a_des + h``) makes the TCP
push with ``f``: never more than the cap,
which is how the contact-force limit is kept in the QP. The damping is ``2 zeta sqrt(K m)`` for a nominal ``m``.
It replaces the TCP position task (weighed 0 meanwhile) while the robot is in contact
(``TaskSpaceQP(contact_task=...)``, switched by ``mmact_ctrl.control.compliance_gate``): in free space the same cap is
all the force the arm may use to move its own inertia, and a pick's hand fell 5-8 cm under its reference. Orientation,
posture and the limits are unchanged.

``pressing_only`` (pick's ``--compliance``) caps only the force's push into the measured contact, along the contact
normal the QP is given each tick (``QPState.contact_normal``; the direction the world pushes the TCP): what keeps the
contact force under the limit is the push into the contact, and the rest of the force (along the contact, or lifting
off it) is left as asked. With the magnitude capped, an open hand that had hit the belt could not lift itself out
against the belt dragging its fingers (pick, 0.4 m/s, hybrid, seed 1041: 620 ticks over 30 N, 199 past the joint
position limits; with the push capped alone, 22.9 N at most).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controllers.qp.state import Objective, QPState
from controllers.qp.tasks import tracking_cost


@dataclass(frozen=True)
class ImpedanceTask:
    """Attributes:
        stiffness_n_m: spring per tool axis (x, y across and along the fingers' closing, z the approach), N/m.
        force_max_n: the cap on the spring-damper's force magnitude, N (the contact-force limit kept in the QP).
        damping_ratio: zeta of the damper (1 = critical for ``nominal_mass_kg``).
        nominal_mass_kg: the apparent mass the damping is tuned for, kg.
        weight: cost per (m/s^2)^2.
        pressing_only: cap only the force's component into the measured contact (``QPState.contact_normal``, the
            direction the world pushes the TCP) at ``force_max_n``; the rest of the force (sideways, or away from the
            contact) is the spring-damper's and the inertia's as asked. False: the magnitude is capped. Where no
            normal is given the magnitude is capped either way.
    """

    stiffness_n_m: tuple[float, float, float] = (500.0, 500.0, 800.0)
    force_max_n: float = 20.0
    damping_ratio: float = 1.0
    nominal_mass_kg: float = 3.0
    weight: float = 1.0
    pressing_only: bool = False

    def __post_init__(self) -> None:
        k = np.asarray(self.stiffness_n_m, dtype=float)
        if k.shape != (3,) or not np.all(np.isfinite(k)) or np.any(k <= 0):
            raise ValueError(f"ImpedanceTask.stiffness_n_m must be three stiffnesses > 0 N/m, got {self.stiffness_n_m!r}")
        for name in ("force_max_n", "damping_ratio", "nominal_mass_kg", "weight"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"ImpedanceTask.{name} must be a finite number > 0, got {v!r}")

    def gains(self) -> tuple[np.ndarray, np.ndarray]:
        """``(K, D)``, (3,) each: the spring per tool axis, N/m, and its damper ``2 zeta sqrt(K m)``, N s/m."""
        k = np.asarray(self.stiffness_n_m, dtype=float)
        return k, 2.0 * self.damping_ratio * np.sqrt(k * self.nominal_mass_kg)

    def spring_damper_n(self, state: QPState) -> np.ndarray:
        """The spring-damper's force (3,) on the TCP, world frame, N (uncapped)."""
        terms, ref = state.terms, state.ref
        rot = terms.rot  # tool -> world
        k, d = self.gains()
        e_tool = rot.T @ (ref.pos_m - terms.pos_m)
        ev_tool = rot.T @ (ref.vel_m_s - terms.vel[:3])
        return rot @ (k * e_tool + d * ev_tool)

    def force_n(self, state: QPState, lambda_inv: np.ndarray | None = None) -> np.ndarray:
        """The force (3,) the TCP is asked to exert, world frame, N: the reference's acceleration carried by the task-
        space inertia (``Lambda a_ref``) plus the spring-damper, its magnitude capped at ``force_max_n`` (with
        ``pressing_only`` and a measured contact normal: its push into the contact)."""
        if lambda_inv is None:
            lambda_inv = self._lambda_inv(state)
        f = np.linalg.solve(lambda_inv, state.ref.acc_m_s2) + self.spring_damper_n(state)
        normal = self.normal(state)
        if normal is not None:
            press = -float(f @ normal)
            return f + (press - self.force_max_n) * normal if press > self.force_max_n else f
        norm = float(np.linalg.norm(f))
        return f * (self.force_max_n / norm) if norm > self.force_max_n else f

    def normal(self, state: QPState) -> np.ndarray | None:
        """The contact normal the cap acts along (unit, world frame), or None: the magnitude is capped."""
        n = state.contact_normal
        return n if self.pressing_only and n is not None and np.any(n != 0.0) else None

    @staticmethod
    def _lambda_inv(state: QPState) -> np.ndarray:
        """``Lambda^-1 = J M^-1 J'`` over the TCP's linear rows, (3, 3)."""
        jp = state.terms.J[:3]
        return jp @ np.linalg.solve(state.terms.M, jp.T)

    def desired_acc(self, state: QPState) -> np.ndarray:
        """``Lambda^-1 sat(Lambda a_ref + f)``, m/s^2: ``a_ref + Lambda^-1 f`` wherever the cap does not bind."""
        lambda_inv = self._lambda_inv(state)
        return lambda_inv @ self.force_n(state, lambda_inv)

    def cost(self, state: QPState) -> Objective:
        t = state.terms
        return tracking_cost(t.J[:3], t.dJv[:3], self.desired_acc(state), self.weight)
