"""Terminal table and JSON output of runs (one run = one configuration, several episodes)."""

from __future__ import annotations

import json
import math
from pathlib import Path

TABLE_ROWS: tuple[tuple[str, str, str], ...] = (
    # (label, summary key, format)
    ("success rate", "success_rate", "{:.0%}"),
    ("  95 % interval (Wilson)", "success_ci95", "ci"),
    ("wrong object", "wrong_object_rate", "{:.0%}"),
    ("final error [mm]", "final_error_m", "mm"),
    ("mean error [mm]", "mean_error_m", "mm"),
    ("  after first reach [mm]", "mean_error_after_reach_m", "mm"),
    ("time to reach [s]", "time_to_reach_s", "{:.2f}"),
    ("tracking ratio", "tracking_ratio", "{:.2f}"),
    ("jerk RMS [m/s^3]", "jerk_rms", "{:.1f}"),
    ("chunk-switch acc [m/s^2]", "chunk_jump_acc_m_s2", "{:.2f}"),
    ("limit violations (all kinds)", "limit_violations", "{:d}"),
    ("  torque rate > 1000 N m/s", "torque_rate_violations", "{:d}"),
    ("  accel / jerk", ("accel_violations", "jerk_violations"), "{:d} / {:d}"),
    ("  non-finite commands", "nonfinite_commands", "{:d}"),
    ("max torque rate [N m/s]", "torque_rate_max_nm_s", "{:.0f}"),
    ("rejected chunks", "rejected_chunks", "{:d}"),
    ("watchdog stops", "watchdog_stops", "{:d}"),
    ("gated measurements", "gated_measurements", "{:d}"),
    ("aborts", "aborts", "{:d}"),
    ("QP failures", "qp_failures", "{:d}"),
    ("MPC failures/late", "mpc_failures", "{:d}"),
    ("tick median [us]", "tick_us.median", "{:.0f}"),
    ("tick p99 [us]", "tick_us.p99", "{:.0f}"),
    ("  with after-command work p99 [us]", "tick_after_us.p99", "{:.0f}"),
    ("MPC solve median / p99 [us]", ("mpc_solve_us.median", "mpc_solve_us.p99"), "{:.0f} / {:.0f}"),
    ("real-time factor", "realtime_factor", "{:.1f}x"),
    ("chunk source [ms]", "policy_latency_ms.median", "{:.1f}"),
    ("  round trip p95 / max [ms]", ("round_trip_ms.p95", "round_trip_ms.max"), "{:.1f} / {:.1f}"),
    ("  server infer [ms]", "server_infer_ms.median", "{:.1f}"),
    ("jumps recovered <1 s", "jump_recovered_rate", "{:.0%}"),
    ("reaction to a change [s]", "reaction_s", "{:.2f}"),
    ("reach after a change [s]", "reach_after_change_s", "{:.2f}"),
    ("inference delay d [steps]", "d_measured", "{:.1f}"),
    ("real time: overruns", ("overruns", "overrun_rate"), "{:d} ({:.2%})"),
    ("  cycles missed", "cycles_missed", "{:d}"),
    ("  tick work median / p99 [us]", ("exec_us.median", "exec_us.p99"), "{:.0f} / {:.0f}"),
    ("  start jitter p99 [us]", "jitter_us_p99", "{:.0f}"),
    ("  command success rate (min)", "control_command_success_rate", "{:.3f}"),
    ("  real-time rate", "realtime_rate", "{:.3f}"),
    ("measurements lost", "measurements_lost_rate", "{:.0%}"),
    ("sensor [ms per sim s]", "sensor_ms_per_sim_s", "{:.0f}"),
)


def _get(summary: dict, key):
    if isinstance(key, tuple):
        return tuple(_get(summary, k) for k in key)
    value = summary
    for part in key.split("."):
        value = value.get(part) if isinstance(value, dict) else None
    return value


def _fmt(value, fmt: str) -> str:
    if isinstance(value, tuple):
        bad = any(v is None or (isinstance(v, float) and math.isnan(v)) for v in value)
        return "-" if bad else fmt.format(*value)
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    if fmt == "ci":
        return f"{100 * value[0]:.0f}-{100 * value[1]:.0f}%" if isinstance(value, (list, tuple)) and len(value) == 2 else "-"
    if fmt == "mm":
        return f"{1000.0 * value:.1f}"
    return fmt.format(value)


#: rows left out when no run has them (real-time statistics in a simulated-time run, a source that reports no
#: server timing)
OPTIONAL_ROWS: frozenset[str] = frozenset({
    "  server infer [ms]", "real time: overruns", "  cycles missed", "  tick work median / p99 [us]",
    "  start jitter p99 [us]", "  command success rate (min)", "  real-time rate"})


def format_table(summaries: dict[str, dict]) -> str:
    """Side-by-side table: one column per run name."""
    names = list(summaries)
    width0 = max(len(r[0]) for r in TABLE_ROWS)
    widths = [max(10, len(n)) for n in names]
    lines = [" " * width0 + "  " + "  ".join(n.rjust(w) for n, w in zip(names, widths))]
    lines.append("-" * len(lines[0]))
    for label, key, fmt in TABLE_ROWS:
        texts = [_fmt(_get(summaries[n], key), fmt) for n in names]
        if label in OPTIONAL_ROWS and all(t == "-" for t in texts):
            continue
        cells = [t.rjust(w) for t, w in zip(texts, widths)]
        lines.append(label.ljust(width0) + "  " + "  ".join(cells))
    return "\n".join(lines)


def _clean(obj):
    """JSON-safe copy: NaN/inf -> None, numpy scalars -> Python."""
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if hasattr(obj, "item") and not isinstance(obj, (str, bytes)):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def write_json(path: str | Path, payload: dict) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(_clean(payload), indent=2))
