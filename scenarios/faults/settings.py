"""Settings of the fault suite: its command, its sources, the quick suite, recovery, and the columns of
``faults.csv``."""

from __future__ import annotations

PROG = "python -m scenarios.faults"
SOURCES: tuple[str, ...] = ("expert", "policy")
#: the episode whose torques ``fault_torque.png`` shows (fault, mode, source; the first seed).
PLOT_CELL = ("qp_fail_burst", "hybrid", "expert")
#: recovery: the TCP back within this distance of the target, for this long.
RECOVERY_RADIUS_M = 0.03
RECOVERY_HOLD_S = 0.3
#: quick mode: seeds, episode length, sources (timed on the shared 2-core machine: all 22 faults x 5 modes x
#: both sources x 1 seed x 3 s take about 80-100 s sequentially).
QUICK_SEEDS = 1
#: the modes the suite runs by default on a contact task (``--task pick|insert``)
CONTACT_MODES = ("open_loop", "hybrid")
QUICK_DURATION_S = 3.0
QUICK_ONSET_S = 0.5  # the 1.5 s windows end at 2.0 s, when the source is next asked (1 Hz): 0.8 s left to recover
QUICK_SOURCES: tuple[str, ...] = ("expert", "policy")
#: the faults whose abort is expected (and required): 20 missed ticks in a row.
EXPECTED_ABORTS: tuple[str, ...] = ("missed_ticks_20",)
SAFETY_COLUMNS: tuple[str, ...] = (
    "limit_violations", "torque_rate_violations", "accel_violations", "jerk_violations", "nonfinite_commands",
    "position_violations", "velocity_violations", "torque_violations", "tcp_speed_violations", "contact_force_violations",
)
VIOLATION_KINDS: tuple[str, ...] = SAFETY_COLUMNS[1:]
COLUMNS: tuple[str, ...] = (
    "fault", "mode", "source", "seed", "applicable", "success", "final_error_m", *SAFETY_COLUMNS,
    "torque_rate_max_nm_s", "rejected_chunks", "rejections", "watchdog_stops", "gated_measurements", "gated",
    "missed_ticks", "aborts", "abort_reason", "abort_t_s", "qp_failures", "qp_rescues", "mpc_failures",
    "perception_errors", "raised", "recovery_s", "fault_start_s", "fault_end_s", "wall_s",
)
