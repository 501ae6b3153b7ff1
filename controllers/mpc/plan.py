"""One MPC solution, :class:`MPCPlan`, and how the 1 kHz layer samples it (joint and task space)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from controllers.mpc.config import N_JOINTS


@dataclass(frozen=True)
class MPCPlan:
    """One solution of the MPC: a joint trajectory with piecewise-constant accelerations.

    Attributes:
        t0_s: time of the first knot, s.
        dt_s: knot spacing, s.
        q_rad: joint positions at the knots, (N+1, 7).
        dq_rad_s: joint velocities at the knots, (N+1, 7).
        ddq_rad_s2: joint accelerations over each interval, (N, 7).
        ee_pos_m: predicted TCP positions at the knots (linearized model), (N+1, 3).
        ok: False when this plan is a fallback (failure, late solve).
        solve_us: wall time of the solve() call that produced it, microseconds.
        ee_jacobian_lin: 3x7 linear Jacobian used for the task-space prediction, m/rad.
    """

    t0_s: float
    dt_s: float
    q_rad: np.ndarray
    dq_rad_s: np.ndarray
    ddq_rad_s2: np.ndarray
    ee_pos_m: np.ndarray
    ok: bool
    solve_us: float
    ee_jacobian_lin: np.ndarray = field(default_factory=lambda: np.zeros((3, N_JOINTS)))

    @property
    def horizon_steps(self) -> int:
        return int(self.ddq_rad_s2.shape[0])

    @property
    def t_end_s(self) -> float:
        return self.t0_s + self.horizon_steps * self.dt_s

    def sample(self, t_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Joint reference (q rad, dq rad/s, ddq rad/s^2) at time ``t_s``.

        Exact inside the horizon (constant acceleration per interval); clamped to the first
        knot before ``t0_s``; past the end the last position is held at rest (dq = ddq = 0).
        """
        tau = float(t_s) - self.t0_s
        n = self.horizon_steps
        if tau >= n * self.dt_s:
            return self.q_rad[n].copy(), np.zeros(N_JOINTS), np.zeros(N_JOINTS)
        tau = max(tau, 0.0)
        k = min(int(np.floor(tau / self.dt_s + 1e-9)), n - 1)  # robust at the knots
        s = max(tau - k * self.dt_s, 0.0)
        a = self.ddq_rad_s2[k]
        q = self.q_rad[k] + self.dq_rad_s[k] * s + 0.5 * a * s * s
        dq = self.dq_rad_s[k] + a * s
        return q, dq, a.copy()

    def sample_task(self, t_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Predicted TCP reference (pos m, vel m/s, acc m/s^2) at ``t_s``, linearized:
        ``p0 + J_lin (q(t) - q0)``, ``J_lin dq(t)``, ``J_lin ddq(t)`` (the dJ/dt dq term is neglected)."""
        q, dq, ddq = self.sample(t_s)
        jl = self.ee_jacobian_lin
        pos = self.ee_pos_m[0] + jl @ (q - self.q_rad[0])
        return pos, jl @ dq, jl @ ddq
