"""The task-space QP's settings, grouped as its parts use them: the TCP tasks, the posture task, the limits' margins
and the solver. Each group is checked at construction; every number carries its unit."""

from __future__ import annotations

from dataclasses import dataclass, field

#: OSQP's iteration cap for a loop on the wall clock (``--realtime``): a solve that has not converged by then goes to
#: DAQP's exact active-set solve at once, which on these 7-variable problems costs about as much as 50-100 ADMM
#: iterations. Measured here (a 2-core EPYC, the residual mode, whose reference steps every 10 ms and keeps the
#: torque-rate rows active): a capped tick's solve took 438 us median at 400 and 233 us at 100; the simulated-time
#: studies keep ``SolverSettings.max_iter`` (400).
REALTIME_MAX_ITER: int = 100


def _nonneg(owner: str, **values: float) -> None:
    for name, v in values.items():
        if not v >= 0:
            raise ValueError(f"{owner}.{name} must be >= 0, got {v}")


def _fraction(owner: str, **values: float) -> None:
    for name, v in values.items():
        if not 0 < v <= 1:
            raise ValueError(f"{owner}.{name} must be in (0, 1], got {v}")


@dataclass(frozen=True)
class TcpGains:
    """The TCP tasks: PD gains, weights, and how far the PD term may pull.

    Attributes:
        kp_pos, kd_pos: position gains, 1/s^2 and 1/s.
        kp_ori, kd_ori: orientation gains, 1/s^2 and 1/s.
        w_pos, w_ori: task weights (cost per (m/s^2)^2 and per (rad/s^2)^2).
        pos_err_max_m: the position error of the PD term is saturated at this length, m: a reference that jumped far
            away (a stale plan dropped, a chunk switch) is approached at about ``kp_pos / kd_pos * pos_err_max_m``
            (1 m/s), not at the 7 x error per second of a raw PD step.
        tcp_vel_cap_m_s: the TCP velocity the PD term steers toward, ``v_ref + kp_pos / kd_pos * e``, is capped at this
            speed (the reference velocity and acceleration feed-forward are scaled down with it), m/s: a reference that
            moves faster than the Panda's 1.7 m/s end-effector limit is followed at a speed the robot accepts.
    """

    kp_pos: float = 400.0
    kd_pos: float = 40.0
    kp_ori: float = 300.0
    kd_ori: float = 35.0
    w_pos: float = 1.0
    w_ori: float = 0.3
    pos_err_max_m: float = 0.1
    tcp_vel_cap_m_s: float = 1.4

    def __post_init__(self) -> None:
        _nonneg("TcpGains", kp_pos=self.kp_pos, kd_pos=self.kd_pos, kp_ori=self.kp_ori, kd_ori=self.kd_ori,
                w_pos=self.w_pos, w_ori=self.w_ori)
        if not self.pos_err_max_m > 0:
            raise ValueError(f"TcpGains.pos_err_max_m must be > 0, got {self.pos_err_max_m}")
        if not self.tcp_vel_cap_m_s > 0:
            raise ValueError(f"TcpGains.tcp_vel_cap_m_s must be > 0, got {self.tcp_vel_cap_m_s}")


@dataclass(frozen=True)
class PostureGains:
    """The posture task (the null space pulled toward a joint posture) and the regularisation.

    Attributes:
        kp_post, kd_post: posture gains, 1/s^2 and 1/s.
        w_post: posture weight (cost per (rad/s^2)^2).
        w_reg: weight of ``||ddq||^2`` (keeps the QP strictly convex).
    """

    kp_post: float = 25.0
    kd_post: float = 10.0
    w_post: float = 1e-3
    w_reg: float = 1e-6

    def __post_init__(self) -> None:
        _nonneg("PostureGains", kp_post=self.kp_post, kd_post=self.kd_post, w_post=self.w_post, w_reg=self.w_reg)


@dataclass(frozen=True)
class LimitMargins:
    """How much of the Panda's limits the QP may use, and how it looks ahead.

    Attributes:
        tau_margin: fraction of the effort limit.
        dtau_max_nm_s: the robot's torque-rate limit, N*m/s (Panda: 1000).
        rate_margin: fraction of the torque-rate limit per step.
        a_margin: fraction of the joint acceleration limits.
        jerk_margin: fraction of the joint jerk limits the commanded acceleration may use.
        v_margin: fraction of the velocity limits.
        q_margin_rad: distance kept from the joint position limits, rad.
        brake_horizon_s: look-ahead of the position-limit viability bound, s.
    """

    tau_margin: float = 0.95
    dtau_max_nm_s: float = 1000.0
    rate_margin: float = 0.95
    a_margin: float = 0.97
    jerk_margin: float = 0.9
    v_margin: float = 0.95
    q_margin_rad: float = 0.05
    brake_horizon_s: float = 0.05

    def __post_init__(self) -> None:
        _fraction("LimitMargins", tau_margin=self.tau_margin, rate_margin=self.rate_margin, a_margin=self.a_margin,
                  jerk_margin=self.jerk_margin, v_margin=self.v_margin)
        if not self.dtau_max_nm_s > 0:
            raise ValueError(f"LimitMargins.dtau_max_nm_s must be > 0, got {self.dtau_max_nm_s}")


@dataclass(frozen=True)
class SolverSettings:
    """OSQP's settings, and the fallback's damping.

    Attributes:
        eps: OSQP absolute and relative tolerance.
        max_iter: OSQP iteration cap (a solve not converged by then goes to DAQP).
        fallback_kd: joint damping of the fallback torque, N*m*s/rad.
    """

    eps: float = 1e-5
    max_iter: int = 400
    fallback_kd: float = 5.0


@dataclass(frozen=True)
class QPConfig:
    """Everything the task-space QP is set up from.

    Attributes:
        tcp: the TCP tasks' gains and weights.
        posture: the posture task and the regularisation.
        limits: the limits' margins.
        solver: OSQP's settings and the fallback.
        dt_s: control period, s.
    """

    tcp: TcpGains = field(default_factory=TcpGains)
    posture: PostureGains = field(default_factory=PostureGains)
    limits: LimitMargins = field(default_factory=LimitMargins)
    solver: SolverSettings = field(default_factory=SolverSettings)
    dt_s: float = 0.001

    def __post_init__(self) -> None:
        if not self.dt_s > 0:
            raise ValueError(f"QPConfig.dt_s must be > 0, got {self.dt_s}")

    @property
    def max_iter(self) -> int:
        """OSQP's iteration cap (``solver.max_iter``)."""
        return self.solver.max_iter
