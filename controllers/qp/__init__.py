"""The task-space inverse-dynamics QP, as tasks and limits (mink's manner).

- :mod:`.config`: :class:`QPConfig` (TCP gains, posture gains, limit margins, solver settings);
- :mod:`.state`: :class:`TaskReference`, :class:`QPState` (what tasks and limits read), :class:`Objective`,
  :class:`Constraint`;
- :mod:`.tasks`: :class:`TcpPositionTask`, :class:`TcpOrientationTask`, :class:`PostureTask`,
  :class:`RegularisationTask` (each gives ``(H, c)``);
- :mod:`.limits`: :class:`EffortRateLimit`, :class:`AccelerationJerkLimit`, :class:`ViabilityLimit` (each gives
  ``(A, lower, upper)`` and a priority);
- :mod:`.solve`: :func:`solve` (stack and solve; DAQP's ladder relaxes the limits of priority >= k);
- :mod:`.task_space_qp`: :class:`TaskSpaceQP`, the 1 kHz QP (the default set on a compiled fast path).
"""

from controllers.qp.config import REALTIME_MAX_ITER, LimitMargins, PostureGains, QPConfig, SolverSettings, TcpGains
from controllers.qp.limits import AccelerationJerkLimit, EffortRateLimit, Limit, ViabilityLimit
from controllers.qp.solve import Problem, build_problem, solve, solve_problem
from controllers.qp.state import Constraint, Objective, QPState, TaskReference
from controllers.qp.task_space_qp import TaskSpaceQP, commanded_accel, default_limits, default_tasks
from controllers.qp.tasks import PostureTask, RegularisationTask, Task, TcpOrientationTask, TcpPositionTask

__all__ = ["REALTIME_MAX_ITER", "AccelerationJerkLimit", "Constraint", "EffortRateLimit", "Limit", "LimitMargins",
           "Objective", "PostureGains", "PostureTask", "Problem", "QPConfig", "QPState", "RegularisationTask",
           "SolverSettings", "Task", "TaskReference", "TaskSpaceQP", "TcpGains", "TcpOrientationTask",
           "TcpPositionTask", "ViabilityLimit", "build_problem", "commanded_accel", "default_limits", "default_tasks",
           "solve", "solve_problem"]
