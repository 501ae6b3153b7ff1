"""Closed-loop kinematic harness and solve-time benchmark of :mod:`controllers.mpc`.

``python -m controllers.mpc_bench`` prints the median / p99 wall time of
:meth:`TaskSpaceMPC.solve` for every solver back-end, measured in closed loop on the Panda
(Pinocchio kinematics, the TCP following a point that moves on a circle at 0.2 m/s).
:func:`bench_mpc` is the entry point for the project's benchmark module.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from controllers.mpc import SOLVERS, MPCConfig, MPCPlan, TaskSpaceMPC
from controllers.robot_description import HOME_Q_RAD


class PandaKinematics:
    """TCP position, rotation and 6x7 Jacobian of the one Panda model (``controllers.robot_model.PandaModel``)."""

    def __init__(self) -> None:
        from controllers.robot_model import PandaModel

        self._robot = PandaModel()

    def tcp(self, q_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(position m (3,), rotation (3,3), Jacobian 6x7 LOCAL_WORLD_ALIGNED) at ``q_rad``."""
        terms = self._robot.terms(np.asarray(q_rad, dtype=float), np.zeros(7))
        return terms.pos_m.copy(), terms.rot.copy(), np.array(terms.J)

    def rotvec(self, rot: np.ndarray) -> np.ndarray:
        """Rotation vector (rad) of a rotation matrix."""
        import pinocchio as pin

        return np.asarray(pin.log3(rot))


@dataclass(frozen=True)
class TrackingLog:
    """Per-solve record of a closed-loop run (arrays of length n_solves unless stated)."""

    t_s: np.ndarray
    q_rad: np.ndarray  # (n, 7) state at each solve
    dq_rad_s: np.ndarray
    ddq_rad_s2: np.ndarray  # (n, 7) acceleration applied over the next interval
    ee_pos_m: np.ndarray  # (n, 3)
    target_m: np.ndarray  # (n, 3) reference at t
    rot_err_rad: np.ndarray  # (n,) orientation drift from the start
    solve_us: np.ndarray
    ok: np.ndarray


def run_closed_loop(
    mpc: TaskSpaceMPC,
    kin: PandaKinematics,
    target_fn: Callable[[float], np.ndarray],
    duration_s: float,
    q0_rad: np.ndarray | None = None,
) -> TrackingLog:
    """Simulate the arm as a perfect joint double integrator: every ``1/rate_hz`` solve, apply
    the plan's accelerations until the next solve (exact integration), recompute FK/J.

    The TCP reference is ``target_fn(t)`` previewed over the horizon; the orientation is held at
    its initial value (constant rotation-vector goal relative to the current orientation)."""
    cfg = mpc.config
    n, dt = cfg.horizon_steps, cfg.dt_s
    period = 1.0 / cfg.rate_hz
    q = np.array(HOME_Q_RAD if q0_rad is None else q0_rad, dtype=float)
    dq = np.zeros(7)
    _, rot0, _ = kin.tcp(q)
    rec: dict[str, list] = {k: [] for k in TrackingLog.__dataclass_fields__}
    t = 0.0
    for _ in range(int(round(duration_s / period))):
        pos, rot, jac = kin.tcp(q)
        refs = np.array([target_fn(t + (i + 1) * dt) for i in range(n)])
        rot_goal = kin.rotvec(rot0 @ rot.T)  # world-frame rotation from current to initial
        plan: MPCPlan = mpc.solve(t, q, dq, pos, jac, refs, rot_goal)
        rec["t_s"].append(t)
        rec["q_rad"].append(q.copy())
        rec["dq_rad_s"].append(dq.copy())
        rec["ee_pos_m"].append(pos)
        rec["target_m"].append(np.asarray(target_fn(t), dtype=float))
        rec["rot_err_rad"].append(float(np.linalg.norm(rot_goal)))
        rec["solve_us"].append(plan.solve_us)
        rec["ok"].append(plan.ok)
        # integrate the plan exactly over one period (piecewise-constant accelerations)
        t_next = t + period
        q, dq, _ = plan.sample(t_next)
        rec["ddq_rad_s2"].append(plan.sample(t)[2])
        t = t_next
    return TrackingLog(**{k: np.asarray(v) for k, v in rec.items()})


def circle_target(center_m: np.ndarray, radius_m: float = 0.1, speed_m_s: float = 0.2) -> Callable[[float], np.ndarray]:
    """A point moving on a horizontal circle at ``speed_m_s`` (starting at ``center + (r, 0, 0)``)."""
    omega = speed_m_s / radius_m
    c = np.asarray(center_m, dtype=float)

    def fn(t_s: float) -> np.ndarray:
        return c + radius_m * np.array([math.cos(omega * t_s), math.sin(omega * t_s), 0.0])

    return fn


def bench_mpc(n_calls: int = 200, solver: str | None = None, config: MPCConfig | None = None) -> dict:
    """Median / p99 wall time (microseconds) of :meth:`TaskSpaceMPC.solve` in closed loop.

    Args:
        n_calls: number of timed solves (after 10 untimed warm-up solves).
        solver: back-end name (default: the :class:`MPCConfig` default).
        config: base configuration.

    Returns:
        dict with solver, n_calls, median_us, p99_us, max_us, mean_us, failures, late,
        tracking_rms_mm (TCP-to-target error after the first 0.5 s).
    """
    cfg = config or MPCConfig()
    if solver is not None:
        cfg = replace(cfg, solver=solver)
    cfg = replace(cfg, max_solve_ms=1e6)  # measure, do not discard
    kin = PandaKinematics()
    mpc = TaskSpaceMPC(cfg)
    p_home, _, _ = kin.tcp(np.asarray(HOME_Q_RAD))
    start = p_home - np.array([0.1, 0.0, 0.0])
    target = circle_target(start, 0.1, 0.2)
    warm = 10
    log = run_closed_loop(mpc, kin, target, (n_calls + warm) / cfg.rate_hz)
    us = log.solve_us[warm:]
    settle = log.t_s >= 0.5
    err = np.linalg.norm(log.ee_pos_m - log.target_m, axis=1)[settle]
    return {
        "solver": cfg.solver,
        "n_calls": int(us.size),
        "median_us": float(np.median(us)),
        "p99_us": float(np.percentile(us, 99)),
        "max_us": float(np.max(us)),
        "mean_us": float(np.mean(us)),
        "failures": mpc.failures,
        "late": mpc.late,
        "tracking_rms_mm": float(1e3 * np.sqrt(np.mean(err**2))) if err.size else float("nan"),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n-calls", type=int, default=200)
    parser.add_argument("--solvers", nargs="*", default=list(SOLVERS))
    args = parser.parse_args()
    print(f"{'solver':<12} {'median_us':>10} {'p99_us':>10} {'max_us':>10} {'fail':>5} {'late':>5} {'rms_mm':>8}")
    for name in args.solvers:
        try:
            r = bench_mpc(args.n_calls, solver=name)
        except Exception as exc:  # noqa: BLE001 - report and go on with the next back-end
            print(f"{name:<12} error: {exc}")
            continue
        print(f"{name:<12} {r['median_us']:10.0f} {r['p99_us']:10.0f} {r['max_us']:10.0f} {r['failures']:5d} "
              f"{r['late']:5d} {r['tracking_rms_mm']:8.2f}")


if __name__ == "__main__":
    main()
