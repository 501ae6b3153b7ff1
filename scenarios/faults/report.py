"""The fault suite's outputs: ``faults.csv`` (one row per episode), ``summary.json`` (totals and per-cell
table), ``report.md`` (how it was run, a fault x mode table per source, what each fault cost, the totals) and the
lines printed at the end."""

from __future__ import annotations

import argparse
import csv
import json
import math
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

import numpy as np

from scenarios.faults.injectors import FAULTS, FaultSpec
from scenarios.faults.plot import PlotEpisode
from scenarios.faults.prose import costs_paragraph, totals_text
from scenarios.faults.settings import COLUMNS, RECOVERY_HOLD_S, RECOVERY_RADIUS_M
from scenarios.faults.tables import cell_table, fault_tables, recovery_tables, success_costs, totals


@dataclass(frozen=True)
class SuiteRun:
    """One run of the suite: its resolved arguments, the command as typed, the notes (modes left out), the rows
    in cell order, when it started, how long it took (the plot episode included) and its torque figure."""

    args: argparse.Namespace
    command: str
    notes: tuple[str, ...]
    rows: list[dict]
    started: datetime
    wall_s: float
    plot: PlotEpisode
    out: Path


@dataclass(frozen=True)
class Findings:
    """The rows summed up (``scenarios.faults.tables``) and put in words (``scenarios.faults.prose``)."""

    cells: list[dict]
    totals: dict
    success_costs: dict
    recovery_costs: dict
    paragraph: str
    tables: dict[str, str]
    recovery_tables: dict[str, str]


def analyse(run: SuiteRun) -> Findings:
    a = run.args
    cells = cell_table(run.rows)
    costs = success_costs(cells, a.faults, a.modes, a.sources)
    rec_costs = success_costs(cells, a.faults, a.modes, a.sources, key="recovered_rate")
    return Findings(cells=cells, totals=totals(run.rows), success_costs=costs, recovery_costs=rec_costs,
                    paragraph=costs_paragraph(costs, rec_costs),
                    tables=fault_tables(cells, a.faults, a.modes, a.sources),
                    recovery_tables=recovery_tables(cells, a.faults, a.modes, a.sources))


def write_outputs(run: SuiteRun) -> Findings:
    """Writes ``faults.csv``, ``summary.json`` and ``report.md`` into ``run.out`` and prints the tables and totals."""
    findings = analyse(run)
    write_csv(run.rows, run.out / "faults.csv")
    write_summary(run, findings, run.out / "summary.json")
    (run.out / "report.md").write_text("\n".join(report_lines(run, findings)) + "\n")
    print_findings(run, findings)
    return findings


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



def write_summary(run: SuiteRun, findings: Findings, path: Path) -> None:
    a, p = run.args, run.plot
    settings = {k: getattr(a, k) for k in ("faults", "modes", "sources", "seeds", "seed", "target", "speed",
                                           "duration_s", "onset_s", "quick", "workers")}
    summary = {"command": run.command, "date": run.started.isoformat(timespec="seconds"), "wall_s": run.wall_s,
               "settings": settings, "totals": findings.totals, "cells": findings.cells,
               "success_cost_vs_none": findings.success_costs, "recovery_cost_vs_none": findings.recovery_costs,
               "paragraph": findings.paragraph,
               "plot": {"fault": p.fault, "mode": p.mode, "source": p.source, "seed": p.seed,
                        "path": p.path.name if p.drawn else None}}
    path.write_text(json.dumps(_json_safe(summary), indent=2))


def report_lines(run: SuiteRun, findings: Findings) -> list[str]:
    """``report.md``, line by line: how it was run, per source its tables, the costs, the totals, the figure, the
    faults."""
    md = _header_lines(run)
    for src in run.args.sources:
        md += [f"## {src} source", "", findings.tables[src], "",
               f"Recovery: median time (s) from the end of the fault window (the onset for the moved targets) until "
               f"the TCP is within {RECOVERY_RADIUS_M * 100:g} cm of the target for {RECOVERY_HOLD_S:g} s "
               "(episodes recovered / episodes):", "", findings.recovery_tables[src], ""]
    md += ["## What the faults cost", "", findings.paragraph, "", "## Totals", "", totals_text(findings.totals), ""]
    return md + _plot_lines(run.plot) + _fault_lines(run.args)


def _header_lines(run: SuiteRun) -> list[str]:
    a = run.args
    target = 'static target' if a.target == 'static' else f'{a.target} target at {a.speed:g} m/s'
    scene = 'two balls' if a.task == 'reach' else f'task {a.task}'
    return ["# Fault-injection suite", "",
            f"- command: `{run.command}`",
            f"- date: {run.started.strftime('%Y-%m-%d %H:%M:%S UTC')}; wall time {run.wall_s:.1f} s; "
            f"{len(run.rows)} episodes",
            f"- {target}, {scene}, {a.duration_s:g} s episodes, fault onset "
            f"{a.onset_s:g} s, seeds {a.seed}..{a.seed + a.seeds - 1}, workers {a.workers}",
            f"- sources: {', '.join(a.sources)}; modes: {', '.join(a.modes)}",
            *[f"- {n}" for n in run.notes],
            "",
            "Cell: success rate over the seeds; `V`n: safety violations (ticks flagged by the monitor, every kind); "
            "`R`n: exceptions that escaped `run_episode`; `A`n: aborted episodes (20 missed ticks in a row: expected "
            "for `missed_ticks_20`); n/a: the fault has nothing to act on in this mode (`mpc_late` without an MPC).",
            ""]


def _plot_lines(p: PlotEpisode) -> list[str]:
    return ["## Torque around a fault", "",
            f"![torque]({p.path.name}) {p.note}".rstrip(), "",
            f"`{p.fault}` in {p.mode} with the {p.source} source, seed {p.seed}: the commanded torque of the "
            "seven joints and its rate |dtau/dt| (the dashed line is the Panda's 1000 N m/s limit) within +-0.5 s of "
            "the onset; the shaded band is the fault window.", ""]


def _fault_lines(args: argparse.Namespace) -> list[str]:
    lines = ["## Faults", "", "| fault | what | window |", "|---|---|---|"]
    for f in args.faults:
        s, e = FaultSpec(f, t_fault_s=args.onset_s).window_s()
        window = "the start" if f == "start_with_velocity" else (
            "none" if f == "none" else f"{s:g} s -> " + ("end" if not math.isfinite(e) else f"{e:g} s"))
        lines.append(f"| `{f}` | {FAULTS[f].description} | {window} |")
    return lines


def print_findings(run: SuiteRun, findings: Findings) -> None:
    out = run.out
    for n in run.notes:
        print(n)
    for src in run.args.sources:
        print(f"\n{src} source (success rate; V violations, R raised, A aborts):\n")
        print(findings.tables[src])
    print("\nTotals:\n" + totals_text(findings.totals))
    print(f"\n{len(run.rows)} episodes in {run.wall_s:.1f} s -> {out / 'faults.csv'}, {out / 'report.md'}, "
          f"{out / 'summary.json'}, {run.plot.path}")
