"""The sweep's speed and scaling, measured (issue 33, point 3): ``python -m scenarios.sweep_scaling``.

Runs the same grid of ``python -m scenarios.sweep`` once per worker count (and, with ``--ray-address``, once on a
Ray cluster), each in a fresh process, and prints per run: the wall time, the CPU time of the whole process tree, the
episodes per CPU-second and per wall-second, and the speed-up over the first run; then whether every run gave the
same results, row for row, on every column but the timings.

    python -m scenarios.sweep_scaling                          # the --quick grid, 1 and 2 workers
    python -m scenarios.sweep_scaling --grid docs/speed/scale_grid.json --workers 1 2 --json out/scaling.json
    python -m scenarios.sweep_scaling --ray-address auto      # and on a running Ray cluster (wall time only)

Why not ``/usr/bin/time``: the local backend's workers are forked by multiprocessing's fork server, a child of the
sweep that nobody waits for, so the rusage of the sweep counts neither it nor them (measured: a 2-worker run showed
2.5 CPU-seconds for 16 s of two busy workers). Here every process of the tree is sampled (``psutil``) every
``--poll-s``; a process's last interval before it exits may be missed (under 0.1 s a process at the default).
A Ray run's workers belong to the cluster, not to this tree: its CPU time is not reported.

Exit status 1 when the runs' results differ (a sweep whose results depend on its workers is a bug), 2 on bad input.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path

#: the columns that name a cell besides the sweep's axes (``scenarios.sweep.study.AXES``, ``TASK_AXES``): rows are
#: matched on them all
MORE_KEY_COLUMNS: tuple[str, ...] = ("duration_s", "source", "checkpoint", "preset")


@dataclass(frozen=True)
class ScalingRun:
    """One sweep run's figures."""

    backend: str
    workers: int
    episodes: int
    wall_s: float
    cpu_s: float | None  # the process tree's user + system time, s (None: not measurable, Ray)
    speedup: float  # the first run's wall time over this run's

    @property
    def episodes_per_cpu_s(self) -> float | None:
        return None if not self.cpu_s else self.episodes / self.cpu_s

    @property
    def episodes_per_wall_s(self) -> float:
        return self.episodes / self.wall_s


def is_timing(column: str) -> bool:
    """Whether a results.csv column is a timing of the host (excluded from the comparison): the golden record's
    wall-clock figures (``scenarios.golden_record.WALL_CLOCK_KEYS``)."""
    from scenarios.golden_record import WALL_CLOCK_KEYS

    return column in WALL_CLOCK_KEYS


def key_columns() -> tuple[str, ...]:
    """The columns that name a cell: the sweep's axes, a contact task's axes, and ``MORE_KEY_COLUMNS``."""
    from scenarios.sweep.study import AXES, TASK_AXES

    return tuple(dict.fromkeys((*AXES, *TASK_AXES, *MORE_KEY_COLUMNS)))


def read_rows(path: Path) -> dict[tuple, dict[str, str]]:
    """results.csv as {the cell's key columns: its row}."""
    with path.open(newline="") as f:
        rows = list(csv.DictReader(f))
    keys = key_columns()
    return {tuple(r.get(c, "") for c in keys): r for r in rows}


def differences(a: dict[tuple, dict[str, str]], b: dict[tuple, dict[str, str]], limit: int = 10) -> list[str]:
    """How two runs' results differ (cells present in one only, then result columns that differ), at most ``limit``."""
    out = [f"cell {k} only in the first run" for k in a.keys() - b.keys()]
    out += [f"cell {k} only in the second run" for k in b.keys() - a.keys()]
    for key in sorted(a.keys() & b.keys()):
        ra, rb = a[key], b[key]
        for col in sorted((ra.keys() | rb.keys())):
            if not is_timing(col) and ra.get(col) != rb.get(col):
                out.append(f"cell {key}: {col} {ra.get(col)!r} != {rb.get(col)!r}")
    return out[:limit]


def run_tree_measured(cmd: list[str], poll_s: float) -> tuple[int, float, float]:
    """Run ``cmd``; returns (exit status, wall s, CPU s of the process and all its descendants, sampled)."""
    import psutil

    seen: dict[tuple[int, float], float] = {}
    err = tempfile.TemporaryFile()  # a file, not a pipe: a pipe read only at the end fills and stalls the child
    t0 = time.perf_counter()
    proc = psutil.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err)
    while True:
        try:
            tree = [proc, *proc.children(recursive=True)]
        except psutil.NoSuchProcess:
            tree = []
        for p in tree:
            try:
                with p.oneshot():
                    t = p.cpu_times()
                    seen[(p.pid, p.create_time())] = t.user + t.system
            except (psutil.NoSuchProcess, psutil.ZombieProcess, psutil.AccessDenied):
                pass
        if proc.poll() is not None:
            break
        time.sleep(poll_s)
    wall_s = time.perf_counter() - t0
    err.seek(0)
    stderr = err.read().decode(errors="replace")
    err.close()
    if proc.returncode != 0:
        tail = stderr.strip().splitlines()[-1:] or ["(no output)"]
        raise SystemExit(f"sweep_scaling: {' '.join(cmd[2:])} failed (exit {proc.returncode}): {tail[0]}")
    return proc.returncode, wall_s, sum(seen.values())


