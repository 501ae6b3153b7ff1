"""Ruckig jerk-limited smoothing of the task-space reference (online, one step per control tick).

The smoother is a trajectory generator with its own state (position, velocity,
acceleration): every tick it re-plans, time-optimally and within velocity /
acceleration / jerk limits, from its current state to the latest reference state
(position and velocity), and advances one control period. Position and orientation
(a rotation vector relative to the nominal grasp) run in two Ruckig instances so each
moves along a straight line (time-synchronized axes).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from ruckig import InputParameter, OutputParameter, Result, Ruckig


@dataclass(frozen=True)
class SmootherConfig:
    """Task-space kinematic limits of the smoothed reference.

    Attributes:
        dt_s: control period, s.
        v_max_m_s, a_max_m_s2, j_max_m_s3: TCP translation limits.
        w_max_rad_s, dw_max_rad_s2, ddw_max_rad_s3: orientation (rotation vector) limits.
    """

    dt_s: float = 0.001
    v_max_m_s: float = 1.0
    a_max_m_s2: float = 6.0
    j_max_m_s3: float = 80.0
    w_max_rad_s: float = 2.0
    dw_max_rad_s2: float = 10.0
    ddw_max_rad_s3: float = 100.0

    def __post_init__(self) -> None:
        for name in self.__dataclass_fields__:
            if not getattr(self, name) > 0:
                raise ValueError(f"SmootherConfig.{name} must be > 0, got {getattr(self, name)}")


class _Axis3:
    """One 3-DoF Ruckig instance with its input/output buffers."""

    def __init__(self, dt_s: float, v_max: float, a_max: float, j_max: float) -> None:
        self.otg = Ruckig(3, dt_s)
        self.inp = InputParameter(3)
        self.out = OutputParameter(3)
        self.inp.max_velocity = [v_max] * 3
        self.inp.max_acceleration = [a_max] * 3
        self.inp.max_jerk = [j_max] * 3
        self.v_cap = 0.95 * v_max
        self.failures = 0

    def reset(self, pos: np.ndarray) -> None:
        self.inp.current_position = list(map(float, pos))
        self.inp.current_velocity = [0.0, 0.0, 0.0]
        self.inp.current_acceleration = [0.0, 0.0, 0.0]

    def step(self, target_pos: np.ndarray, target_vel: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        inp = self.inp
        inp.target_position = target_pos.tolist()
        inp.target_velocity = np.clip(target_vel, -self.v_cap, self.v_cap).tolist()
        result = self.otg.update(inp, self.out)
        if result in (Result.Working, Result.Finished):
            self.out.pass_to_input(inp)
        else:  # keep the previous state, coast to a stop is not possible without a plan: hold
            self.failures += 1
            inp.current_velocity = [0.0, 0.0, 0.0]
            inp.current_acceleration = [0.0, 0.0, 0.0]
        return (
            np.array(inp.current_position),
            np.array(inp.current_velocity),
            np.array(inp.current_acceleration),
        )


class TaskSpaceSmoother:
    """Jerk-limited online filter of a TCP reference (position m, rotation vector rad)."""

    def __init__(self, config: SmootherConfig = SmootherConfig()) -> None:
        self.config = config
        self._pos = _Axis3(config.dt_s, config.v_max_m_s, config.a_max_m_s2, config.j_max_m_s3)
        self._rot = _Axis3(config.dt_s, config.w_max_rad_s, config.dw_max_rad_s2, config.ddw_max_rad_s3)

    @property
    def failures(self) -> int:
        return self._pos.failures + self._rot.failures

    def reset(self, pos_m: np.ndarray, rotvec_rad: np.ndarray) -> None:
        """Start at rest at the given pose."""
        self._pos.reset(pos_m)
        self._rot.reset(rotvec_rad)

    def step(
        self, pos_m: np.ndarray, vel_m_s: np.ndarray, rotvec_rad: np.ndarray, ang_vel_rad_s: np.ndarray | None = None
    ) -> tuple[np.ndarray, ...]:
        """Advance one period toward the reference; returns (pos, vel, acc, rotvec, ang_vel, ang_acc)."""
        p, v, a = self._pos.step(np.asarray(pos_m, dtype=float), np.asarray(vel_m_s, dtype=float))
        w_target = np.zeros(3) if ang_vel_rad_s is None else np.asarray(ang_vel_rad_s, dtype=float)
        r, w, dw = self._rot.step(np.asarray(rotvec_rad, dtype=float), w_target)
        return p, v, a, r, w, dw
