"""The real-time figures of ``mmact_ctrl.metrics``: an episode's deadline statistics and the late ticks it
describes, and their summary over a run's episodes (``--realtime``, ``mmact_ctrl.realtime.pacer``; empty in
simulated time)."""

from __future__ import annotations

import numpy as np

from mmact_ctrl.episode_log import EpisodeLog


def _realtime_episode(log: EpisodeLog) -> dict:
    """The deadline statistics of a real-time episode (empty in simulated time)."""
    d = log.deadline
    if not d or not d.get("ticks"):
        return {}
    return {
        "realtime": True,
        "overruns": int(d["overruns"]),
        "overrun_rate": float(d["overrun_rate"]),
        "cycles_missed": int(d["cycles_missed"]),
        "late_commands": int(log.late_commands),
        "exec_us_median": float(d["exec_us"]["median"]),
        "exec_us_p99": float(d["exec_us"]["p99"]),
        "exec_us_max": float(d["exec_us"]["max"]),
        "jitter_us_std": float(d["jitter_us"]["std"]),
        "jitter_us_p99": float(d["jitter_us"]["p99"]),
        "control_command_success_rate": float(d["control_command_success_rate"]),
        "realtime_rate": float(d["realtime_rate"]),
        "exec_us": [float(x) for x in (log.rt_exec_us if log.rt_exec_us is not None else [])],
        "late_ticks": _late_ticks(log),
    }


#: at most this many late ticks are described per episode
MAX_LATE_TICKS = 100


def _late_ticks(log: EpisodeLog) -> list[dict]:
    """Each tick whose command was late (the first ``MAX_LATE_TICKS``): its index, how late it started, its whole
    work, the loop thread's CPU time in that work, its command path and its after-command work, us: whether a late
    command came from our work (a long command path) or from outside it (a late start; CPU time well under the work:
    the thread did not run; CPU time equal to a work far above the usual: the CPU ran slowly, a contended host, which
    ``python -m mmact_ctrl.realtime.host_check`` measures with no work of ours)."""
    late = log.rt_late_ticks
    if late is None or not len(late):
        return []

    def at(series, k: int) -> float | None:
        return float(series[k]) if series is not None and 0 <= k < len(series) else None

    return [{"k": int(k), "start_late_us": at(log.rt_jitter_us, int(k)), "work_us": at(log.rt_exec_us, int(k)),
             "cpu_us": at(log.rt_cpu_us, int(k)), "command_path_us": at(log.tick_us, int(k)),
             "after_us": at(log.after_us, int(k))}
            for k in np.asarray(late, dtype=int)[:MAX_LATE_TICKS]]


def _realtime_summary(episodes: list[dict], ticks: int) -> dict:
    """Deadline statistics over the real-time episodes of a run (pooled ticks), empty in simulated time."""
    rt = [e for e in episodes if e.get("realtime")]
    if not rt:
        return {}
    exec_us = np.concatenate([np.asarray(e.get("exec_us", []), dtype=float) for e in rt]) if rt else np.zeros(0)
    overruns = int(sum(e["overruns"] for e in rt))
    return {
        "realtime": True,
        "overruns": overruns,
        "overrun_rate": float(overruns / max(1, ticks)),
        "cycles_missed": int(sum(e["cycles_missed"] for e in rt)),
        "exec_us": ({"median": float(np.median(exec_us)), "p99": float(np.percentile(exec_us, 99)),
                     "max": float(np.max(exec_us))} if exec_us.size else {}),
        "jitter_us_p99": float(max(e["jitter_us_p99"] for e in rt)),
        "control_command_success_rate": float(min(e["control_command_success_rate"] for e in rt)),
        "realtime_rate": float(np.mean([e["realtime_rate"] for e in rt])),
    }
