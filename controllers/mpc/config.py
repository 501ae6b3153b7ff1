"""The settings of the task-space MPC: :class:`MPCConfig` and the solver back-ends it can name."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

#: Joints of the arm (the Panda): every joint vector of the MPC has this length.
N_JOINTS = 7

#: Solver back-ends understood by :class:`MPCConfig.solver`. ``"osqp_direct"`` drives OSQP 1.x
#: itself (set up once on the CasADi sparsity, then ``update()``); the others go through
#: ``casadi.conic`` with the named plugin.
SOLVERS: tuple[str, ...] = ("osqp_piqp", "osqp_direct", "piqp", "osqp", "qrqp", "proxqp")

_WEIGHTS: tuple[str, ...] = ("w_pos", "w_rot", "w_posture", "w_null_posture", "w_vel", "w_acc", "w_jerk",
                             "w_terminal_vel")


@dataclass(frozen=True)
class MPCConfig:
    """Settings of :class:`~controllers.mpc.TaskSpaceMPC` (all fixed when the problem is built).

    Attributes:
        horizon_steps: number of steps N of the horizon.
        dt_s: step length, s (horizon = N * dt_s).
        rate_hz: rate at which the caller re-solves (informational; the plan is valid for its horizon).
        w_pos: weight of the TCP position error, 1/m^2.
        w_rot: weight of the TCP orientation error (rotation vector), 1/rad^2.
        w_posture: weight pulling q toward the nominal posture, 1/rad^2 (in every direction: it biases the task).
        w_null_posture: weight of the posture error projected onto the null space of the 6x7 task Jacobian at
            the current state (:func:`~controllers.mpc.null_projector`), 1/rad^2: pulls the self-motion toward the
            nominal posture without trading off the TCP task (in the linear model). Without it the self-motion of
            the 7-DoF arm drifts wherever the approach leaves it (the plain ``w_posture`` is too weak to move it
            against the acceleration costs): measured on the 0.4 m/s circle, the arm wound up to
            ``q1 ~ 1.4, q3 ~ -1.8`` (smallest singular value of J 0.035-0.06 instead of ~0.2 at the posture the
            same TCP pose has near home), saturated joint velocities / accelerations and left the circle by up to
            0.1 m. Measured (circle, mean error after the first reach, seeds 0-19 / 100-119, with the turn-aware
            preview of ``target_estimator.turn_extrapolate``): 22.8 / 21.1 mm without, 21.4 / 21.3 with it
            (3.0: 22.2 / 20.1); alone, with the old preview, it made no difference (24.0 vs 23.5 mm):
            docs/perception/circle_tracking.md.
        null_damping: damping of the pseudo-inverse in the null-space projector, m (or rad): directions of the
            task the arm can barely move in (singular values below it) count as null space, so the posture
            pull also leads the arm out of a near-singular configuration.
        w_vel: joint velocity damping weight, s^2/rad^2.
        w_acc: joint acceleration weight, s^4/rad^2.
        w_jerk: weight of the acceleration change between steps (including from the
            previously applied acceleration), s^4/rad^2.
        w_terminal_vel: weight of the terminal joint velocity, s^2/rad^2.
        max_ref_dist_m: each position reference is pulled toward the current TCP position to at
            most this distance, m (the linearization is not meaningful farther away, and a far
            goal otherwise makes the QP badly scaled; the direction is kept).
        max_ref_angle_rad: the same for the orientation references, rad.
        q_margin_rad: the position limits are shrunk by this much on each side, rad.
        v_limit_scale: fraction of the velocity limits used by the plan.
        a_limit_scale: fraction of the acceleration limits used by the plan.
        solver: one of :data:`SOLVERS`.
        max_solve_ms: a solve slower than this counts as late and its result is discarded, ms.
        solver_options: extra options passed to the solver (a tuple of (key, value) pairs so
            the config stays hashable).
        w_pos_z_scale: the vertical position error's weight is ``w_pos`` times this. 1 (default) weighs the three
            axes alike, as every published reach figure was made. Near a table it is not alike: with it 1, the plan of a
            pick's hand 40 cm from its cube went 13 cm below its reference to catch up horizontally (seed 1001 at 0.4
            m/s: the open fingers swept into the cube at 1.2 m/s, 60 N); a contact task sets it higher.
    """

    horizon_steps: int = 10
    dt_s: float = 0.04
    rate_hz: float = 50.0
    w_pos: float = 1.0e4
    w_rot: float = 1.0e3
    w_posture: float = 1.0e-2
    w_null_posture: float = 1.0
    null_damping: float = 0.05
    w_vel: float = 1.0e-3
    w_acc: float = 1.0e-3
    w_jerk: float = 1.0e-3
    w_terminal_vel: float = 1.0e-1
    max_ref_dist_m: float = 0.2
    max_ref_angle_rad: float = 0.5
    q_margin_rad: float = 0.05
    v_limit_scale: float = 0.95
    a_limit_scale: float = 0.95
    solver: str = "osqp_piqp"
    max_solve_ms: float = 10.0
    solver_options: tuple[tuple[str, Any], ...] = ()
    w_pos_z_scale: float = 1.0

    def __post_init__(self) -> None:
        if self.horizon_steps < 1:
            raise ValueError("horizon_steps must be >= 1")
        if not self.dt_s > 0.0:
            raise ValueError("dt_s must be > 0")
        if self.solver not in SOLVERS:
            raise ValueError(f"solver must be one of {SOLVERS}, got {self.solver!r}")
        if not (0.0 < self.v_limit_scale <= 1.0 and 0.0 < self.a_limit_scale <= 1.0):
            raise ValueError("v_limit_scale and a_limit_scale must be in (0, 1]")
        if not (self.max_ref_dist_m > 0.0 and self.max_ref_angle_rad > 0.0):
            raise ValueError("max_ref_dist_m and max_ref_angle_rad must be > 0")
        if self.q_margin_rad < 0.0:
            raise ValueError("q_margin_rad must be >= 0")
        if not self.null_damping > 0.0:
            raise ValueError("null_damping must be > 0")
        if not self.w_pos_z_scale > 0.0:
            raise ValueError(f"w_pos_z_scale must be > 0, got {self.w_pos_z_scale!r}")
        for name in _WEIGHTS:
            if getattr(self, name) < 0.0:
                raise ValueError(f"{name} must be >= 0")
        if self.w_acc <= 0.0:
            raise ValueError("w_acc must be > 0 (keeps the QP strictly convex)")
