"""Tabulate the safety counts of main-job runs: one row per (source, target, mode).

    for src in expert policy; do for tgt in static linear jump random_walk; do
      python -m scenarios.moving_target --source $src --target $tgt --episodes 20 \\
        --mode open_loop receding temporal_ensemble inpaint hybrid --json out/matrix/${src}_${tgt}.json
    done; done
    python -m scenarios.safety_table out/matrix/*.json --out docs/results/safety_matrix.md

Every count is summed over the episodes of the run (ticks flagged by ``controllers.safety.SafetyMonitor``);
success carries its 95 % Wilson interval.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from mmact_ctrl.stats import wilson_interval

COLUMNS: tuple[tuple[str, str], ...] = (
    ("torque rate > 1000 N m/s", "torque_rate_violations"),
    ("max torque rate [N m/s]", "torque_rate_max_nm_s"),
    ("non-finite", "nonfinite_commands"),
    ("accel", "accel_violations"),
    ("jerk", "jerk_violations"),
    ("joint pos / vel / torque", ("position_violations", "velocity_violations", "torque_violations")),
    ("TCP speed", "tcp_speed_violations"),
    ("all kinds", "limit_violations"),
    ("QP fallbacks", "qp_failures"),
    ("rejected chunks", "rejected_chunks"),
    ("watchdog stops", "watchdog_stops"),
)


def _cell(summary: dict, key) -> str:
    if isinstance(key, tuple):
        return " / ".join(str(int(summary.get(k, 0))) for k in key)
    value = summary.get(key, 0)
    return f"{value:.0f}" if isinstance(value, float) else str(int(value))


def table(payloads: list[dict]) -> tuple[str, dict]:
    """Markdown table and the totals over every run."""
    head = ["source", "target", "mode", "episodes", "success (95 % CI)", "final error [mm]"] + [c for c, _ in COLUMNS]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    totals = {"episodes": 0, "limit_violations": 0, "torque_rate_violations": 0, "nonfinite_commands": 0,
              "accel_violations": 0, "jerk_violations": 0, "torque_rate_max_nm_s": 0.0}
    for payload in payloads:
        cfg = payload["config"]
        for mode, run in payload["runs"].items():
            s = run["summary"]
            n = int(s["episodes"])
            k = round(s["success_rate"] * n)
            lo, hi = wilson_interval(k, n)
            row = [cfg["source"], cfg["target"], mode, str(n), f"{k}/{n} ({lo:.0%}-{hi:.0%})",
                   f"{1e3 * s['final_error_m']:.1f}"] + [_cell(s, key) for _, key in COLUMNS]
            lines.append("| " + " | ".join(row) + " |")
            totals["episodes"] += n
            for key in totals:
                if key == "torque_rate_max_nm_s":
                    totals[key] = max(totals[key], float(s.get(key, 0.0)))
                elif key != "episodes":
                    totals[key] += int(s.get(key, 0))
    return "\n".join(lines), totals


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m scenarios.safety_table", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("json", nargs="+", help="--json files written by python -m scenarios.moving_target")
    p.add_argument("--out", metavar="PATH", help="write the markdown here (default: print it)")
    args = p.parse_args(argv)
    payloads = []
    for path in args.json:
        try:
            payloads.append(json.loads(Path(path).read_text()))
        except (OSError, ValueError) as exc:
            p.error(f"cannot read {path}: {exc}")
    body, totals = table(payloads)
    text = (f"# Safety counts of the main job, every mode\n\n{totals['episodes']} episodes; over all of them: "
            f"{totals['limit_violations']} flagged ticks of any kind, {totals['torque_rate_violations']} above "
            f"1000 N m/s (largest rate sent {totals['torque_rate_max_nm_s']:.0f} N m/s), "
            f"{totals['nonfinite_commands']} non-finite, {totals['accel_violations']} acceleration and "
            f"{totals['jerk_violations']} jerk violations.\n\nCommands: see `python -m scenarios.safety_table --help`."
            f"\n\n{body}\n")
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(text)
        print(f"wrote {args.out}")
    else:
        print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
