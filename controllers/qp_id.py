"""The task-space inverse-dynamics QP: kept at this path for its importers; the code lives in ``controllers.qp``
(tasks, limits, one solve function, the 1 kHz fast path)."""

from controllers.qp import (REALTIME_MAX_ITER, QPConfig, SolverSettings, TaskReference, TaskSpaceQP, TcpGains,
                            commanded_accel)

__all__ = ["REALTIME_MAX_ITER", "QPConfig", "SolverSettings", "TaskReference", "TaskSpaceQP", "TcpGains",
           "commanded_accel"]
