"""What one episode recorded (``EpisodeLog``), and the link that may drop commands (``CommandLink``)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np


@dataclass
class EpisodeLog:
    """Everything recorded in one episode (arrays sampled every control period; shorter than the episode
    when it was aborted).

    Safety (``controllers.safety``): ``safety_counts`` ticks flagged per kind, ``safety_mask`` the per-tick
    bitmask, ``torque_rate_max_nm_s`` the largest torque rate sent. Faults survived: ``rejections`` chunks
    rejected per reason (``mmact_ctrl.chunk_intake``), ``watchdog_stops``, ``gated_measurements`` (per gate),
    ``missed_ticks``; ``abort`` is ``{"t_s", "reason"}`` when the robot would have aborted the motion.
    ``events`` lists ``(t_s, what, detail)`` of every fault handled; ``source_errors`` what the source said when it
    failed (``{"t_s", "count", "line", "text"}`` per distinct text, the text whole: a policy server's traceback). ``change_times_s``: when the target's motion
    changed course (``World.target_change_times_s``); ``delay_steps``: per activated chunk, the waypoints of the
    running chunk consumed while it was computed (activation time minus observation time, in chunk steps: the
    inference delay d of RTC, as it actually ran); ``mpc_solve_us``: the wall time of each MPC solve, us (beside the
    1 kHz path: not in ``tick_us``). ``tick_us``: per tick, the command path (state -> checked command) as real time
    runs it; ``after_us``: per tick, the work real time does on the loop's thread after the command is out (fusing
    the measurements that arrived, the MPC's 50 Hz update: reference, preview, problem); simulated time does the same
    work before the command (results unchanged) and records it here too. Real time: ``late_commands`` commands computed after their cycle's deadline (they
    count in ``missed_ticks`` too: the robot re-applied the last torque), ``deadline`` the pacer's statistics
    (``mmact_ctrl.realtime.pacer``) with its per-tick ``rt_exec_us`` / ``rt_cpu_us`` (the loop thread's CPU time in the
    work) / ``rt_jitter_us`` / ``rt_late_ticks``,
    ``recording`` (when the runner records: the target
    estimate at 100 Hz, the activated chunks, the MPC previews and the frames each query was answered from).
    """

    seed: int
    t_s: np.ndarray
    ee_pos_m: np.ndarray
    target_pos_m: np.ndarray
    ref_pos_m: np.ndarray
    q_rad: np.ndarray
    dq_rad_s: np.ndarray
    tau_cmd_nm: np.ndarray
    tick_us: np.ndarray
    safety_mask: np.ndarray | None = None
    after_us: np.ndarray | None = None
    chunk_active_s: list[float] = field(default_factory=list)
    plan_ms: list[float] = field(default_factory=list)
    jump_times_s: tuple[float, ...] = ()
    change_times_s: tuple[float, ...] = ()
    delay_steps: list[float] = field(default_factory=list)
    source_timing_ms: dict[str, list[float]] = field(default_factory=dict)
    objects_pos_m: np.ndarray | None = None  # (n, n_objects, 3) when the world has several objects
    target_index: int = 0
    qp_failures: int = 0
    smoother_failures: int = 0
    mpc_failures: int = 0
    clipped_actions: int = 0
    wall_s: float = 0.0
    instruction: str = ""
    frames: list[np.ndarray] = field(default_factory=list)
    safety_counts: dict[str, int] = field(default_factory=dict)
    #: the task's own figures (``World.task_report()`` of a contact task: its success predicate, time to grasp, ...);
    #: None for reach, whose figures are these arrays'
    task: dict | None = None
    torque_rate_max_nm_s: float = 0.0
    rejections: dict[str, int] = field(default_factory=dict)
    watchdog_stops: int = 0
    gated_measurements: dict[str, int] = field(default_factory=dict)
    perception_errors: int = 0
    measurements: int = 0
    measurements_lost: int = 0
    sensor_wall_s: float = 0.0
    sensor_stats: dict = field(default_factory=dict)
    missed_ticks: int = 0
    rate_clamps: int = 0
    qp_rescues: int = 0
    plan_resyncs: int = 0
    floor_clamps: int = 0
    mpc_bypass_ticks: int = 0
    mpc_solve_us: list[float] = field(default_factory=list)
    late_commands: int = 0
    recording: dict | None = None
    deadline: dict | None = None
    rt_exec_us: np.ndarray | None = None
    rt_jitter_us: np.ndarray | None = None
    rt_cpu_us: np.ndarray | None = None
    rt_late_ticks: np.ndarray | None = None
    abort: dict | None = None
    events: list[tuple[float, str, str]] = field(default_factory=list)
    source_errors: list[dict] = field(default_factory=list)

    def truncate(self, n: int) -> None:
        """Keep the first ``n`` samples (an aborted episode)."""
        for name in ("t_s", "ee_pos_m", "target_pos_m", "ref_pos_m", "q_rad", "dq_rad_s", "tau_cmd_nm", "tick_us",
                     "after_us", "safety_mask", "objects_pos_m"):
            value = getattr(self, name)
            if value is not None:
                setattr(self, name, value[:n])


class CommandLink(Protocol):
    """The link from the controller to the robot: whether the command of tick ``k`` reaches it."""

    def delivered(self, k: int, t_s: float) -> bool:
        ...
