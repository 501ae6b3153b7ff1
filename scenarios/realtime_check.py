"""The validity check of the study: the same seeds in real time and in simulated time with the measured latency.

    python -m scenarios.realtime_check --out docs/realtime/check                  # expert, every mode, linear + reversal
    python -m scenarios.realtime_check --source policy --modes open_loop hybrid --episodes 10 --out ...

For each target it runs every mode in real time (``--realtime``: the source in its own process, the chunk active
when it arrives), takes the median chunk round trip measured there, then runs the same seeds in simulated time with
``--latency-ms`` set to that median (and the same MPC phase and QP iteration cap). ``OUT/report.md`` has, per target
and mode, both success rates with 95 % Wilson intervals, the paired difference (real minus simulated: Newcombe's
interval, exact McNemar) and the mean paired difference of the final error (t-interval, Wilcoxon), and says plainly
where the simulated-latency figures are optimistic. ``OUT/results.json`` holds both runs.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from controllers.qp_id import REALTIME_MAX_ITER
from mmact_ctrl.config import MODES
from mmact_ctrl.report import write_json
from mmact_ctrl.stats import paired_binary, paired_continuous, wilson_interval

PROG = "python -m scenarios.realtime_check"


def build_parser() -> argparse.ArgumentParser:
    from scenarios.cli import OneLineErrorParser as _OneLineErrorParser
    from scenarios.cli import number as _number
    from scenarios.sources import source_spec_arg
    from scenarios.world.targets import KINDS

    p = _OneLineErrorParser(prog=PROG, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--source", type=source_spec_arg, default="expert",
                   help="the chunk source (policy, expert, module:factory, ws://HOST:PORT); default expert")
    p.add_argument("--source-arg", action="append", default=[], metavar="KEY=VALUE", help="for a module:factory source")
    p.add_argument("--checkpoint", default=None, help="policy checkpoint (default: the shipped one)")
    p.add_argument("--modes", nargs="+", choices=MODES, default=list(MODES), help="execution modes (default: all)")
    p.add_argument("--targets", nargs="+", choices=KINDS, default=["linear", "reversal"], help="target motions")
    p.add_argument("--speed", type=_number(float, "--speed", 0, True, 1.7), default=0.2, help="target speed (m/s)")
    p.add_argument("--replan-hz", type=_number(float, "--replan-hz", 0, False, 100.0), default=1.0,
                   help="how often the source is queried (Hz)")
    p.add_argument("--episodes", type=_number(int, "--episodes", 1), default=10, help="seeds per mode and target")
    p.add_argument("--duration-s", type=_number(float, "--duration-s", 0, False), default=6.0, help="episode length (s)")
    p.add_argument("--rt-priority", type=_number(int, "--rt-priority", 0, True, 99), default=10,
                   help="SCHED_FIFO priority of the real-time loop's thread (0: normal scheduling)")
    p.add_argument("--qp-max-iter", type=_number(int, "--qp-max-iter", 1, True, 100000), default=REALTIME_MAX_ITER,
                   help="OSQP's iteration cap in the QP, the same in both runs so that only time differs (default: "
                        "the real-time cap)")
    p.add_argument("--out", metavar="DIR", required=True, help="output directory (report.md, results.json)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p


def _main_job_args(args, target: str, realtime: bool, latency_ms: float | None = None) -> argparse.Namespace:
    from scenarios.moving_target import build_parser as mt_parser

    argv = ["--source", args.source, "--target", target, "--speed", str(args.speed), "--replan-hz", str(args.replan_hz),
            "--episodes", str(args.episodes), "--duration-s", str(args.duration_s), "--mpc-phase-ms", "5",
            "--mode", *args.modes, "--quiet", "--qp-max-iter", str(args.qp_max_iter)]
    for item in args.source_arg:
        argv += ["--source-arg", item]
    if args.checkpoint:
        argv += ["--checkpoint", args.checkpoint]
    if realtime:
        argv += ["--realtime", "--rt-priority", str(args.rt_priority)]
    else:
        argv += ["--latency-ms", f"{latency_ms:.3f}"]
    ns = mt_parser().parse_args(argv)
    ns.mode = list(dict.fromkeys(ns.mode))
    return ns


def compare(real: dict, sim: dict) -> list[dict]:
    """Per mode: both runs' success and final error, and the paired differences (real minus simulated)."""
    rows = []
    for mode, run in real["runs"].items():
        er, es = run["episodes"], sim["runs"][mode]["episodes"]
        sr, ss = [bool(e["success"]) for e in er], [bool(e["success"]) for e in es]
        fr, fs = [e["final_error_m"] for e in er], [e["final_error_m"] for e in es]
        b, c = paired_binary(sr, ss), paired_continuous(fr, fs)
        summ = run["summary"]
        rows.append({
            "mode": mode, "n": len(er),
            "real_success": sum(sr), "real_ci95": list(wilson_interval(sum(sr), len(sr))),
            "sim_success": sum(ss), "sim_ci95": list(wilson_interval(sum(ss), len(ss))),
            "diff_success": b["diff"], "diff_lo": b["diff_lo"], "diff_hi": b["diff_hi"], "p_mcnemar": b["p_mcnemar"],
            "real_final_mm": 1e3 * float(np.mean(fr)), "sim_final_mm": 1e3 * float(np.mean(fs)),
            "diff_final_mm": 1e3 * c["mean_diff"], "diff_final_lo_mm": 1e3 * c["diff_lo"],
            "diff_final_hi_mm": 1e3 * c["diff_hi"], "p_wilcoxon": c["p_wilcoxon"],
            "round_trip_ms": summ.get("round_trip_ms", {}), "d_steps": summ.get("d_steps", {}),
            "overruns": summ.get("overruns"), "overrun_rate": summ.get("overrun_rate"),
            "control_command_success_rate": summ.get("control_command_success_rate"),
            "violations": summ.get("limit_violations"), "sim_violations": sim["runs"][mode]["summary"]["limit_violations"],
        })
    return rows


