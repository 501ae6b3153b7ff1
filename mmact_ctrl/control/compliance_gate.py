"""The compliance gate (``--compliance``): the impedance where the robot is in contact, stiff tracking in free space.

The impedance task (``controllers.qp.impedance``) makes the TCP a soft spring-damper whose force is capped at 2/3 of
the contact-force limit: in contact that is what keeps the force under the limit. In free space the same cap is the
most force the arm may use to move its own inertia, and a soft spring is slow: measured on pick (``--compliance``,
open loop, seeds 1000-1049), an open hand descending at 0.3-0.5 m/s when the chunk's reference turned back up fell
5-8 cm under that reference onto the belt (about 2 m/s^2 of braking is all 20 N buys the arm), was dragged by it for
seconds, and in 10 of 250 episodes the arm went past its joint position or velocity limits (up to 2,416 ticks a
run), with contact forces to 460 N. So the QP tracks stiffly until a contact is measured (the external force at the
TCP over ``threshold_n``, the chunk's latch), switches the position task for the impedance
(:meth:`controllers.qp.TaskSpaceQP.set_contact`), and switches back once the force has stayed under the threshold for
``HOLD_S``, so a contact that chatters at its threshold does not switch the tasks tick by tick. A world that measures
no wrench (reach) is never in contact: its QP stays stiff.
"""

from __future__ import annotations

#: the impedance stays on this long after the measured force has fallen under the threshold, s
HOLD_S = 0.1


class ComplianceGate:
    """See the module. ``in_contact``: the impedance's turn this tick; ``switches``: how often it changed (episode)."""

    def __init__(self, threshold_n: float, dt_s: float, hold_s: float = HOLD_S) -> None:
        if not (threshold_n > 0 and dt_s > 0 and hold_s >= 0):
            raise ValueError(f"ComplianceGate needs threshold_n > 0, dt_s > 0 and hold_s >= 0; got {threshold_n!r}, "
                             f"{dt_s!r}, {hold_s!r}")
        self.threshold_n = float(threshold_n)
        self.hold_ticks = int(round(hold_s / dt_s))
        self.reset()

    def reset(self) -> None:
        self.in_contact = False
        self.switches = 0
        self._free_ticks = self.hold_ticks + 1  # ticks since the force was last over the threshold (free at the start)

    def update(self, force_n: float) -> bool:
        """One tick with the measured external force's magnitude at the TCP, N; returns ``in_contact``."""
        self._free_ticks = 0 if force_n > self.threshold_n else min(self._free_ticks + 1, self.hold_ticks + 1)
        in_contact = self._free_ticks <= self.hold_ticks
        if in_contact != self.in_contact:
            self.in_contact = in_contact
            self.switches += 1
        return in_contact
