"""The contact-force check: the safety monitor's kind for a robot that touches things.

A Panda stops a motion whose estimated external force passes its collision thresholds (libfranka's
``setCollisionBehavior``, per Cartesian axis x, y, z, rx, ry, rz): libfranka's examples (``setDefaultBehavior``) set
20, 20, 20 N and 25, 25, 25 N m, lower and upper alike; franka_ros2's default robot behaviour sets 30 N lower and
40 N upper on the forces (25 / 35 N m on the torques). Here every tick's measured external wrench at the TCP
(``RobotState.wrench_ext``, libfranka's ``O_F_ext_hat_K``) is checked against one limit on the force's magnitude
(``StackConfig.contact_force_limit_n``, default 30 N) and the ticks over it are counted as ``contact_force``
violations, beside the command checks of ``controllers.safety``.
"""

from __future__ import annotations

import math

import numpy as np

#: the kind's name in ``EpisodeLog.safety_counts``
CONTACT_FORCE = "contact_force"


class ContactForceMonitor:
    """Counts the ticks whose external force is over ``limit_n`` and keeps the largest force seen.

    Args:
        limit_n: the force limit, N (> 0).
    """

    def __init__(self, limit_n: float = 30.0) -> None:
        if not (math.isfinite(limit_n) and limit_n > 0):
            raise ValueError(f"contact_force_limit_n must be a force > 0 N, got {limit_n!r}")
        self.limit_n = float(limit_n)
        self.reset()

    def reset(self) -> None:
        self.violations = 0
        self.peak_n = 0.0

    def check(self, wrench_ext: np.ndarray | None) -> bool:
        """One tick: whether the force of ``wrench_ext`` (6,) (force N, torque N m) is over the limit (counted);
        None (a world where nothing touches the robot) is never over it."""
        if wrench_ext is None:
            return False
        force_n = float(np.sqrt(wrench_ext[0] ** 2 + wrench_ext[1] ** 2 + wrench_ext[2] ** 2))
        self.peak_n = max(self.peak_n, force_n)
        over = force_n > self.limit_n
        self.violations += int(over)
        return over
