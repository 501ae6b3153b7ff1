"""The floor of the 1 kHz command path: the bare calls a tick cannot avoid, timed in tight loops on the inputs of a
real episode, beside our tick (``python -m mmact_ctrl.bench --floor``).

The calls, each replayed in tick order on what one recorded episode of the main job gave them (so that warm starts
and cache behaviour are the episode's, not a single repeated input's):

- ``mj_step``: MuJoCo's step of the scene (the world side records it: :class:`FloorRecording`);
- ``pinocchio``: the robot terms the QP needs (``computeAllTerms``, the TCP frame's placement, Jacobian, classical
  acceleration and velocity) at the episode's states;
- ``osqp``: OSQP's warm-started solve of the QP each tick assembled: its data updated, solved, its status and
  solution read (the low-level calls the fast path makes, ``TaskSpaceQP.bare_solver``);
- ``safety``: the safety monitor's compiled per-tick check on the episode's commands.

The floor of the command path is ``pinocchio + osqp + safety`` (medians): our tick (state in, checked command out)
is held against it; the floor of the episode adds ``mj_step``: the episode's wall time per simulated millisecond
(physics, policy, rendering, everything) is held against that. The three calls are also summed tick by tick: the p99
of that sum is the floor of a hard tick (OSQP's iterations vary ~4x over an episode), the like-for-like reference of
the tick's p99 (printed beside the strict ratio, the tick's p99 over the floor's median).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from controllers.safety import N_STATE, N_STATS, CommandLimits, check_tick
from mmact_ctrl.config import StackConfig
from mmact_ctrl.controller import HybridController


@dataclass(frozen=True)
class FloorRecording:
    """One recorded episode of the main job, what the floor replays.

    Attributes:
        q_rad, dq_rad_s, tau_nm: per tick (n, 7): the state the tick read and the torque it sent.
        ddq_rad_s2: per tick (n, 7): the QP's joint accelerations.
        qp_data: per tick, the assembled QP ``(P_x, q, A_x, l, u)`` stacked (each (n, k)).
        mj_step_s: per step, the bare ``mj_step`` of the scene replaying ``tau_nm``, s.
        tick_us, tick_after_us: our tick (command path), and with the after-command work, pooled over the timed
            episodes, us.
        realtime_factors: simulated over wall time of each timed episode.
        sim_s: simulated time of the timed episodes together, s; wall_s: their wall time, s.
        label: what ran (source, mode, target).
        mink_solve_ik_s: ``mink.solve_ik`` on the same Panda at the episode's states, s (None: mink not installed).
    """

    q_rad: np.ndarray
    dq_rad_s: np.ndarray
    tau_nm: np.ndarray
    ddq_rad_s2: np.ndarray
    qp_data: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]
    mj_step_s: np.ndarray
    tick_us: np.ndarray
    tick_after_us: np.ndarray
    realtime_factors: tuple[float, ...]
    sim_s: float
    wall_s: float
    label: str
    mink_solve_ik_s: np.ndarray | None = None


def _stats_us(samples_s: np.ndarray) -> dict:
    us = np.asarray(samples_s, dtype=float) * 1e6
    return {"median_us": float(np.median(us)), "p99_us": float(np.percentile(us, 99)), "n": int(us.size)}


def pinocchio_floor(q_rad: np.ndarray, dq_rad_s: np.ndarray, controller: HybridController) -> np.ndarray:
    """The bare Pinocchio calls of one tick's terms at each recorded state, s per call."""
    robot = controller.model
    m, d, fid = robot.model, robot.data, robot.frame_id
    frame = pin.LOCAL_WORLD_ALIGNED
    out = np.empty(len(q_rad))
    for i in range(len(q_rad)):
        q, dq = q_rad[i], dq_rad_s[i]
        t0 = time.perf_counter()
        pin.computeAllTerms(m, d, q, dq)
        pin.updateFramePlacement(m, d, fid)
        pin.getFrameJacobian(m, d, fid, frame)
        pin.getFrameClassicalAcceleration(m, d, fid, frame)
        pin.getFrameVelocity(m, d, fid, frame)
        out[i] = time.perf_counter() - t0
    return out


def osqp_floor(qp_data: tuple[np.ndarray, ...], controller: HybridController) -> np.ndarray:
    """OSQP's warm-started update and solve of each recorded QP, in tick order, s per tick."""
    solver = controller.qp.bare_solver()
    ext = solver._solver  # the low-level object the fast path drives (``TaskSpaceQP._setup_solver``)
    P_x, g, A_x, lo, up = qp_data
    out = np.empty(len(g))
    for i in range(len(g)):
        t0 = time.perf_counter()
        ext.update_data_vec(g[i], lo[i], up[i])  # positional, as the fast path calls them
        ext.update_data_mat(P_x[i], None, A_x[i], None)
        ext.solve()
        _status, _x = ext.info.status_val, ext.solution.x  # a solve is read: whether it solved, and its solution
        out[i] = time.perf_counter() - t0
    return out