def _grid_switches(grid: str) -> list[str]:
    return ["--quick"] if grid == "quick" else ["--grid", grid]


def measure(grid: str, workers: list[int], ray_address: str | None, out_dir: Path, poll_s: float,
            extra: list[str], progress=print) -> dict:
    """Every run's figures and the comparison of their results (see the module)."""
    plans = [("local", w, ["--workers", str(w)]) for w in workers]
    if ray_address:
        plans.append(("ray", 0, ["--backend", "ray", "--ray-address", ray_address]))
    runs: list[ScalingRun] = []
    results: list[dict] = []
    for backend, w, switches in plans:
        out = out_dir / (f"{backend}{w}" if w else backend)
        cmd = [sys.executable, "-m", "scenarios.sweep", *_grid_switches(grid), "--out", str(out), "--quiet", *switches,
               *extra]
        progress(f"running {backend} {'' if not w else f'{w} worker(s)'}: {' '.join(cmd[2:])}")
        _, wall_s, cpu_s = run_tree_measured(cmd, poll_s)
        rows = read_rows(out / "results.csv")
        results.append(rows)
        first_wall = runs[0].wall_s if runs else wall_s
        runs.append(ScalingRun(backend, w, len(rows), wall_s, None if backend == "ray" else cpu_s,
                               first_wall / wall_s))
    diffs = [d for r in results[1:] for d in differences(results[0], r)]
    return {"grid": grid, "runs": [{**asdict(r), "episodes_per_cpu_s": r.episodes_per_cpu_s,
                                    "episodes_per_wall_s": r.episodes_per_wall_s} for r in runs],
            "identical": not diffs, "differences": diffs}


def format_report(report: dict) -> str:
    lines = [f"sweep scaling, grid {report['grid']}",
             f"{'run':<14}{'episodes':>9}{'wall [s]':>10}{'CPU [s]':>10}{'ep / CPU-s':>12}{'ep / wall-s':>13}"
             f"{'speed-up':>10}"]
    for r in report["runs"]:
        name = f"{r['backend']} {r['workers']}w" if r["backend"] == "local" else r["backend"]
        cpu = "-" if r["cpu_s"] is None else f"{r['cpu_s']:.1f}"
        per_cpu = "-" if r["episodes_per_cpu_s"] is None else f"{r['episodes_per_cpu_s']:.2f}"
        lines.append(f"{name:<14}{r['episodes']:>9}{r['wall_s']:>10.1f}{cpu:>10}{per_cpu:>12}"
                     f"{r['episodes_per_wall_s']:>13.2f}{r['speedup']:>9.2f}x")
    lines.append("results identical in every run (all columns but timings)" if report["identical"] else
                 "RESULTS DIFFER between runs:\n  " + "\n  ".join(report["differences"]))
    return "\n".join(lines)


def _workers(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f"--workers takes counts >= 1, got {text!r}")
    return n


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m scenarios.sweep_scaling", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--grid", default="quick", help="'quick' (the sweep's --quick grid, default) or a grid JSON file")
    p.add_argument("--workers", type=_workers, nargs="+", default=[1, 2], help="local worker counts, in order")
    p.add_argument("--ray-address", default=None, help="also run on this Ray cluster ('auto': the running one)")
    p.add_argument("--out", default=None, help="where the runs' outputs go (default: a temporary directory)")
    p.add_argument("--json", metavar="PATH", default=None, help="write the figures as JSON")
    p.add_argument("--poll-s", type=float, default=0.05, help="how often the process tree's CPU time is sampled, s")
    p.add_argument("--sweep-arg", action="append", default=[], metavar="SWITCH",
                   help="one more switch for every sweep run (repeatable), e.g. --sweep-arg=--duration-s=3")
    return p


def main(argv: list[str] | None = None) -> int:
    p = build_parser()
    args = p.parse_args(argv)
    if args.grid != "quick" and not Path(args.grid).is_file():
        p.error(f"--grid: no such grid file {args.grid!r} (or 'quick')")
    if not (math.isfinite(args.poll_s) and 0 < args.poll_s <= 1.0):
        p.error(f"--poll-s must be in (0, 1] s, got {args.poll_s}")
    try:
        import psutil  # noqa: F401
    except ImportError:
        p.error("measuring the process tree's CPU time needs psutil: pip install -e '.[bench]'")
    with tempfile.TemporaryDirectory(prefix="sweep_scaling_") as tmp:
        out_dir = Path(args.out) if args.out else Path(tmp)
        report = measure(args.grid, args.workers, args.ray_address, out_dir, args.poll_s, args.sweep_arg,
                         progress=lambda m: print(m, file=sys.stderr, flush=True))
    print(format_report(report))
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(report, indent=2))
    return 0 if report["identical"] else 1


if __name__ == "__main__":
    sys.exit(main())
