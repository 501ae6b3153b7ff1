"""The sweep's command line (``python -m scenarios.sweep``, described in ``scenarios.sweep.study``): the arguments
and the grid checked before any work, the chunk source probed once, the cells still to run handed to a backend, then
``results.csv`` and the report written."""

from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

from mmact_ctrl.executors import make_executor
from mmact_ctrl.sources.contract import SourceError, require_capabilities
from scenarios.sources import build_source, close_source, settings_from_args, source_spec_arg
from scenarios.sweep import study as _study
from scenarios.sweep.backends import run_local, run_ray
from scenarios.sweep.study import STEP_S, Study, cell_key, task_grid


def write_csv(rows: list[dict], path: Path) -> None:
    keys: list[str] = []
    for r in rows:
        keys += [k for k in r if k not in keys]
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m scenarios.sweep", description=_study.__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True, help="output directory (cells/, results.csv, report.md, *.png)")
    p.add_argument("--quick", action="store_true", help="a small grid that finishes in under two minutes")
    p.add_argument("--seeds", type=int, default=10, help="seeds per cell of the default grid's lead and families studies "
                                                         "(the replan, rtc_grid, bins and perception studies use up to 3)")
    p.add_argument("--duration-s", type=float, default=None,
                   help="episode length (default 6 s; 4 s with --quick on reach)")
    p.add_argument("--backend", choices=("local", "ray"), default="local", help="process pool here, or a Ray cluster")
    p.add_argument("--workers", type=int, default=2, help="local backend: parallel processes")
    p.add_argument("--ray-address", default=None, help="ray backend: cluster address (default: auto)")
    p.add_argument("--grid", metavar="JSON", help="a JSON list of studies ({name, modes, replan_hz, latency_ms, target, "
                                                  "speed_m_s, bins, seeds[, perception, lead, d_steps, s_steps, task, "
                                                  "clearance_mm, noise_m, compliance, close_at_grasp]}) instead of the "
                                                  "default grid")
    p.add_argument("--source", type=source_spec_arg, default="expert", metavar="SOURCE",
                   help="chunk source of every cell: expert (the scripted expert, default), policy (the learned policy "
                        "in its training scenes; bins are then its own), module.path:factory or file.py:factory (your "
                        "own source, README 'Bring your own policy'), or ws://HOST:PORT (a policy server speaking "
                        "openpi's protocol). Every source but the expert has no lead axis and no bins study")
    p.add_argument("--source-arg", action="append", default=[], metavar="KEY=VALUE",
                   help="a keyword setting for a module:factory source (repeatable; VALUE read as JSON when it parses)")
    p.add_argument("--checkpoint", default=None, help="policy checkpoint (default: the shipped one)")
    p.add_argument("--preset", metavar="NAME|PATH", default=None,
                   help="ws:// source: the convention its policy was trained in (libero, droid, mmact, or a JSON preset "
                        "file: README 'Conventions'); default: what the server declares")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    from scenarios.world.tasks.registry import TASKS

    p.add_argument("--task", choices=TASKS, default="reach",
                   help="the task of the default grid: reach (the studies above), pick (open_loop vs hybrid on the "
                        "conveyor: static, linear 0.2 / 0.4 m/s, reversal, jump) or insert (bins x clearance x noise x "
                        "mode x compliance, static fixture). Default: reach")
    p.add_argument("--close-at-grasp", action="store_true",
                   help="pick: every cell with the closing from the grasp height and the descent stopped there (README, "
                        "Contact, point 14; in the modes that read the cube). For both, off and on, as an axis: "
                        "\"close_at_grasp\": [false, true] in a --grid study")
    return p


def _parse(p: argparse.ArgumentParser, argv: list[str] | None) -> tuple[argparse.Namespace, float]:
    """The arguments and the episode length, s (a bad value exits with status 2)."""
    args = p.parse_args(argv)
    if args.seeds < 1 or args.workers < 1:
        p.error(f"--seeds and --workers must be >= 1, got {args.seeds} and {args.workers}")
    # a contact task needs its 6 s even in a quick run (a peg seats at 3-5 s)
    duration_s = args.duration_s if args.duration_s is not None else (4.0 if args.quick and args.task == "reach" else 6.0)
    if not duration_s > 0:
        p.error(f"--duration-s must be > 0, got {duration_s}")
    return args, duration_s


def _read_grid(text: str):
    """``--grid``: a JSON list of studies, inline or in a file."""
    text = text.strip()
    return json.loads(text if text.startswith("[") or not Path(text).is_file() else Path(text).read_text())


def _check_studies(studies: list[Study], duration_s: float) -> None:
    """Every target a known kind, every latency shorter than the episode."""
    from scenarios.world.targets import KINDS

    for s in studies:
        bad = [t for t in s.target if t not in KINDS]
        if bad:
            raise ValueError(f"study {s.name!r}: unknown target(s) {bad}; expected some of {KINDS}")
        lats = [d * STEP_S * 1000.0 for d in s.d_steps] if s.d_steps else list(s.latency_ms)
        if any(lat / 1000.0 >= duration_s for lat in lats):
            raise ValueError(f"study {s.name!r}: a latency of {max(lats):g} ms is not shorter than the episode")


