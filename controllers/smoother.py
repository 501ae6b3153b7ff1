"""Ruckig jerk-limited smoothing of the task-space reference (online, one step per control tick).

Two ways to use Ruckig online, selected by ``SmootherConfig.relative``:

- ``relative=False`` ("chase"): a trajectory generator with its own state re-plans every
  tick, time-optimally within velocity / acceleration / jerk limits, from its state to the
  latest reference state (position and velocity). Fine for a reference that stands still;
  for a *moving* reference it overshoots and oscillates, because each time-optimal
  (bang-bang) plan assumes the target state stays where it is now.
- ``relative=True`` (default): the smoothed reference is ``ref(t) + d(t)``. Wherever the raw
  reference is discontinuous (a new chunk, a kink between waypoints, a retargeting step)
  the jump in position and velocity is absorbed into the offset ``d``, and Ruckig brings
  ``d`` back to zero within the velocity / acceleration / jerk limits. The smoothed reference
  has continuous position and velocity and jerk-limited corrections, and follows a smoothly
  moving reference with no lag. Only the part of a step's change that a reference accelerating within the
  limits could not make in one step (``SmootherConfig.pass_through``) is absorbed: the smooth acceleration of a
  curving or decelerating reference (a circle, an estimate turning after a bounce) passes through instead of
  being taken back to zero as an offset velocity, which lagged (circle) and overshot (after a bounce). Measured on the linear 0.2 m/s target: final error 22 mm
  (chase) vs a few mm (relative).

Position and orientation (a rotation vector relative to the nominal grasp) run in two
3-DoF Ruckig instances with time-synchronized axes, so a correction moves along a line.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from ruckig import InputParameter, OutputParameter, Result, Ruckig, RuckigError

from controllers.tick_kernels import absorb_jump


@dataclass(frozen=True)
class SmootherConfig:
    """Task-space kinematic limits of the smoothed reference.

    Attributes:
        dt_s: control period, s.
        v_max_m_s, a_max_m_s2, j_max_m_s3: TCP translation limits.
        w_max_rad_s, dw_max_rad_s2, ddw_max_rad_s3: orientation (rotation vector) limits.
    relative: smooth the discontinuities of the reference (True) or chase it (False); see the module doc.
    pass_through: relative mode: the part of a step's change of the reference that a reference accelerating at
        ``pass_through * a_max`` could make in one step (velocity ``a dt``, position ``a dt^2 / 2``) is the
        reference's own motion and passes through; only the excess is absorbed. 0 absorbs every change.
    """

    dt_s: float = 0.001
    v_max_m_s: float = 1.0
    a_max_m_s2: float = 6.0
    j_max_m_s3: float = 80.0
    w_max_rad_s: float = 2.0
    dw_max_rad_s2: float = 10.0
    ddw_max_rad_s3: float = 100.0
    relative: bool = True
    pass_through: float = 1.0

    def __post_init__(self) -> None:
        if not self.pass_through >= 0.0:
            raise ValueError(f"SmootherConfig.pass_through must be >= 0, got {self.pass_through}")
        for name in self.__dataclass_fields__:
            if name not in ("relative", "pass_through") and not getattr(self, name) > 0:
                raise ValueError(f"SmootherConfig.{name} must be > 0, got {getattr(self, name)}")


class _Axis3:
    """One 3-DoF Ruckig instance with its input/output buffers."""

    def __init__(self, dt_s: float, v_max: float, a_max: float, j_max: float, pass_through: float = 0.0) -> None:
        self.otg = Ruckig(3, dt_s)
        self.pass_vel = pass_through * a_max * dt_s
        self.pass_pos = 0.5 * pass_through * a_max * dt_s * dt_s
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
        self.dt_s = self.otg.delta_time
        self.prev_ref = np.asarray(pos, dtype=float).copy()
        self.prev_vel = np.zeros(3)
        self._zeros = np.zeros(3)  # never written in place
        self.offset, self.offset_vel, self.offset_acc = self._zeros, self._zeros, self._zeros
        self.inp.target_position = [0.0, 0.0, 0.0]
        self.inp.target_velocity = [0.0, 0.0, 0.0]
        self.inp.target_acceleration = [0.0, 0.0, 0.0]

    def step_relative(self, ref: np.ndarray, ref_vel: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Absorb the reference's jumps into the offset, then let Ruckig take the offset to zero."""
        offset, offset_vel = np.empty(3), np.empty(3)
        # offset - (ref - prev_ref - prev_vel dt), offset_vel - (ref_vel - prev_vel), each beyond what passes
        # through, and whether any is left
        active = absorb_jump(self.offset, self.offset_vel, self.offset_acc, ref, ref_vel, self.prev_ref, self.prev_vel,
                             self.dt_s, self.pass_pos, self.pass_vel, offset, offset_vel)
        self.prev_ref, self.prev_vel = ref, ref_vel
        if not active:
            # nothing to smooth (and Ruckig's profile search is ill-posed at an exact zero offset)
            self.offset, self.offset_vel, self.offset_acc = self._zeros, self._zeros, self._zeros
            return ref, ref_vel, self._zeros
        inp = self.inp
        inp.current_position = offset.tolist()
        inp.current_velocity = offset_vel.tolist()
        inp.current_acceleration = self.offset_acc.tolist()
        try:
            result = self.otg.update(inp, self.out)
        except RuckigError:
            result = Result.Error
        out = self.out
        if result == Result.Working or result == Result.Finished:
            self.offset = np.array(out.new_position)
            self.offset_vel = np.array(out.new_velocity)
            self.offset_acc = np.array(out.new_acceleration)
        else:  # no valid plan (e.g. an offset velocity above the limit): drop the offset, count it
            self.failures += 1
            self.offset, self.offset_vel, self.offset_acc = self._zeros, self._zeros, self._zeros
        return ref + self.offset, ref_vel + self.offset_vel, self.offset_acc

    def preview_offset(self, taus_s: np.ndarray) -> np.ndarray:
        """relative mode: the offset (N, 3) the current Ruckig plan will have ``taus_s`` from now."""
        if not (np.any(self.offset) or np.any(self.offset_vel) or np.any(self.offset_acc)):
            return np.zeros((len(taus_s), 3))
        traj = self.out.trajectory
        duration = traj.duration
        return np.array([traj.at_time(min(float(t), duration))[0] if t < duration else (0.0, 0.0, 0.0) for t in taus_s])

    def step(self, target_pos: np.ndarray, target_vel: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        inp = self.inp
        inp.target_position = target_pos.tolist()
        inp.target_velocity = np.clip(target_vel, -self.v_cap, self.v_cap).tolist()
        try:
            result = self.otg.update(inp, self.out)
        except RuckigError:
            result = Result.Error
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
        self._pos = _Axis3(config.dt_s, config.v_max_m_s, config.a_max_m_s2, config.j_max_m_s3, config.pass_through)
        self._rot = _Axis3(config.dt_s, config.w_max_rad_s, config.dw_max_rad_s2, config.ddw_max_rad_s3,
                           config.pass_through)

    def preview_pos_offset(self, taus_s: np.ndarray) -> np.ndarray:
        """relative mode: position offsets (N, 3) of the smoothed reference ``taus_s`` from now."""
        return self._pos.preview_offset(taus_s)

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
        w_target = np.zeros(3) if ang_vel_rad_s is None else np.asarray(ang_vel_rad_s, dtype=float)
        pos_m, vel_m_s = np.asarray(pos_m, dtype=float), np.asarray(vel_m_s, dtype=float)
        rotvec_rad = np.asarray(rotvec_rad, dtype=float)
        if self.config.relative:
            p, v, a = self._pos.step_relative(pos_m, vel_m_s)
            r, w, dw = self._rot.step_relative(rotvec_rad, w_target)
        else:
            p, v, a = self._pos.step(pos_m, vel_m_s)
            r, w, dw = self._rot.step(rotvec_rad, w_target)
        return p, v, a, r, w, dw
