"""The fault-injection suite: every fault of ``scenarios.faults.injectors.FAULTS`` x execution modes x seeds, with
the scripted expert and with the learned policy, checking that nothing escapes the loop and nothing unsafe is sent.

    python -m scenarios.faults --quick --out /tmp/faults_quick     # every fault x every mode, 1 seed, 3 s, ~1-2 min
    python -m scenarios.faults --out out/faults                    # 3 seeds x 4 s, both sources
    python -m scenarios.faults --faults qp_fail_burst missed_ticks_19 --modes hybrid --sources expert --seeds 5

Writes ``OUT/faults.csv`` (one row per episode), ``OUT/report.md`` (how it was run, a fault x mode table per
source, what each fault cost versus the ``none`` row, the totals) with ``OUT/fault_torque.png`` (commanded
torque and torque rate around the onset of one fault), and ``OUT/summary.json`` (totals and per-cell table).
Exit status 0 when the suite ran, whatever it found; an exception inside an episode is caught, counted and
reported (column ``raised``), never fatal.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import shlex
import sys
import time
import traceback
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from mmact_ctrl.config import MODES
from scenarios.faults.injectors import FAULTS, FaultSpec
from scenarios.sources import source_spec_arg
from scenarios.world.tasks.registry import TASKS, task_stack_settings

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


# ---- command line ----------------------------------------------------------------------------------


def _choice(kind: str, allowed) -> callable:
    allowed = tuple(allowed)

    def parse(text: str) -> str:
        if text not in allowed:
            raise argparse.ArgumentTypeError(f"unknown {kind} {text!r}; expected one of {' '.join(allowed)}")
        return text

    return parse


class _DefaultsFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Shows defaults, except the None of options whose default depends on --quick (their help says it)."""

    def _get_help_string(self, action):
        if action.default is None:
            return action.help
        return super()._get_help_string(action)