def _studies(p: argparse.ArgumentParser, args: argparse.Namespace, duration_s: float) -> list[Study]:
    """The grid: ``--grid``'s studies or the task's default grid, checked (a bad one exits with status 2)."""
    try:
        if args.grid:
            spec = _read_grid(args.grid)
            studies = [Study(**{k: tuple(v) if isinstance(v, list) else v for k, v in s.items()}) for s in spec]
        else:
            studies = task_grid(args.task, args.quick, args.seeds)
        if args.close_at_grasp:
            studies = [replace(s, close_at_grasp=(True,)) for s in studies]
        _check_studies(studies, duration_s)
        if not isinstance(spec if args.grid else [], list):
            raise ValueError("--grid must be a JSON list of studies")
    except (ValueError, TypeError, OSError) as exc:
        p.error(f"bad grid: {exc}")
    return studies


def _probe_source(p: argparse.ArgumentParser, args: argparse.Namespace, cells: list[dict]):
    """The source's settings, the cells whose modes it can serve, and a note per mode left out; a source that
    cannot be built fails here, in one line, not in every worker."""
    try:
        settings = settings_from_args(args)
        settings.check()
        notes: list[str] = []
        if settings.kind != "expert":  # fail here, in one line, not in every worker
            probe = build_source(settings)
            try:  # the modes this source cannot serve are left out, and the report says so
                for mode in sorted({c["mode"] for c in cells}):
                    try:
                        require_capabilities(probe, make_executor(mode).needs, mode)
                    except SourceError as exc:
                        notes.append(f"--mode {mode} left out: {exc}")
                        cells = [c for c in cells if c["mode"] != mode]
            finally:
                close_source(probe)
    except (ValueError, OSError, RuntimeError) as exc:
        p.error(str(exc).splitlines()[0])
    return settings, cells, notes


def _source_cells(args: argparse.Namespace, settings, cells: list[dict], duration_s: float) -> list[dict]:
    """The cells labelled with their source; a source's own chunks have no expert lead axis (one cell per lead-free
    condition) and no bins study."""
    if settings.kind == "expert":
        return [{**c, "source": "expert"} for c in cells]
    ckpt = None
    if settings.kind == "policy":
        from policy.inference import DEFAULT_CHECKPOINT

        ckpt = args.checkpoint or str(DEFAULT_CHECKPOINT)
    seen, own_cells = set(), []
    for c in cells:
        if c["study"] == "bins":
            continue
        c = {**c, "source": args.source, "checkpoint": ckpt, "lead": "-",
             **({"source_args": settings.args} if settings.args else {}),
             **({"preset": settings.preset} if settings.preset else {})}
        key = cell_key(c, duration_s) + c["study"]
        if key not in seen:
            seen.add(key)
            own_cells.append(c)
    return own_cells


def _cell_path(out: Path, cell: dict, duration_s: float) -> Path:
    return out / "cells" / f"{cell_key(cell, duration_s)}.json"


def _run(args: argparse.Namespace, cells: list[dict], todo: list[tuple[dict, float, str]]) -> None:
    """The cells not yet on disk, on the chosen backend, behind a progress bar."""
    from tqdm import tqdm

    bar = tqdm(total=len(cells), initial=len(cells) - len(todo), desc="cells", unit="ep", disable=args.quiet,
               file=sys.stderr)
    try:
        if args.backend == "ray":
            run_ray(todo, args.ray_address, lambda: bar.update(1))
        else:
            run_local(todo, args.workers, lambda: bar.update(1))
    finally:
        bar.close()


def _write(out: Path, cells: list[dict], duration_s: float, t0: float, resumed: int, notes: list[str]) -> list[dict]:
    """``results.csv`` (rows in grid order, each cell's study label from this grid) and the report."""
    rows = []
    for c in cells:
        row = json.loads(_cell_path(out, c, duration_s).read_text())
        rows.append({**row, "study": c["study"]})
    write_csv(rows, out / "results.csv")
    from scenarios.sweep.report import write_report

    write_report(rows, out, wall_s=time.perf_counter() - t0, resumed=resumed, notes=notes)
    return rows


def main(argv: list[str] | None = None) -> int:
    p = _parser()
    args, duration_s = _parse(p, argv)
    studies = _studies(p, args, duration_s)
    out = Path(args.out)
    (out / "cells").mkdir(parents=True, exist_ok=True)
    settings, cells, notes = _probe_source(p, args, [c for s in studies for c in s.cells()])
    cells = _source_cells(args, settings, cells, duration_s)
    todo = [(c, duration_s, str(_cell_path(out, c, duration_s))) for c in cells
            if not _cell_path(out, c, duration_s).is_file()]
    t0 = time.perf_counter()
    _run(args, cells, todo)
    rows = _write(out, cells, duration_s, t0, len(cells) - len(todo), notes)
    for n in notes:
        print(n)
    print(f"{len(rows)} episodes ({len(cells) - len(todo)} resumed) -> {out / 'results.csv'}, {out / 'report.md'}")
    return 0
