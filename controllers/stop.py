"""A stop that the robot can follow: the task-space reference decelerates to rest within jerk limits, then holds.

Used by the stale-chunk watchdog (MoveIt Servo's ``incoming_command_timeout`` -> smooth halt): when no valid
chunk covers the present, the reference is not left to jump to the last waypoint or to freeze with a velocity
step; it brakes from the position and velocity it has now to zero velocity and zero acceleration within the
smoother's acceleration and jerk limits (Ruckig's velocity interface, computed once, offline), then holds.

Position and orientation (a rotation vector) stop in two 3-DoF Ruckig trajectories with synchronized axes;
the gripper command is held.
"""

from __future__ import annotations

import numpy as np
from ruckig import ControlInterface, InputParameter, Result, Ruckig, Synchronization, Trajectory


def _brake(pos: np.ndarray, vel: np.ndarray, a_max: float, j_max: float) -> Trajectory | None:
    """Ruckig trajectory from (pos, vel, acc=0) to zero velocity and acceleration (None: already at rest)."""
    if not np.any(np.abs(vel) > 1e-9):
        return None
    inp = InputParameter(3)
    inp.control_interface = ControlInterface.Velocity
    inp.synchronization = Synchronization.Time
    inp.current_position = [float(x) for x in pos]
    inp.current_velocity = [float(x) for x in vel]
    inp.current_acceleration = [0.0, 0.0, 0.0]
    inp.target_velocity = [0.0, 0.0, 0.0]
    inp.target_acceleration = [0.0, 0.0, 0.0]
    inp.max_velocity = [1e3] * 3  # unused by the velocity interface, required by the API
    inp.max_acceleration = [float(a_max)] * 3
    inp.max_jerk = [float(j_max)] * 3
    traj = Trajectory(3)
    if Ruckig(3).calculate(inp, traj) not in (Result.Working, Result.Finished):  # pragma: no cover - cannot fail here
        return None
    return traj


class StopTrajectory:
    """Braking reference that starts at ``t_start_s`` from ``action`` (7,: pos, rotvec, gripper) moving at ``rate``
    (7,) per s, and reaches rest within ``a_max_m_s2``/``j_max_m_s3`` (position) and ``dw_max_rad_s2``/
    ``ddw_max_rad_s3`` (orientation). Same sampling interface as a chunk reference."""

    def __init__(self, t_start_s: float, action: np.ndarray, rate: np.ndarray, a_max_m_s2: float, j_max_m_s3: float,
                 dw_max_rad_s2: float, ddw_max_rad_s3: float) -> None:
        action = np.asarray(action, dtype=np.float64)
        rate = np.asarray(rate, dtype=np.float64)
        if action.shape != (7,) or rate.shape != (7,) or not (np.all(np.isfinite(action)) and np.all(np.isfinite(rate))):
            raise ValueError(f"StopTrajectory needs a finite (7,) action and rate, got {action!r}, {rate!r}")
        self.t_start_s = float(t_start_s)
        self._start = action.copy()
        self._parts = ((slice(0, 3), _brake(action[:3], rate[:3], a_max_m_s2, j_max_m_s3)),
                       (slice(3, 6), _brake(action[3:6], rate[3:6], dw_max_rad_s2, ddw_max_rad_s3)))
        self._rest = action.copy()
        for sl, traj in self._parts:
            if traj is not None:
                self._rest[sl] = traj.at_time(traj.duration)[0]
        self.duration_s = max((traj.duration for _, traj in self._parts if traj is not None), default=0.0)
        self.t_last_s = float("inf")  # it covers every time from its start on

    @property
    def rest_action(self) -> np.ndarray:
        """Where the reference comes to rest (7,)."""
        return self._rest.copy()

    def sample(self, t_s: float) -> tuple[np.ndarray, np.ndarray]:
        """(action (7,), action rate (7,) per s) at ``t_s``: braking, then at rest."""
        tau = t_s - self.t_start_s
        if tau >= self.duration_s:
            return self._rest, np.zeros(7)
        action, rate = self._start.copy(), np.zeros(7)
        tau = max(tau, 0.0)
        for sl, traj in self._parts:
            if traj is None:
                continue
            if tau >= traj.duration:
                action[sl] = self._rest[sl]
            else:
                p, v, _ = traj.at_time(tau)
                action[sl], rate[sl] = p, v
        return action, rate

    def sample_positions(self, times_s: np.ndarray) -> np.ndarray:
        """Positions (N, 3) at many times."""
        return np.array([self.sample(float(t))[0][:3] for t in np.asarray(times_s, dtype=float)]).reshape(-1, 3)
