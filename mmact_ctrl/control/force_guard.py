"""The contact-force guard: the safety layer that keeps the measured contact force under the limit, in every mode.

A position-tracking arm pressed against something it cannot pass (a peg caught on a chamfer, a cube pushed into the
belt) builds force at its stiffness times the reference's overshoot: a reference descending at 4 cm/s into a jam adds
about 40 N a second. libfranka stops the arm when its collision thresholds are crossed (``setCollisionBehavior``),
so a command that drives the force over ``StackConfig.contact_force_limit_n`` is one the robot would reject. The guard
is an admittance on the reference, from the measured external force at the TCP (``RobotState.wrench_ext``, libfranka's
``O_F_ext_hat_K``): above ``GUARD_FRACTION`` of the limit the reference yields along the measured force at
``yield_m_s_per_n`` per newton over (``StackConfig.guard_yield_m_s_per_n``: ``YIELD_M_S_PER_N`` unless the task's
settings ask for a faster one); below it the yield relaxes back with ``RELAX_TAU_S``. In a guarded descent
(``StackConfig.descent_band_m``: pick), while the force is over the threshold the reference also stops advancing into
the contact (:meth:`ContactForceGuard.halt`): its velocity and acceleration toward the obstacle (against the measured
force) are removed, as a guarded move stops on contact; without that the tracking's damping alone (``kd_pos`` 40/s
times a 0.25 m/s descent: 10 m/s^2) pressed on. Insert keeps the guard without the halt, as its figures were made (with
the halt its 1 mm, ``--compliance`` hybrid run had one episode of 50 at 37 N). A world that measures no wrench (reach)
never moves it: the reference passes unchanged, bit for bit.
"""

from __future__ import annotations

import numpy as np

#: the guard acts above this fraction of the contact-force limit
GUARD_FRACTION = 0.5
#: how fast the reference yields per newton over the guard's threshold by default, m/s/N (arm stiffness about
#: 1000 N/m: a loop time constant near 0.1 s). A task may ask for a faster rate (``StackConfig.guard_yield_m_s_per_n``):
#: at this one an open finger pressed on an object that a conveyor drags along was dragged with it for 0.3 s, and the
#: arm wound up past its joint velocity and position limits (the task's settings say where and how it was measured)
YIELD_M_S_PER_N = 0.01
#: the yield relaxes back with this time constant once the force is under the threshold, s
RELAX_TAU_S = 0.5
#: the largest yield, m
MAX_YIELD_M = 0.05


class ContactForceGuard:
    """See the module. ``offset_m`` is the reference's current yield (world frame, m)."""

    def __init__(self, limit_n: float, dt_s: float, floor_m: float = -np.inf,
                 yield_m_s_per_n: float = YIELD_M_S_PER_N) -> None:
        self.threshold_n = GUARD_FRACTION * float(limit_n)
        self.dt_s = float(dt_s)
        #: how fast the reference yields per newton over the threshold, m/s/N
        self.yield_m_s_per_n = float(yield_m_s_per_n)
        #: the yield never takes the reference below the TCP floor (``StackConfig.tcp_floor_m``), m: a force that
        #: pulls the hand down (a held cube dragged by the belt) must not drive it into the table
        self.floor_m = float(floor_m)
        self.reset()

    def reset(self) -> None:
        self.offset_m = np.zeros(3)
        self.active = False
        self.yield_ticks = 0
        #: the measured force's direction while it is over the threshold (unit, world frame), else None
        self.normal: np.ndarray | None = None

    def update(self, force_n: np.ndarray | None) -> None:
        """One tick with the measured external force on the robot at the TCP (N, world frame; None: not measured)."""
        if force_n is None:
            return
        f = np.asarray(force_n, dtype=float)[:3]
        norm = float(np.linalg.norm(f))
        if norm > self.threshold_n:
            self.normal = f / norm
            self.offset_m = self.offset_m + self.dt_s * self.yield_m_s_per_n * (norm - self.threshold_n) * self.normal
            n = float(np.linalg.norm(self.offset_m))
            if n > MAX_YIELD_M:
                self.offset_m *= MAX_YIELD_M / n
            self.active = True
            self.yield_ticks += 1
        elif self.active:
            self.normal = None
            self.offset_m = self.offset_m * (1.0 - self.dt_s / RELAX_TAU_S)
            if float(np.linalg.norm(self.offset_m)) < 1e-6:
                self.offset_m, self.active = np.zeros(3), False

    def apply(self, pos_m: np.ndarray) -> np.ndarray:
        """The reference position with the yield, never below the floor (``pos_m`` itself while the guard is idle)."""
        if not self.active:
            return pos_m
        out = pos_m + self.offset_m
        out[2] = max(out[2], min(self.floor_m, pos_m[2]))
        return out

    def halt(self, vel_m_s: np.ndarray, acc_m_s2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The reference's velocity and acceleration without their components into the contact (against the
        measured force) while the force is over the threshold; both unchanged (the same arrays) otherwise."""
        n = self.normal
        if n is None:
            return vel_m_s, acc_m_s2
        into_v, into_a = float(vel_m_s @ n), float(acc_m_s2 @ n)
        if into_v < 0.0:
            vel_m_s = vel_m_s - into_v * n
        if into_a < 0.0:
            acc_m_s2 = acc_m_s2 - into_a * n
        return vel_m_s, acc_m_s2
