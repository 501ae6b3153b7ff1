"""Episode and summary metrics, defined once and used everywhere.

- success: the TCP within ``success_radius_m`` (3 cm) of the target centre for at least
  ``success_hold_s`` (0.3 s) of continuous time.
- time_to_reach_s: start of the first such window (NaN if never).
- final_error_m: TCP-target distance at the last sample.
- mean_error_m: TCP-target distance averaged over the whole episode (the approach from the home pose included).
- mean_error_after_reach_m: the same average from the start of the first success window (``time_to_reach_s``) to
  the end: how well the target is *followed* once reached, without the approach, which on a fast target can
  dominate the plain mean (circle 0.4 m/s, expert: 79 mm plain, 26 mm after reach). NaN when the target is never
  reached; the summary averages the episodes that reached it, so read it beside ``success_rate``.
- tracking_ratio: fraction of the episode's samples with the TCP within the success radius.
- jerk_rms: RMS of the TCP jerk (m/s^3), from the measured TCP position resampled at
  ``jerk_rate_hz`` (100 Hz: the jerk of the motion, not of the 1 kHz torque steps).
- safety (``controllers.safety.SafetyMonitor``, run on every tick on the command actually sent): ticks
  flagged per kind: ``nonfinite_commands``, ``torque_rate_violations`` (|dtau/dt| > 1000 N m/s),
  ``torque_violations`` (|tau| > effort limit), ``position_violations``, ``velocity_violations``,
  ``accel_violations`` and ``jerk_violations`` (the commanded joint acceleration and its backward-Euler
  jerk), ``tcp_speed_violations`` (> 1.7 m/s); ``torque_rate_max_nm_s``, the largest torque rate sent.
- limit_violations: the sum of every kind above (until 2026-12 it counted only joint position, velocity
  and torque magnitude, which hid the torque rate, the one condition a Panda in torque control aborts on).
- faults survived: ``rejected_chunks`` (and ``rejections`` per reason, ``mmact_ctrl.chunk_intake``),
  ``watchdog_stops``, ``gated_measurements`` (non-finite, frozen, outlier), ``missed_ticks``, ``aborts``
  (episodes the robot would have aborted: 20 missed ticks in a row), ``rate_clamps`` (solver-tolerance
  corrections of the last guard), ``qp_rescues`` (ticks OSQP did not solve and DAQP did), ``plan_resyncs``, ``floor_clamps`` (reference samples raised to the TCP floor above the table), ``mpc_bypass_ticks`` (ticks with
  no good MPC plan, tracking the smoothed reference directly).
- wrong_object: the TCP held within the success radius of an object that was not instructed.
- tick_us: the wall time of the 1 kHz command path per tick as real time runs it (chunk admission, the controller,
  the safety check), us; the MPC is solved beside it (``mmact_ctrl.mpc_worker``) and its solves are ``mpc_solve_us``
  (median, p99); ``tick_after_us``: the command path plus the work real time does after the command on the same
  thread (fusing the measurements, the MPC's 50 Hz update), per tick (median, p99).
- policy_latency_ms: measured time of each chunk-source call (``plan``), ms.
- round_trip_ms: the same calls as median / p95 / max (for a source in another process, the chunk's round trip on the
  wire); server_infer_ms / policy_infer_ms: what a remote source's server reported of its own inference time, ms
  (``EpisodeLog.source_timing_ms``; absent for a source that reports none).
- chunk_jump_acc_m_s2: largest TCP acceleration within +-50 ms of a chunk switch.
- reaction (``mmact_ctrl.reaction``): for each change of the target's motion (a jump, flip, swerve, set-off:
  ``EpisodeLog.change_times_s``), ``reaction_s`` the median time until the TCP's velocity turns toward the new
  course, ``reach_after_change_s`` the median time until the TCP is within the success radius again (NaN: none).
- real time (``--realtime``, ``mmact_ctrl.realtime.pacer``; computed in ``mmact_ctrl.metrics_realtime``): ``overruns``
  (ticks whose command was ready after its cycle: the robot re-applied the last torque), ``overrun_rate``,
  ``cycles_missed`` (ticks that started a whole period late), ``exec_us`` (a tick's work, median / p99 / max),
  ``jitter_us`` (its start's lateness), libfranka's ``control_command_success_rate`` (minimum over windows of 100
  ticks), ``realtime_rate`` (simulated over wall time); NaN / absent in simulated time.
- d_measured: the inference delay as it ran, median over chunks of the waypoints of the running chunk consumed
  while the chunk was computed (RTC's d, in chunk steps; ``EpisodeLog.delay_steps``).
- jump recovery: for each target teleport whose 1 s window ends inside the episode, whether the
  TCP got within the success radius of the new goal within ``jump_window_s`` (1 s), and how long it took.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mmact_ctrl.loop import EpisodeLog
from mmact_ctrl.metrics_realtime import MAX_LATE_TICKS, _realtime_episode, _realtime_summary  # noqa: F401
from mmact_ctrl.reaction import reaction_metrics
from mmact_ctrl.stats import wilson_interval


@dataclass(frozen=True)
class MetricsConfig:
    success_radius_m: float = 0.03
    success_hold_s: float = 0.3
    jerk_rate_hz: float = 100.0
    jump_window_s: float = 1.0


def _first_hold_start(inside: np.ndarray, hold_n: int) -> int | None:
    """Index where the first run of ``hold_n`` consecutive True values starts."""
    run = 0
    for i, v in enumerate(inside):
        run = run + 1 if v else 0
        if run >= hold_n:
            return i - hold_n + 1
    return None


def limit_violation_mask(log: EpisodeLog) -> np.ndarray:
    """Per-tick bool: the safety monitor flagged the command of that tick (any kind)."""
    return log.safety_mask != 0


#: summary key of each safety kind (``controllers.safety.KINDS``)
SAFETY_KEYS: dict[str, str] = {
    "nonfinite": "nonfinite_commands",
    "torque_rate": "torque_rate_violations",
    "torque": "torque_violations",
    "position": "position_violations",
    "velocity": "velocity_violations",
    "accel": "accel_violations",
    "jerk": "jerk_violations",
    "tcp_speed": "tcp_speed_violations",
    "contact_force": "contact_force_violations",
}
#: fault counters summed over episodes
FAULT_KEYS: tuple[str, ...] = ("rejected_chunks", "watchdog_stops", "gated_measurements", "missed_ticks", "aborts",
                               "rate_clamps", "qp_rescues", "plan_resyncs", "mpc_bypass_ticks", "perception_errors",
                               "floor_clamps")


def _motion_figures(log: EpisodeLog, dt: float, config: MetricsConfig) -> tuple[np.ndarray, list[float]]:
    """(the TCP's jerk (N, 3) at ``jerk_rate_hz``, the largest acceleration within 5 samples of each chunk switch)."""
    stride = max(1, int(round(1.0 / (config.jerk_rate_hz * dt))))
    p = log.ee_pos_m[::stride]
    h = stride * dt
    jerk = np.diff(p, n=3, axis=0) / h**3 if len(p) > 3 else np.zeros((1, 3))
    acc = np.diff(p, n=2, axis=0) / h**2 if len(p) > 2 else np.zeros((1, 3))
    acc_n = np.linalg.norm(acc, axis=1)
    switch_acc = []
    for ts in log.chunk_active_s[1:]:
        i = int(round(ts / h))
        lo, hi = max(0, i - 5), min(len(acc_n), i + 5)
        if hi > lo:
            switch_acc.append(float(acc_n[lo:hi].max()))
    return jerk, switch_acc


def _reached_wrong_object(log: EpisodeLog, hold_n: int, config: MetricsConfig) -> bool:
    """Whether the TCP held within the success radius of an object other than the instructed one."""
    wrong_object = False
    if log.objects_pos_m is not None:
        for j in range(log.objects_pos_m.shape[1]):
            if j == log.target_index:
                continue
            near = np.linalg.norm(log.ee_pos_m - log.objects_pos_m[:, j], axis=1) < config.success_radius_m
            wrong_object |= _first_hold_start(near, hold_n) is not None
    return wrong_object


def _jump_recoveries(log: EpisodeLog, inside: np.ndarray, dt: float, config: MetricsConfig) -> tuple[list, list]:
    """(per target jump whose window fits in the episode: whether the TCP got back within the radius, the times it
    took, s)."""
    recovered, recovery_s = [], []
    for tj in log.jump_times_s:
        j0 = int(np.ceil(tj / dt)) + 1
        j1 = j0 + int(round(config.jump_window_s / dt))
        if j1 > len(inside):  # the episode ends before the recovery window does: not counted
            continue
        hit = np.flatnonzero(inside[j0:j1])
        recovered.append(bool(hit.size))
        if hit.size:
            recovery_s.append(float(hit[0] * dt))
    return recovered, recovery_s


def episode_metrics(log: EpisodeLog, config: MetricsConfig = MetricsConfig()) -> dict:
    """The per-episode figures (JSON-ready floats and ints)."""
    dt = float(log.t_s[1] - log.t_s[0]) if len(log.t_s) > 1 else 1e-3
    err = np.linalg.norm(log.ee_pos_m - log.target_pos_m, axis=1)
    inside = err < config.success_radius_m
    hold_n = max(1, int(round(config.success_hold_s / dt)))
    start = _first_hold_start(inside, hold_n)
    jerk, switch_acc = _motion_figures(log, dt, config)
    wrong_object = _reached_wrong_object(log, hold_n, config)
    safety = {key: int(log.safety_counts.get(kind, 0)) for kind, key in SAFETY_KEYS.items()}
    recovered, recovery_s = _jump_recoveries(log, inside, dt, config)
    sim_s = float(len(log.t_s) * dt)
    reaction = reaction_metrics(log.t_s, log.ee_pos_m, log.target_pos_m, log.change_times_s,
                                success_radius_m=config.success_radius_m)
    return {
        **_outcome(log, err, inside, start, dt, jerk, switch_acc, wrong_object, safety),
        **_survived(log),
        **_timing(log, sim_s),
        **_reactions(log, recovered, recovery_s, reaction),
        **_realtime_episode(log),
        # what the source said when it failed (whole); only when it did, so other episodes' figures are unchanged
        **({"source_errors": [dict(e) for e in log.source_errors]} if log.source_errors else {}),
        **_task_figures(log),
    }


#: the task figures a contact task's world reports (``EpisodeLog.task``), summarised over episodes as medians
TASK_MEDIAN_KEYS: tuple[str, ...] = ("time_to_grasp_s", "time_to_seat_s", "object_speed_at_grasp_m_s",
                                     "lateral_error_at_contact_m", "peak_contact_force_n", "peg_slip_m")
#: ... and as sums
TASK_SUM_KEYS: tuple[str, ...] = ("closings", "drops", "jams")


def _task_figures(log: EpisodeLog) -> dict:
    """A contact task's figures (``EpisodeLog.task``): its predicate replaces reach's ``success`` (and
    ``wrong_object``), its figures are added; nothing for reach."""
    if not log.task:
        return {}
    figures = {k: v for k, v in log.task.items() if k != "task"}
    return {**figures, "task": log.task.get("task", ""), "success": bool(log.task["success"]),
            "wrong_object": bool(log.task.get("wrong_object", False))}


def _outcome(log, err, inside, start, dt, jerk, switch_acc, wrong_object, safety) -> dict:
    """Success, errors, smoothness and the safety counts."""
    return {
        "seed": int(log.seed),
        "instruction": log.instruction,
        "target_start_pos_m": [float(x) for x in log.target_pos_m[0]] if len(log.target_pos_m) else [],
        "success": start is not None,
        "wrong_object": bool(wrong_object),
        "time_to_reach_s": float(start * dt) if start is not None else float("nan"),
        "final_error_m": float(err[-1]),
        "mean_error_m": float(err.mean()),
        "mean_error_after_reach_m": float(err[start:].mean()) if start is not None else float("nan"),
        "tracking_ratio": float(inside.mean()),
        "jerk_rms": float(np.sqrt(np.mean(np.sum(jerk**2, axis=1)))),
        "chunk_jump_acc_m_s2": float(max(switch_acc)) if switch_acc else 0.0,
        "limit_violations": int(sum(safety.values())),
        **safety,
        "torque_rate_max_nm_s": float(log.torque_rate_max_nm_s),
    }


def _survived(log: EpisodeLog) -> dict:
    """The faults survived and counted: rejected chunks, watchdog stops, gated measurements, missed ticks, ..."""
    return {
        "rejected_chunks": int(sum(log.rejections.values())),
        "rejections": {k: int(v) for k, v in log.rejections.items() if v},
        "watchdog_stops": int(log.watchdog_stops),
        "gated_measurements": int(sum(log.gated_measurements.values())),
        "gated": {k: int(v) for k, v in log.gated_measurements.items() if v},
        "missed_ticks": int(log.missed_ticks),
        "aborts": int(log.abort is not None),
        "abort": log.abort,
        "rate_clamps": int(log.rate_clamps),
        "qp_rescues": int(log.qp_rescues),
        "plan_resyncs": int(log.plan_resyncs),
        "floor_clamps": int(log.floor_clamps),
        "mpc_bypass_ticks": int(log.mpc_bypass_ticks),
        "perception_errors": int(log.perception_errors),
        "measurements": int(log.measurements),
        "measurements_lost": int(log.measurements_lost),
    }


def _timing(log: EpisodeLog, sim_s: float) -> dict:
    """Wall-clock figures: the sensor's, the tick's, the MPC's, the source's, the real-time factor; and the solvers'
    failures."""
    return {
        "sensor_ms_per_sim_s": float(1e3 * log.sensor_wall_s / sim_s) if sim_s > 0 else float("nan"),
        "qp_failures": int(log.qp_failures),
        "smoother_failures": int(log.smoother_failures),
        "mpc_failures": int(log.mpc_failures),
        "clipped_actions": int(log.clipped_actions),
        "tick_us_median": float(np.median(log.tick_us)),
        "tick_us_p99": float(np.percentile(log.tick_us, 99)),
        "mpc_solve_us_median": float(np.median(log.mpc_solve_us)) if log.mpc_solve_us else float("nan"),
        "mpc_solve_us_p99": float(np.percentile(log.mpc_solve_us, 99)) if log.mpc_solve_us else float("nan"),
        "mpc_solve_us": [float(x) for x in log.mpc_solve_us],
        "plan_ms_median": float(np.median(log.plan_ms)) if log.plan_ms else float("nan"),
        "plan_ms": [float(x) for x in log.plan_ms],
        "source_timing_ms": {k: [float(x) for x in v] for k, v in log.source_timing_ms.items()},
        "realtime_factor": sim_s / log.wall_s if log.wall_s > 0 else float("nan"),
    }


def _reactions(log: EpisodeLog, recovered: list, recovery_s: list, reaction: dict) -> dict:
    """Jumps recovered, the reaction to a change of course, the inference delay as it ran."""
    return {
        "n_jumps": len(recovered),
        "jumps_recovered": int(sum(recovered)),
        "jump_recovery_s": recovery_s,
        "reaction_s": float(reaction["reaction_s"]),
        "reach_after_change_s": float(reaction["reach_after_change_s"]),
        "n_changes": int(reaction["n_changes"]),
        "changes_reacted": int(reaction["reacted"]),
        "d_measured": float(np.median(log.delay_steps)) if log.delay_steps else float("nan"),
        "d_steps": [float(x) for x in log.delay_steps],
    }


def _task_summary(episodes: list[dict]) -> dict:
    """Medians and sums of the contact tasks' figures (none for reach)."""
    out: dict = {}
    for key in TASK_MEDIAN_KEYS:
        if any(key in e for e in episodes):
            out[key] = _nanmedian([float(e.get(key, float("nan"))) for e in episodes])
    for key in TASK_SUM_KEYS:
        if any(key in e for e in episodes):
            out[key] = int(sum(int(e.get(key, 0)) for e in episodes))
    return out


def _nanmedian(values: list[float]) -> float:
    v = np.asarray([x for x in values if np.isfinite(x)], dtype=float)
    return float(np.median(v)) if v.size else float("nan")


def _nanmean(values: list[float]) -> float:
    v = np.asarray([x for x in values if np.isfinite(x)], dtype=float)
    return float(np.mean(v)) if v.size else float("nan")


def _median_p99(values: list[float]) -> dict:
    if len(values) == 0:
        return {"median": float("nan"), "p99": float("nan")}
    return {"median": float(np.median(values)), "p99": float(np.percentile(values, 99))}


def _median_p95_max(values: list[float]) -> dict:
    if not values:
        return {"median": float("nan"), "p95": float("nan"), "max": float("nan")}
    return {"median": float(np.median(values)), "p95": float(np.percentile(values, 95)), "max": float(np.max(values))}


def _source_timing(episodes: list[dict]) -> dict:
    """``{key: {median, p95, max}}`` of what sources reported (``server_infer_ms``, ``policy_infer_ms``)."""
    keys = sorted({k for e in episodes for k in e.get("source_timing_ms", {}) if k != "round_trip_ms"})
    return {k: _median_p95_max([x for e in episodes for x in e.get("source_timing_ms", {}).get(k, [])]) for k in keys}


def summarize(episodes: list[dict], tick_us: np.ndarray, after_us: np.ndarray | None = None) -> dict:
    """Summary over episodes; ``tick_us`` pools the controller tick times of all episodes, ``after_us`` (optional,
    the same ticks) the work after each command (``EpisodeLog.after_us``)."""
    if not episodes:
        raise ValueError("summarize needs at least one episode")
    n_jumps = sum(e["n_jumps"] for e in episodes)
    recovery = [s for e in episodes for s in e["jump_recovery_s"]]
    return {
        "episodes": len(episodes),
        **_task_summary(episodes),
        "success_rate": float(np.mean([e["success"] for e in episodes])),
        "success_ci95": list(wilson_interval(int(sum(bool(e["success"]) for e in episodes)), len(episodes))),
        "wrong_object_rate": float(np.mean([e.get("wrong_object", False) for e in episodes])),
        "final_error_m": float(np.mean([e["final_error_m"] for e in episodes])),
        "mean_error_m": float(np.mean([e["mean_error_m"] for e in episodes])),
        "mean_error_after_reach_m": _nanmean([e.get("mean_error_after_reach_m", float("nan")) for e in episodes]),
        "time_to_reach_s": _nanmedian([e["time_to_reach_s"] for e in episodes]),
        "tracking_ratio": float(np.mean([e["tracking_ratio"] for e in episodes])),
        "jerk_rms": float(np.mean([e["jerk_rms"] for e in episodes])),
        "chunk_jump_acc_m_s2": float(np.mean([e["chunk_jump_acc_m_s2"] for e in episodes])),
        "limit_violations": int(sum(e["limit_violations"] for e in episodes)),
        **{key: int(sum(e.get(key, 0) for e in episodes)) for key in SAFETY_KEYS.values()},
        "torque_rate_max_nm_s": float(max(e.get("torque_rate_max_nm_s", 0.0) for e in episodes)),
        **{key: int(sum(e.get(key, 0) for e in episodes)) for key in FAULT_KEYS},
        "qp_failures": int(sum(e["qp_failures"] for e in episodes)),
        "mpc_failures": int(sum(e.get("mpc_failures", 0) for e in episodes)),
        "clipped_actions": int(sum(e["clipped_actions"] for e in episodes)),
        "tick_us": {"median": float(np.median(tick_us)), "p99": float(np.percentile(tick_us, 99))},
        "tick_us_max": float(np.max(tick_us)),
        **({"tick_after_us": _median_p99(np.asarray(tick_us) + np.asarray(after_us))}
           if after_us is not None and len(after_us) == len(tick_us) else {}),
        "mpc_solve_us": _median_p99([x for e in episodes for x in e.get("mpc_solve_us", [])]),
        "policy_latency_ms": _median_p99([x for e in episodes for x in e.get("plan_ms", [])]),
        "round_trip_ms": _median_p95_max([x for e in episodes for x in e.get("plan_ms", [])]),
        **_source_timing(episodes),
        "realtime_factor": float(np.mean([e["realtime_factor"] for e in episodes])),
        "measurements_lost_rate": (float(sum(e.get("measurements_lost", 0) for e in episodes)
                                         / max(1, sum(e.get("measurements", 0) for e in episodes)))),
        "sensor_ms_per_sim_s": float(np.mean([e.get("sensor_ms_per_sim_s", 0.0) for e in episodes])),
        "jump_recovered_rate": float(sum(e["jumps_recovered"] for e in episodes) / n_jumps) if n_jumps else float("nan"),
        "jump_recovery_s": _nanmedian(recovery),
        "reaction_s": _nanmedian([e.get("reaction_s", float("nan")) for e in episodes]),
        "reach_after_change_s": _nanmedian([e.get("reach_after_change_s", float("nan")) for e in episodes]),
        "d_measured": _nanmedian([e.get("d_measured", float("nan")) for e in episodes]),
        "d_steps": _median_p95_max([x for e in episodes for x in e.get("d_steps", [])]),
        **_realtime_summary(episodes, int(len(tick_us))),
    }