def safety_floor(rec: FloorRecording, dt_s: float = 0.001) -> np.ndarray:
    """The safety monitor's compiled check on each recorded command, s per tick."""
    lim = CommandLimits(dt_s=dt_s).packed()
    state, stats = np.zeros(N_STATE), np.zeros(N_STATS, dtype=np.int64)
    v = np.zeros(3)
    check_tick(rec.tau_nm[0], rec.q_rad[0], rec.dq_rad_s[0], rec.ddq_rad_s2[0], v, lim, state, stats)  # compiled
    out = np.empty(len(rec.tau_nm))
    for i in range(len(rec.tau_nm)):
        tau, q, dq, ddq = rec.tau_nm[i], rec.q_rad[i], rec.dq_rad_s[i], rec.ddq_rad_s2[i]
        t0 = time.perf_counter()
        check_tick(tau, q, dq, ddq, v, lim, state, stats)
        out[i] = time.perf_counter() - t0
    return out


def floor_report(rec: FloorRecording) -> dict:
    """The floor's calls, our tick and the episode beside them, and the ratios (see the module)."""
    controller = HybridController(StackConfig())
    per_call_s = {
        "pinocchio": pinocchio_floor(rec.q_rad, rec.dq_rad_s, controller),
        "osqp": osqp_floor(rec.qp_data, controller),
        "safety": safety_floor(rec),
    }
    calls = {"mj_step": _stats_us(rec.mj_step_s), **{k: _stats_us(v) for k, v in per_call_s.items()}}
    # the floor tick by tick: the three bare calls of the same tick summed, so that a hard tick (OSQP's iterations)
    # is held against the same tick's floor; its p99 is the like-for-like reference of the tick's p99
    per_tick = _stats_us(per_call_s["pinocchio"] + per_call_s["osqp"] + per_call_s["safety"])
    command_floor = sum(calls[k]["median_us"] for k in ("pinocchio", "osqp", "safety"))
    episode_floor = command_floor + calls["mj_step"]["median_us"]
    tick = {"median_us": float(np.median(rec.tick_us)), "p99_us": float(np.percentile(rec.tick_us, 99))}
    after = {"median_us": float(np.median(rec.tick_after_us)), "p99_us": float(np.percentile(rec.tick_after_us, 99))}
    wall_per_sim_ms_us = 1e3 * rec.wall_s / rec.sim_s
    out = {
        "label": rec.label,
        "calls": calls,
        "command_floor_us": command_floor,
        "episode_floor_us": episode_floor,
        "tick": tick,
        "tick_after": after,
        "tick_median_over_floor": tick["median_us"] / command_floor,
        "tick_p99_over_floor": tick["p99_us"] / command_floor,
        "command_floor_per_tick": per_tick,
        "tick_p99_over_floor_p99": tick["p99_us"] / per_tick["p99_us"],
        "episode_wall_us_per_sim_ms": wall_per_sim_ms_us,
        "episode_over_floor": wall_per_sim_ms_us / episode_floor,
        "realtime_factor_median": float(np.median(rec.realtime_factors)),
        "realtime_factors": list(rec.realtime_factors),
    }
    if rec.mink_solve_ik_s is not None:
        out["mink_solve_ik"] = _stats_us(rec.mink_solve_ik_s)
        out["tick_median_over_mink"] = tick["median_us"] / out["mink_solve_ik"]["median_us"]
    return out


def format_floor(r: dict) -> str:
    """The report as a table and the ratios."""
    lines = [f"floor of the command path ({r['label']}), bare calls in tight loops on the episode's own inputs:",
             f"{'call':<34}{'median [us]':>12}{'p99 [us]':>10}"]
    for name, c in r["calls"].items():
        lines.append(f"{name:<34}{c['median_us']:>12.1f}{c['p99_us']:>10.1f}")
    lines.append(f"{'floor: pinocchio + osqp + safety':<34}{r['command_floor_us']:>12.1f}")
    per_tick = r["command_floor_per_tick"]
    lines.append(f"{'  the same, summed tick by tick':<34}{per_tick['median_us']:>12.1f}{per_tick['p99_us']:>10.1f}")
    lines.append(f"{'floor of a step: + mj_step':<34}{r['episode_floor_us']:>12.1f}")
    lines.append(f"{'our tick (state -> checked command)':<34}{r['tick']['median_us']:>12.1f}{r['tick']['p99_us']:>10.1f}")
    lines.append(f"{'  with the after-command work':<34}{r['tick_after']['median_us']:>12.1f}"
                 f"{r['tick_after']['p99_us']:>10.1f}")
    if "mink_solve_ik" in r:
        lines.append(f"{'mink solve_ik (same Panda, daqp)':<34}{r['mink_solve_ik']['median_us']:>12.1f}"
                     f"{r['mink_solve_ik']['p99_us']:>10.1f}")
    lines.append(f"{'episode wall time per sim ms':<34}{r['episode_wall_us_per_sim_ms']:>12.1f}")
    lines.append("")
    lines.append(f"tick median / floor: {r['tick_median_over_floor']:.2f}x   tick p99 / floor: "
                 f"{r['tick_p99_over_floor']:.2f}x   episode / step floor: {r['episode_over_floor']:.2f}x")
    lines.append(f"tick p99 / floor p99 (tick by tick): {r['tick_p99_over_floor_p99']:.2f}x")
    if "tick_median_over_mink" in r:
        lines.append(f"tick median / mink solve_ik: {r['tick_median_over_mink']:.2f}x")
    else:
        lines.append("mink not installed (pip install 'mmact-ctrl[bench]'): no solve_ik comparison")
    rtf = ", ".join(f"{x:.1f}" for x in r["realtime_factors"])
    lines.append(f"real-time factor of the episodes: median {r['realtime_factor_median']:.1f}x ({rtf})")
    return "\n".join(lines)
