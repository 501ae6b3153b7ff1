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

The suite's parts: ``cli`` (the parser, the arguments resolved and checked), ``cells`` (one episode of one cell, the
suite), ``tables`` and ``prose`` (the rows summed up, in tables and in words), ``plot`` (the torque figure),
``report`` (the files written), ``settings`` (its constants). Every name is importable from here.
"""

from __future__ import annotations

import shlex
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

from scenarios.faults.cells import make_cells, recovery_time_s, run_cell, run_suite
from scenarios.faults.cli import build_parser, parse_args
from scenarios.faults.injectors import FAULTS, FaultSpec
from scenarios.faults.plot import PlotEpisode, plot_fault_torque, run_plot_episode
from scenarios.faults.prose import costs_paragraph, totals_text
from scenarios.faults.report import Findings, SuiteRun, write_csv, write_outputs
from scenarios.faults.settings import (
    COLUMNS,
    CONTACT_MODES,
    EXPECTED_ABORTS,
    PLOT_CELL,
    PROG,
    QUICK_DURATION_S,
    QUICK_ONSET_S,
    QUICK_SEEDS,
    QUICK_SOURCES,
    RECOVERY_HOLD_S,
    RECOVERY_RADIUS_M,
    SAFETY_COLUMNS,
    SOURCES,
    VIOLATION_KINDS,
)
from scenarios.faults.tables import cell_table, fault_tables, recovery_tables, success_costs, totals

__all__ = [
    "PROG", "SOURCES", "PLOT_CELL", "RECOVERY_RADIUS_M", "RECOVERY_HOLD_S", "QUICK_SEEDS", "CONTACT_MODES",
    "QUICK_DURATION_S", "QUICK_ONSET_S", "QUICK_SOURCES", "EXPECTED_ABORTS", "SAFETY_COLUMNS", "VIOLATION_KINDS",
    "COLUMNS", "FAULTS", "FaultSpec", "build_parser", "parse_args", "recovery_time_s", "run_cell", "make_cells",
    "run_suite", "cell_table", "totals", "fault_tables", "recovery_tables", "success_costs", "costs_paragraph",
    "totals_text", "plot_fault_torque", "run_plot_episode", "PlotEpisode", "write_csv", "write_outputs",
    "SuiteRun", "Findings", "main",
]


def main(argv: list[str] | None = None) -> int:
    """Runs the suite as ``argv`` (``sys.argv[1:]`` when None) asks; 0 when it ran, whatever it found."""
    args, argv, notes = parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    started = datetime.now(timezone.utc)
    rows = run_suite(make_cells(args), workers=args.workers, quiet=args.quiet)
    plot = run_plot_episode(args, out)
    wall_s = time.perf_counter() - t0
    write_outputs(SuiteRun(args=args, command=" ".join([PROG, *map(shlex.quote, argv)]), notes=tuple(notes),
                           rows=rows, started=started, wall_s=wall_s, plot=plot, out=out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