def _rate(value) -> str:
    """A success rate in three decimals ('-' when there is none)."""
    return "-" if value is None or value != value else f"{float(value):.3f}"


#: a mean final-error difference smaller than this is negligible, however significant: below the target sensor's
#: noise (2 mm) and the success radius's resolution. Identical runs that differ by float rounding (tens of nanometres,
#: all of one sign) are otherwise "significant" to a rank test.
NEGLIGIBLE_FINAL_MM = 1.0


def _verdict(r: dict) -> str:
    if r["p_mcnemar"] < 0.05 and r["diff_success"] < 0:
        return "**simulated is optimistic** (success)"
    if r["p_mcnemar"] < 0.05 and r["diff_success"] > 0:
        return "real time is better (success)"
    if np.isfinite(r["p_wilcoxon"]) and r["p_wilcoxon"] < 0.05:
        if abs(r["diff_final_mm"]) < NEGLIGIBLE_FINAL_MM:
            return f"significant but negligible (final error, {r['diff_final_mm']:+.2g} mm)"
        return "**simulated is optimistic** (final error)" if r["diff_final_mm"] > 0 else "real time is better (final error)"
    return "no significant difference"


def report(results: dict, args) -> str:
    lines = ["# Real time vs simulated time, same seeds", "",
             f"- command: `{' '.join([PROG, *sys.argv[1:]])}`",
             f"- source {args.source}, modes {', '.join(args.modes)}, {args.episodes} seeds per cell, "
             f"{args.duration_s:g} s episodes, replan {args.replan_hz:g} Hz, target speed {args.speed:g} m/s",
             "- real time: the loop on the wall clock at 1 kHz, the source in its own process, each chunk active when "
             "it arrives; simulated: the same seeds with `--latency-ms` = the median round trip measured in real time; "
             f"both with the MPC phase 5 ms and the QP's iteration cap {args.qp_max_iter}.",
             "- success: successes/n [95 % Wilson]; Δ = real minus simulated (Newcombe's paired interval, exact "
             "McNemar); final error: mean, Δ mean paired difference [95 % t-interval], Wilcoxon.", ""]
    for target, res in results.items():
        lines += [f"## {target} (measured median round trip {res['latency_ms']:.1f} ms)", "",
                  "| mode | real success | simulated success | Δ success [95 %] (p) | real / sim final [mm] | "
                  "Δ final [mm] [95 %] (p) | round trip median / p95 / max [ms] | d median / max [steps] | "
                  "overruns (rate) | command success (min) | violations real / sim | verdict |",
                  "|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in res["rows"]:
            rt, d = r["round_trip_ms"] or {}, r["d_steps"] or {}
            lines.append(
                f"| {r['mode']} | {r['real_success']}/{r['n']} [{100 * r['real_ci95'][0]:.0f}-{100 * r['real_ci95'][1]:.0f}] | "
                f"{r['sim_success']}/{r['n']} [{100 * r['sim_ci95'][0]:.0f}-{100 * r['sim_ci95'][1]:.0f}] | "
                f"{100 * r['diff_success']:+.0f} [{100 * r['diff_lo']:+.0f}, {100 * r['diff_hi']:+.0f}] ({r['p_mcnemar']:.2f}) | "
                f"{r['real_final_mm']:.1f} / {r['sim_final_mm']:.1f} | {r['diff_final_mm']:+.1f} "
                f"[{r['diff_final_lo_mm']:+.1f}, {r['diff_final_hi_mm']:+.1f}] ({r['p_wilcoxon']:.2f}) | "
                f"{rt.get('median', float('nan')):.1f} / {rt.get('p95', float('nan')):.1f} / {rt.get('max', float('nan')):.1f} | "
                f"{d.get('median', float('nan')):.2f} / {d.get('max', float('nan')):.2f} | "
                f"{r['overruns']} ({100 * (r['overrun_rate'] or 0):.2f} %) | {_rate(r['control_command_success_rate'])} | "
                f"{r['violations']} / {r['sim_violations']} | {_verdict(r)} |")
        lines.append("")
    optimistic = [(t, r["mode"]) for t, res in results.items() for r in res["rows"] if "optimistic" in _verdict(r)]
    lines += ["## Where the simulated-latency figures are optimistic", "",
              ("- " + ", ".join(f"{m} on {t}" for t, m in optimistic)) if optimistic else
              "- nowhere significantly (p < 0.05) on these seeds; the comparison is not corrected for multiple tests.",
              f"- a final-error difference under {NEGLIGIBLE_FINAL_MM:g} mm is called negligible whatever its p-value.", ""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    from scenarios.moving_target import run

    parser = build_parser()
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results = {}
    t0 = time.perf_counter()
    try:
        for target in args.targets:
            real = run(_main_job_args(args, target, realtime=True))
            real.pop("_logs", None)
            rts = [x for m in real["runs"].values() for e in m["episodes"] for x in e.get("plan_ms", [])]
            latency_ms = float(np.median(rts)) if rts else 0.0
            sim = run(_main_job_args(args, target, realtime=False, latency_ms=latency_ms))
            sim.pop("_logs", None)
            results[target] = {"latency_ms": latency_ms, "rows": compare(real, sim), "real": real, "sim": sim}
            print(f"{target}: measured median round trip {latency_ms:.1f} ms ({time.perf_counter() - t0:.0f} s)",
                  flush=True)
    except (ValueError, RuntimeError, ConnectionError) as exc:
        parser.error(str(exc).splitlines()[0])
    text = report(results, args)
    (out / "report.md").write_text(text)
    # the rows and each run's summaries (the episodes are in the main job's JSON when it is asked for)
    write_json(out / "results.json", {t: {"latency_ms": r["latency_ms"], "rows": r["rows"],
                                          "real": {m: run["summary"] for m, run in r["real"]["runs"].items()},
                                          "sim": {m: run["summary"] for m, run in r["sim"]["runs"].items()}}
                                      for t, r in results.items()})
    print(text)
    print(f"wrote {out / 'report.md'}, {out / 'results.json'} ({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