def build_parser() -> argparse.ArgumentParser:
    from scenarios.cli import OneLineErrorParser as _OneLineErrorParser
    from scenarios.cli import number as _number
    from scenarios.world.targets import KINDS as TARGET_KINDS

    p = _OneLineErrorParser(
        prog=PROG,
        description=(
            "Fault-injection suite: runs every fault (source crashes, NaN chunks, garbage tokens, spliced or late "
            "chunks, silence, perception dropout/frozen/outliers/NaN, QP and MPC fallbacks, missed ticks, a moving "
            "start, an unreachable or near-singular target) in every execution mode, with the scripted expert and "
            "the learned policy, and reports success, every safety violation, exceptions and aborts."
        ),
        epilog=(
            f"--quick: {QUICK_SEEDS} seed, {QUICK_DURATION_S:g} s episodes, onset {QUICK_ONSET_S:g} s, every fault x "
            "every mode with both sources "
            f"({len(FAULTS)} x {len(MODES)} x 2 = {len(FAULTS) * len(MODES) * 2} episodes; about 1.5 min on the 2-core "
            "machine, under 2 min); an explicit --seeds / --duration-s / --onset-s / --sources overrides it. "
            f"Faults: {' '.join(FAULTS)}."
        ),
        formatter_class=_DefaultsFormatter,
    )
    p.add_argument("--faults", nargs="+", type=_choice("fault", FAULTS), default=None, metavar="NAME",
                   help="faults to inject (default: all)")
    p.add_argument("--modes", nargs="+", type=_choice("mode", MODES), default=None, metavar="MODE",
                   help=f"execution modes (default: all: {' '.join(MODES)})")
    p.add_argument("--sources", nargs="+", type=source_spec_arg, default=None, metavar="SOURCE",
                   help="chunk sources: expert (scripted), policy (the shipped learned policy), module.path:factory or "
                        "file.py:factory (your own), ws://HOST:PORT (a policy server); default expert and policy")
    p.add_argument("--source", action="append", type=source_spec_arg, default=None, metavar="SOURCE",
                   help="one more chunk source, as in moving_target and the sweep (repeatable; joins --sources; alone "
                        "it replaces the default pair)")
    p.add_argument("--source-arg", action="append", default=[], metavar="KEY=VALUE",
                   help="a keyword setting for the module:factory sources (repeatable; VALUE read as JSON when it parses)")
    p.add_argument("--seeds", type=_number(int, "--seeds", 1), default=None, help="seeds per cell (default 3, 1 with --quick)")
    p.add_argument("--seed", type=_number(int, "--seed", 0), default=0, help="first seed")
    p.add_argument("--target", choices=TARGET_KINDS, default="static",
                   help="how the target moves (static: every mode reaches it without a fault, so the cost of each "
                        "fault shows in every column)")
    p.add_argument("--speed", type=_number(float, "--speed", 0), default=0.2, help="target speed (m/s)")
    p.add_argument("--duration-s", type=_number(float, "--duration-s", 0, False), default=None,
                   help="episode length (s; default 5, 3 with --quick)")
    p.add_argument("--onset-s", type=_number(float, "--onset-s", 0), default=None,
                   help="fault onset (s; default 0.5, during the approach, also with --quick)")
    p.add_argument("--task", choices=TASKS, default="reach",
                   help="the task every episode runs (scenarios.world.tasks): reach, pick or insert (the expert then "
                        "is the task's; default: reach)")
    p.add_argument("--out", metavar="DIR", default="out/faults", help="output directory")
    p.add_argument("--quick", action="store_true", help="the quick suite (see below)")
    p.add_argument("--workers", type=_number(int, "--workers", 1), default=1,
                   help="parallel processes (each builds its own world and source)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p


# ---- one episode -------------------------------------------------------------------------------------

_CACHE: dict = {}


def _source_key(spec: str, args: dict | None) -> tuple:
    return ("source", spec, json.dumps(args or {}, sort_keys=True))


def _world(source: str, target: str, speed: float, source_args: dict | None = None, task: str = "reach"):
    from scenarios.world.factory import make_world
    from scenarios.sources import scene_settings

    key = ("world", _source_key(source, source_args), target, speed, task)
    if key not in _CACHE:  # any source but the expert: the scenes it asks for (our policy's plane and cameras)
        extra = {"n_objects": 2, **(scene_settings(_source(source, source_args)) if source != "expert" else {})}
        _CACHE[key] = make_world(target, speed, **extra, **({"task": task} if task != "reach" else {}))
    return _CACHE[key]


def _source(source: str, source_args: dict | None = None, world=None):
    """The cell's chunk source (``scenarios.sources``): a fresh expert (a contact task's, leading the object, when
    ``world`` is one), any other built once per process."""
    from scenarios.sources import SourceSettings, build_source

    if source == "expert":
        from scenarios.world.factory import make_expert

        if world is not None and world.scene.task != "reach":
            return make_expert(lead="velocity", world=world)
        return make_expert()
    key = _source_key(source, source_args)
    if key not in _CACHE:
        _CACHE[key] = build_source(SourceSettings(spec=source, args=dict(source_args or {})))
    return _CACHE[key]


def _model():
    if "model" not in _CACHE:
        from controllers.robot_model import PandaModel

        _CACHE["model"] = PandaModel()
    return _CACHE["model"]


def recovery_time_s(log, t_from_s: float, radius_m: float = RECOVERY_RADIUS_M, hold_s: float = RECOVERY_HOLD_S) -> float:
    """Time from ``t_from_s`` until the TCP is within ``radius_m`` of the target and stays there ``hold_s``
    (NaN if never within the log, or when ``t_from_s`` is not finite)."""
    if not math.isfinite(t_from_s) or len(log.t_s) < 2:
        return float("nan")
    dt = float(log.t_s[1] - log.t_s[0])
    i0 = int(np.searchsorted(log.t_s, t_from_s - 1e-9))
    inside = np.linalg.norm(log.ee_pos_m[i0:] - log.target_pos_m[i0:], axis=1) < radius_m
    n = max(1, int(round(hold_s / dt)))
    if len(inside) < n:
        return float("nan")
    c = np.concatenate([[0], np.cumsum(inside)])
    full = np.flatnonzero(c[n:] - c[:-n] == n)
    return float(full[0] * dt) if full.size else float("nan")


def _empty_metrics() -> dict:
    nan = float("nan")
    return {**{k: 0 for k in SAFETY_COLUMNS}, "success": False, "final_error_m": nan, "torque_rate_max_nm_s": nan,
            "rejected_chunks": 0, "rejections": "", "watchdog_stops": 0, "gated_measurements": 0, "gated": "",
            "missed_ticks": 0, "aborts": 0, "abort_reason": "", "abort_t_s": nan, "qp_failures": 0,
            "qp_rescues": 0, "mpc_failures": 0, "perception_errors": 0, "recovery_s": nan}


def _compact(counts: dict) -> str:
    return ";".join(f"{k}:{v}" for k, v in counts.items() if v)


def run_cell(cell: dict, keep_log: bool = False):
    """One episode of one cell ``{fault, mode, source, seed, target, speed, duration_s, onset_s}``: the CSV row
    (and the log when ``keep_log``). Anything raised is caught and reported in ``raised``/``traceback``."""
    from mmact_ctrl.config import StackConfig
    from mmact_ctrl.controller import HybridController
    from mmact_ctrl.metrics import episode_metrics
    from scenarios.faults.injectors import run_fault_episode

    spec = FaultSpec(cell["fault"], t_fault_s=cell["onset_s"])
    row = {k: cell[k] for k in ("fault", "mode", "source", "seed")}
    row.update(_empty_metrics())
    row.update(applicable=True, raised="", traceback="", wall_s=float("nan"))
    log = None
    t0 = time.perf_counter()
    try:
        task = cell.get("task", "reach")
        world = _world(cell["source"], cell["target"], cell["speed"], cell.get("source_args"), task)
        source = _source(cell["source"], cell.get("source_args"), world)
        controller = HybridController(StackConfig(mode=cell["mode"], duration_s=cell["duration_s"],
                                                  **task_stack_settings(task)), model=_model())
        start, end = spec.window_s(controller.config.dt_s)
        row.update(fault_start_s=start, fault_end_s=end)
        log, inj = run_fault_episode(spec, world, source, controller, seed=int(cell["seed"]))
        m = episode_metrics(log)
        row.update({k: m.get(k, 0) for k in (*SAFETY_COLUMNS, "success", "final_error_m", "torque_rate_max_nm_s",
                                      "rejected_chunks", "watchdog_stops", "gated_measurements", "missed_ticks",
                                      "aborts", "qp_failures", "mpc_failures", "perception_errors")})
        row["qp_rescues"] = int(m.get("qp_rescues", 0))  # OSQP failed, DAQP solved
        row["rejections"] = _compact(m["rejections"])
        row["gated"] = _compact(m["gated"])
        if log.abort is not None:
            row["abort_reason"] = str(log.abort.get("reason", ""))
            row["abort_t_s"] = float(log.abort.get("t_s", float("nan")))
        row["applicable"] = bool(inj.applicable)
        row["recovery_s"] = recovery_time_s(log, end if math.isfinite(end) else start)
    except Exception as exc:  # noqa: BLE001 - the suite survives and reports whatever escaped
        row["raised"] = f"{type(exc).__name__}: {exc}"[:300]
        row["traceback"] = traceback.format_exc()
    row["wall_s"] = time.perf_counter() - t0
    return (row, log) if keep_log else row


# ---- the suite ------------------------------------------------------------------------------------


def make_cells(args) -> list[dict]:
    """Every fault x mode x source x seed, but the modes a source cannot serve (``args.unservable``: source ->
    modes, e.g. inpaint for a source without ``plan_inpaint``)."""
    extra = {"source_args": args.source_args} if getattr(args, "source_args", None) else {}
    skip = getattr(args, "unservable", {}) or {}
    task = getattr(args, "task", "reach")
    return [dict(fault=f, mode=m, source=s, seed=args.seed + i, target=args.target, speed=args.speed,
                 duration_s=args.duration_s, onset_s=args.onset_s, **(extra if s not in SOURCES else {}),
                 **({"task": task} if task != "reach" else {}))
            for s in args.sources for f in args.faults for m in args.modes if m not in skip.get(s, ())
            for i in range(args.seeds)]


def run_suite(cells: list[dict], workers: int = 1, quiet: bool = False) -> list[dict]:
    """Every cell once; rows in the order of ``cells``."""
    from tqdm import tqdm

    bar = tqdm(total=len(cells), desc="episodes", unit="ep", disable=quiet, file=sys.stderr)
    rows: list[dict | None] = [None] * len(cells)
    try:
        if workers <= 1:
            for i, cell in enumerate(cells):
                rows[i] = run_cell(cell)
                bar.set_postfix(fault=cell["fault"][:18], mode=cell["mode"], src=cell["source"])
                bar.update(1)
        else:
            import multiprocessing as mp

            with mp.get_context("spawn").Pool(workers) as pool:
                for i, row in pool.imap_unordered(_indexed_cell, list(enumerate(cells))):
                    rows[i] = row
                    bar.update(1)
    finally:
        bar.close()
    return rows  # type: ignore[return-value]


def _indexed_cell(item: tuple[int, dict]) -> tuple[int, dict]:
    i, cell = item
    return i, run_cell(cell)


def _violations(row: dict) -> int:
    return int(row["limit_violations"])


def cell_table(rows: list[dict]) -> list[dict]:
    """Per (source, fault, mode): episodes, success rate, violations, raised, aborts, median recovery."""
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault((r["source"], r["fault"], r["mode"]), []).append(r)
    out = []
    for (src, fault, mode), rs in groups.items():
        rec = [r["recovery_s"] for r in rs if math.isfinite(r["recovery_s"])]
        out.append({
            "source": src, "fault": fault, "mode": mode, "episodes": len(rs),
            "applicable": all(r["applicable"] for r in rs),
            "success_rate": float(np.mean([bool(r["success"]) for r in rs])),
            "violations": int(sum(_violations(r) for r in rs)),
            **{k: int(sum(int(r[k]) for r in rs)) for k in VIOLATION_KINDS},
            "raised": int(sum(bool(r["raised"]) for r in rs)),
            "aborts": int(sum(int(r["aborts"]) for r in rs)),
            "rejected_chunks": int(sum(int(r["rejected_chunks"]) for r in rs)),
            "watchdog_stops": int(sum(int(r["watchdog_stops"]) for r in rs)),
            "gated_measurements": int(sum(int(r["gated_measurements"]) for r in rs)),
            "qp_failures": int(sum(int(r["qp_failures"]) for r in rs)),
            "mpc_failures": int(sum(int(r["mpc_failures"]) for r in rs)),
            "recovery_s_median": float(np.median(rec)) if rec else float("nan"),
            "recovered": len(rec),
            "recovered_rate": len(rec) / len(rs),
        })
    return out


def totals(rows: list[dict]) -> dict:
    """Violations of every kind over all episodes, exceptions, aborts and which faults they came from."""
    by_kind = {k: int(sum(int(r[k]) for r in rows)) for k in SAFETY_COLUMNS}
    viol_cells = sorted({(r["fault"], r["mode"], r["source"]) for r in rows if _violations(r)})
    raised = [{"fault": r["fault"], "mode": r["mode"], "source": r["source"], "seed": r["seed"], "raised": r["raised"],
               "traceback": r.get("traceback", "")} for r in rows if r["raised"]]
    aborts = [{"fault": r["fault"], "mode": r["mode"], "source": r["source"], "seed": r["seed"],
               "reason": r["abort_reason"], "t_s": r["abort_t_s"], "expected": r["fault"] in EXPECTED_ABORTS}
              for r in rows if int(r["aborts"])]
    missing_aborts = [{"fault": r["fault"], "mode": r["mode"], "source": r["source"], "seed": r["seed"]}
                      for r in rows if r["fault"] in EXPECTED_ABORTS and not int(r["aborts"]) and not r["raised"]]
    return {
        "episodes": len(rows),
        "violations": by_kind,
        "violation_cells": [{"fault": f, "mode": m, "source": s} for f, m, s in viol_cells],
        "exceptions": len(raised),
        "exception_list": raised,
        "aborts": len(aborts),
        "unexpected_aborts": sum(not a["expected"] for a in aborts),
        "abort_list": aborts,
        "missing_expected_aborts": missing_aborts,
        **{k: int(sum(int(r[k]) for r in rows)) for k in ("rejected_chunks", "watchdog_stops", "gated_measurements",
                                                           "missed_ticks", "qp_failures", "mpc_failures",
                                                           "perception_errors")},
    }


def _cell_text(c: dict) -> str:
    if not c["applicable"]:
        return "n/a"
    text = f"{c['success_rate']:.0%}"
    if c["violations"]:
        text += f" V{c['violations']}"
    if c["raised"]:
        text += f" R{c['raised']}"
    if c["aborts"]:
        text += f" A{c['aborts']}"
    return text


def _tables(cells: list[dict], faults: list[str], modes: list[str], sources: list[str], cell_text) -> dict[str, str]:
    """A markdown fault x mode table per source; ``cell_text(cell)`` formats one cell ("-" where none ran)."""
    index = {(c["source"], c["fault"], c["mode"]): c for c in cells}
    tables = {}
    for src in sources:
        lines = ["| fault | " + " | ".join(modes) + " |", "|---|" + "---|" * len(modes)]
        for f in faults:
            lines.append(f"| {f} | " + " | ".join(cell_text(index[(src, f, m)]) if (src, f, m) in index else "-"
                                                   for m in modes) + " |")
        tables[src] = "\n".join(lines)
    return tables


def _recovery_text(c: dict) -> str:
    if not c["applicable"]:
        return "n/a"
    if c["recovered"]:
        return f"{c['recovery_s_median']:.2f} ({c['recovered']}/{c['episodes']})"
    return f"never (0/{c['episodes']})"


def fault_tables(cells: list[dict], faults: list[str], modes: list[str], sources: list[str]) -> dict[str, str]:
    """Success (and violations, exceptions, aborts) per fault x mode, one table per source."""
    return _tables(cells, faults, modes, sources, _cell_text)


def recovery_tables(cells: list[dict], faults: list[str], modes: list[str], sources: list[str]) -> dict[str, str]:
    """Median recovery time (episodes recovered / episodes) per fault x mode, one table per source."""
    return _tables(cells, faults, modes, sources, _recovery_text)


def success_costs(cells: list[dict], faults: list[str], modes: list[str], sources: list[str],
                  key: str = "success_rate") -> dict:
    """Per source and fault: ``key`` (``success_rate`` or ``recovered_rate``) versus the ``none`` row in the same
    modes (applicable cells only)."""
    index = {(c["source"], c["fault"], c["mode"]): c for c in cells}
    out: dict[str, dict] = {}
    for src in sources:
        base = {m: index[(src, "none", m)][key] for m in modes if (src, "none", m) in index}
        per_fault = {}
        for f in faults:
            if f == "none":
                continue
            deltas = {m: index[(src, f, m)][key] - base[m] for m in modes
                      if m in base and (src, f, m) in index and index[(src, f, m)]["applicable"]}
            if not deltas:
                continue
            worst = min(deltas, key=deltas.get)
            rate = float(np.mean([index[(src, f, m)][key] for m in deltas]))
            ref = float(np.mean([base[m] for m in deltas]))
            per_fault[f] = {"rate": rate, "baseline": ref, "n_modes": len(deltas), "delta": rate - ref, "worst_mode": worst,
                            "worst_delta": deltas[worst], "worst_rate": index[(src, f, worst)][key],
                            "worst_baseline": base[worst]}
        out[src] = {"baseline": base, "faults": per_fault}
    return out


def costs_paragraph(costs: dict, recovery: dict | None = None) -> str:
    """Plain language, computed: which faults cost success (and recovery after the fault window) and how much
    versus the ``none`` row."""
    paras = []
    for src, c in costs.items():
        if not c["baseline"]:
            paras.append(f"**{src}**: no `none` baseline in this run, so no fault's cost can be computed.")
            continue
        text = _cost_sentences(c, "succeeds (within 3 cm for 0.3 s at any time of the episode)", "success")
        if recovery is not None and src in recovery and recovery[src]["baseline"]:
            text += " " + _cost_sentences(recovery[src], "is back on the target after the fault window (within 3 cm "
                                                         "for 0.3 s; from the onset without a fault)", "recovery")
        paras.append(f"**{src}**: " + text)
    return "\n\n".join(paras)


def _cost_sentences(c: dict, what: str, noun: str) -> str:
    base = c["baseline"]
    parts = [f"Without a fault the TCP {what} in {np.mean(list(base.values())):.0%} of episodes ("
             + ", ".join(f"{m} {v:.0%}" for m, v in base.items()) + ")."]
    costly = sorted(((f, d) for f, d in c["faults"].items() if d["delta"] < -1e-9), key=lambda x: x[1]["delta"])
    better = [f for f, d in c["faults"].items() if d["delta"] > 1e-9]
    free = [f for f, d in c["faults"].items() if abs(d["delta"]) <= 1e-9]
    if costly:
        items = []
        for f, d in costly:
            note = " (expected: the target is out of reach)" if FAULTS[f].unreachable else ""
            items.append(f"`{f}` {100 * d['delta']:+.0f} points ({d['baseline']:.0%} -> {d['rate']:.0%} over "
                         f"{d['n_modes']} mode{'s' if d['n_modes'] > 1 else ''}; "
                         f"worst in {d['worst_mode']}: {d['worst_baseline']:.0%} -> {d['worst_rate']:.0%}){note}")
        parts.append(f"{len(costly)} fault(s) cost {noun}: " + "; ".join(items) + ".")
    else:
        parts.append(f"No fault cost {noun}.")
    if free:
        parts.append(f"No loss of {noun} with {len(free)} fault(s): " + ", ".join(f"`{f}`" for f in free) + ".")
    if better:
        parts.append(f"More {noun} than the baseline (seed noise, or a fault that happens to help): "
                     + ", ".join(f"`{f}`" for f in better) + ".")
    return " ".join(parts)


def totals_text(t: dict) -> str:
    lines = [f"- episodes: {t['episodes']}",
             "- violations: " + ", ".join(f"{k} {v}" for k, v in t["violations"].items())]
    if t["violation_cells"]:
        lines.append("- violations came from: " + ", ".join(f"{c['fault']}/{c['mode']}/{c['source']}"
                                                            for c in t["violation_cells"]))
    lines.append(f"- exceptions escaping run_episode: {t['exceptions']}")
    for e in t["exception_list"]:
        lines.append(f"  - {e['fault']}/{e['mode']}/{e['source']} seed {e['seed']}: {e['raised']}")
    by_fault: dict[str, int] = {}
    for a in t["abort_list"]:
        by_fault[a["fault"]] = by_fault.get(a["fault"], 0) + 1
    lines.append(f"- aborts: {t['aborts']} (" + (", ".join(f"{f} x{n}" for f, n in by_fault.items()) or "none")
                 + f"; unexpected: {t['unexpected_aborts']})")
    if t["missing_expected_aborts"]:
        lines.append("- expected aborts that did not happen: " + ", ".join(
            f"{a['fault']}/{a['mode']}/{a['source']} seed {a['seed']}" for a in t["missing_expected_aborts"]))
    lines.append("- faults survived: " + ", ".join(f"{k} {t[k]}" for k in (
        "rejected_chunks", "watchdog_stops", "gated_measurements", "missed_ticks", "qp_failures", "mpc_failures",
        "perception_errors")))
    return "\n".join(lines)


def plot_fault_torque(log, spec: FaultSpec, path: Path, title: str, window_s: float = 0.5) -> None:
    """Commanded torque of the 7 joints and |dtau/dt| with the 1000 N m/s line, +-``window_s`` around the onset."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from controllers.safety import CommandLimits

    t, tau = log.t_s, log.tau_cmd_nm
    dt = float(t[1] - t[0])
    rate = np.vstack([np.zeros((1, 7)), np.abs(np.diff(tau, axis=0)) / dt])
    t0 = spec.t_fault_s
    sel = (t >= t0 - window_s) & (t <= t0 + window_s)
    start, end = spec.window_s(dt)
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 6.5), sharex=True)
    for j in range(7):
        ax1.plot(t[sel], tau[sel, j], lw=1.0, label=f"joint {j + 1}")
        ax2.plot(t[sel], rate[sel, j], lw=1.0)
    for ax in (ax1, ax2):
        ax.axvspan(start, min(end, t0 + window_s), color="tab:red", alpha=0.12, label="fault window" if ax is ax1 else None)
    ax2.axhline(CommandLimits().dtau_max_nm_s, color="k", ls="--", lw=1.0, label="1000 N m/s")
    ax1.set_ylabel("commanded torque (N m)")
    ax2.set_ylabel("|dtau/dt| (N m/s)")
    ax2.set_xlabel("time (s)")
    ax1.legend(ncol=4, fontsize=7, loc="upper left")
    ax2.legend(fontsize=7, loc="upper left")
    ax1.set_title(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_csv(rows: list[dict], path: Path) -> None:
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(COLUMNS), extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)


def _json_safe(value):
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    if isinstance(value, np.generic):
        return _json_safe(value.item())
    return value


def _unservable(args) -> tuple[dict[str, tuple[str, ...]], list[str]]:
    """Per foreign source, the requested modes it cannot serve (checked on a probe built here, so a bad plugin is
    one line before any work), and a note for the report on each."""
    from mmact_ctrl.executors import make_executor
    from mmact_ctrl.sources.contract import SourceError, require_capabilities
    from scenarios.sources import SourceSettings, build_source, close_source

    skip, notes = {}, []
    for spec in args.sources:
        if spec in SOURCES:
            continue
        probe = build_source(SourceSettings(spec=spec, args=dict(args.source_args)))
        try:
            for mode in args.modes:
                try:
                    require_capabilities(probe, make_executor(mode).needs, mode)
                except SourceError as exc:
                    skip.setdefault(spec, ())
                    skip[spec] += (mode,)
                    notes.append(f"--mode {mode} left out for {spec}: {exc}")
        finally:
            close_source(probe)
    return skip, notes


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parser.parse_args(argv)
    args.faults = list(dict.fromkeys(args.faults or FAULTS))
    # a contact task's study is open_loop vs hybrid (the other modes are reach's field fixes; their chunk blending
    # was not built for a gripper channel: measured, temporal_ensemble and residual press a cube into the belt)
    args.modes = list(dict.fromkeys(args.modes or (MODES if args.task == "reach" else CONTACT_MODES)))
    if args.sources is None and not args.source:  # our policy knows reach only: a contact task runs the expert
        args.sources = list(QUICK_SOURCES if args.quick else SOURCES) if args.task == "reach" else ["expert"]
    args.sources = list(dict.fromkeys((args.sources or []) + (args.source or [])))
    try:
        from mmact_ctrl.sources.loader import parse_source_args

        args.source_args = parse_source_args(args.source_arg)
        args.unservable, notes = _unservable(args)
    except (ValueError, OSError, RuntimeError) as exc:  # a bad plugin, a server that is down: one line
        parser.error(str(exc).splitlines()[0])
    if args.seeds is None:
        args.seeds = QUICK_SEEDS if args.quick else 3
    if args.duration_s is None:  # a contact task needs 6 s (a grasp and lift, a seat take 3-5 s)
        args.duration_s = (QUICK_DURATION_S if args.quick else 5.0) if args.task == "reach" else 6.0
    if args.onset_s is None:
        args.onset_s = QUICK_ONSET_S if args.quick else 0.5
    if not args.onset_s < args.duration_s:
        parser.error(f"--onset-s ({args.onset_s:g}) must be earlier than the end of the episode (--duration-s "
                     f"{args.duration_s:g})")
    try:
        from mmact_ctrl.config import StackConfig

        for m in args.modes:  # a bad combination is one clear line before any work
            StackConfig(mode=m, duration_s=args.duration_s)
    except ValueError as exc:
        parser.error(str(exc))
    if "policy" in args.sources:
        from policy.inference import DEFAULT_CHECKPOINT

        if not Path(DEFAULT_CHECKPOINT).is_file():
            parser.error(f"policy checkpoint {str(DEFAULT_CHECKPOINT)!r} does not exist (use --sources expert)")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    t0 = time.perf_counter()
    started = datetime.now(timezone.utc)
    cells = make_cells(args)
    rows = run_suite(cells, workers=args.workers, quiet=args.quiet)

    # the torque figure: one episode re-run here (deterministic), whatever the selection
    plot_fault, plot_mode, plot_source = PLOT_CELL
    plot_cell = dict(fault=plot_fault, mode=plot_mode, source=plot_source, seed=args.seed, target=args.target,
                     speed=args.speed, duration_s=args.duration_s, onset_s=args.onset_s)
    plot_row, plot_log = run_cell(plot_cell, keep_log=True)
    plot_path = out / "fault_torque.png"
    plot_note = ""
    if plot_log is not None:
        plot_fault_torque(plot_log, FaultSpec(plot_fault, t_fault_s=args.onset_s), plot_path,
                          f"{plot_fault}, {plot_mode}, {plot_source} source, seed {args.seed}: commanded torque and "
                          f"torque rate around the onset ({args.onset_s:g} s)")
    else:
        plot_note = f"(the plot episode raised: {plot_row['raised']})"
    wall_s = time.perf_counter() - t0

    cells_tab = cell_table(rows)
    tot = totals(rows)
    costs = success_costs(cells_tab, args.faults, args.modes, args.sources)
    rec_costs = success_costs(cells_tab, args.faults, args.modes, args.sources, key="recovered_rate")
    paragraph = costs_paragraph(costs, rec_costs)
    tables = fault_tables(cells_tab, args.faults, args.modes, args.sources)
    rec_tables = recovery_tables(cells_tab, args.faults, args.modes, args.sources)
    command = " ".join([PROG, *map(shlex.quote, argv)])

    write_csv(rows, out / "faults.csv")
    settings = {k: getattr(args, k) for k in ("faults", "modes", "sources", "seeds", "seed", "target", "speed",
                                              "duration_s", "onset_s", "quick", "workers")}
    summary = {"command": command, "date": started.isoformat(timespec="seconds"), "wall_s": wall_s,
               "settings": settings, "totals": tot, "cells": cells_tab, "success_cost_vs_none": costs, "recovery_cost_vs_none": rec_costs,
               "paragraph": paragraph,
               "plot": {"fault": plot_fault, "mode": plot_mode, "source": plot_source, "seed": args.seed,
                        "path": plot_path.name if plot_log is not None else None}}
    (out / "summary.json").write_text(json.dumps(_json_safe(summary), indent=2))

    md = ["# Fault-injection suite", "",
          f"- command: `{command}`",
          f"- date: {started.strftime('%Y-%m-%d %H:%M:%S UTC')}; wall time {wall_s:.1f} s; {len(rows)} episodes",
          f"- {'static target' if args.target == 'static' else f'{args.target} target at {args.speed:g} m/s'}, {'two balls' if args.task == 'reach' else f'task {args.task}'}, {args.duration_s:g} s episodes, fault onset "
          f"{args.onset_s:g} s, seeds {args.seed}..{args.seed + args.seeds - 1}, workers {args.workers}",
          f"- sources: {', '.join(args.sources)}; modes: {', '.join(args.modes)}",
          *[f"- {n}" for n in notes],
          "",
          "Cell: success rate over the seeds; `V`n: safety violations (ticks flagged by the monitor, every kind); "
          "`R`n: exceptions that escaped `run_episode`; `A`n: aborted episodes (20 missed ticks in a row: expected for "
          "`missed_ticks_20`); n/a: the fault has nothing to act on in this mode (`mpc_late` without an MPC).", ""]
    for src in args.sources:
        md += [f"## {src} source", "", tables[src], "",
               f"Recovery: median time (s) from the end of the fault window (the onset for the moved targets) until "
               f"the TCP is within {RECOVERY_RADIUS_M * 100:g} cm of the target for {RECOVERY_HOLD_S:g} s "
               "(episodes recovered / episodes):", "", rec_tables[src], ""]
    md += ["## What the faults cost", "", paragraph, "", "## Totals", "", totals_text(tot), "",
           "## Torque around a fault", "",
           f"![torque]({plot_path.name}) {plot_note}".rstrip(), "",
           f"`{plot_fault}` in {plot_mode} with the {plot_source} source, seed {args.seed}: the commanded torque of the "
           "seven joints and its rate |dtau/dt| (the dashed line is the Panda's 1000 N m/s limit) within +-0.5 s of "
           "the onset; the shaded band is the fault window.", "",
           "## Faults", "", "| fault | what | window |", "|---|---|---|"]
    for f in args.faults:
        s, e = FaultSpec(f, t_fault_s=args.onset_s).window_s()
        window = "the start" if f == "start_with_velocity" else (
            "none" if f == "none" else f"{s:g} s -> " + ("end" if not math.isfinite(e) else f"{e:g} s"))
        md.append(f"| `{f}` | {FAULTS[f].description} | {window} |")
    (out / "report.md").write_text("\n".join(md) + "\n")

    for n in notes:
        print(n)
    for src in args.sources:
        print(f"\n{src} source (success rate; V violations, R raised, A aborts):\n")
        print(tables[src])
    print("\nTotals:\n" + totals_text(tot))
    print(f"\n{len(rows)} episodes in {wall_s:.1f} s -> {out / 'faults.csv'}, {out / 'report.md'}, "
          f"{out / 'summary.json'}, {plot_path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
