"""A golden record of episodes: a change that is not meant to move a result moves none.

    python -m scenarios.golden --write                   # the full set -> tests/golden/record.json
    python -m scenarios.golden --check                   # rerun it; exit 1 on any difference
    python -m scenarios.golden --subset ci --check       # the small CI subset (tests/golden/record_ci.json)

The record holds, for a fixed set of episodes, each episode's summary figures (``mmact_ctrl.metrics.episode_metrics``
less the wall-clock ones, :data:`WALL_CLOCK_KEYS`) and the SHA-256 of its torque commands (``log.tau_cmd_nm``) and of
its TCP path (``log.ee_pos_m``). ``--check`` reruns the episodes the record names and compares bit for bit.

The full set (issue 31): every execution mode x targets static, linear, reversal, jump x seeds 0, 1, 2, for the
scripted expert and the shipped policy, each cell run as ``python -m scenarios.moving_target --source S --target T
--mode M --episodes 3`` runs it (one controller per cell, the seeds in order, the main job's defaults otherwise);
plus one episode in the real-time ("deadline") tick order in simulated time (:data:`DEADLINE_ORDER`). A mode the
source cannot run (``ChunkExecutor.needs``: inpaint with a source without ``plan_inpaint``) is recorded as skipped,
with the reason (none is at the time of writing: the shipped policy and the expert both inpaint).

The hashes are those of one machine and one set of library versions (the record says which: ``made_with``); a
different CPU or a different numpy / MuJoCo / OSQP / torch may legitimately move the last bits.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import importlib.metadata
import json
import platform
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from scenarios.cli import HelpFormatter, OneLineErrorParser

PROG = "python -m scenarios.golden"
FORMAT = 1
#: the record files of the two subsets (relative to the repository root)
DEFAULT_PATHS: dict[str, Path] = {"full": Path("tests/golden/record.json"), "ci": Path("tests/golden/record_ci.json")}
SOURCES: tuple[str, ...] = ("expert", "policy")
TARGETS: tuple[str, ...] = ("static", "linear", "reversal", "jump")
SEEDS: tuple[int, ...] = (0, 1, 2)
#: the tick orders: simulated (``EpisodeRunner`` without a deadline) and deadline (real time's order, simulated time)
SIMULATED_ORDER, DEADLINE_ORDER = "simulated", "deadline"
#: figures of ``episode_metrics`` that are wall-clock timings (or per-tick lists of them): they change from run to
#: run and are not recorded
WALL_CLOCK_KEYS: frozenset[str] = frozenset({
    "tick_us_median", "tick_us_p99", "mpc_solve_us_median", "mpc_solve_us_p99", "mpc_solve_us",
    "plan_ms_median", "plan_ms", "source_timing_ms", "sensor_ms_per_sim_s", "realtime_factor",
    # real time's deadline statistics (absent in simulated time; listed so a record never holds them)
    "realtime", "overruns", "overrun_rate", "cycles_missed", "late_commands", "exec_us_median", "exec_us_p99",
    "exec_us_max", "jitter_us_std", "jitter_us_p99", "control_command_success_rate", "realtime_rate", "exec_us",
    "late_ticks",
})
#: the libraries whose versions can move the last bits of a result (distribution names)
LIBRARIES: tuple[str, ...] = ("numpy", "mujoco", "pin", "osqp", "torch", "numba")


@dataclass(frozen=True)
class Cell:
    """One run of the main job: one source, mode and target, its seeds in order on one controller.

    Attributes:
        source: ``expert`` or ``policy`` (``--source``).
        mode: the execution mode (``mmact_ctrl.config.MODES``).
        target: the target motion (``--target``).
        seeds: the episodes' seeds, run in this order.
        duration_s: each episode's simulated length, s.
        order: :data:`SIMULATED_ORDER` or :data:`DEADLINE_ORDER`.
    """

    source: str
    mode: str
    target: str
    seeds: tuple[int, ...]
    duration_s: float = 6.0
    order: str = SIMULATED_ORDER

    def key(self, seed: int) -> str:
        """The record's name of this cell's episode of ``seed``."""
        return f"{self.source}/{self.mode}/{self.target}/{self.order}/{self.duration_s:g}s/seed={seed}"

    def argv(self) -> list[str]:
        """The main job's command line for this cell (``scenarios.moving_target.build_parser``). The deadline order
        adds ``--realtime``, which only sets real time's defaults in ``stack_config`` (the MPC 5 ms off the 20 ms
        marks, OSQP's real-time iteration cap); the episode itself is run here, in simulated time."""
        argv = ["--source", self.source, "--target", self.target, "--mode", self.mode, "--quiet",
                "--duration-s", repr(float(self.duration_s)), "--episodes", str(len(self.seeds))]
        return argv + (["--realtime"] if self.order == DEADLINE_ORDER else [])

    @classmethod
    def from_json(cls, data: dict) -> "Cell":
        """The cell a record stores (``dataclasses.asdict``); ValueError when malformed."""
        try:
            cell = cls(source=str(data["source"]), mode=str(data["mode"]), target=str(data["target"]),
                       seeds=tuple(int(s) for s in data["seeds"]), duration_s=float(data["duration_s"]),
                       order=str(data["order"]))
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"a malformed cell in the record: {data!r} ({type(exc).__name__}: {exc})") from None
        if cell.order not in (SIMULATED_ORDER, DEADLINE_ORDER) or not cell.seeds:
            raise ValueError(f"a malformed cell in the record: {data!r}")
        return cell


def full_set() -> tuple[Cell, ...]:
    """Issue 31's set: every mode x static, linear, reversal, jump x seeds 0-2, expert and policy (6 s each), plus
    one episode in the deadline order (the expert, hybrid, linear target, seed 0)."""
    from mmact_ctrl.config import MODES

    cells = tuple(Cell(source, mode, target, SEEDS) for source in SOURCES for target in TARGETS for mode in MODES)
    return cells + (Cell("expert", "hybrid", "linear", (0,), order=DEADLINE_ORDER),)


def ci_set() -> tuple[Cell, ...]:
    """A small subset for the test suite (2 s episodes): expert and policy, open_loop and hybrid, linear and jump
    targets, and the deadline order."""
    return (
        Cell("expert", "open_loop", "linear", (0,), 2.0),
        Cell("expert", "hybrid", "jump", (0,), 2.0),
        Cell("expert", "hybrid", "linear", (0,), 2.0, DEADLINE_ORDER),
        Cell("policy", "open_loop", "jump", (0,), 2.0),
        Cell("policy", "hybrid", "jump", (1,), 2.0),
        Cell("policy", "hybrid", "linear", (0,), 2.0),
    )


SUBSETS = {"full": full_set, "ci": ci_set}


# ---- running ------------------------------------------------------------------------------------------------------
class OnTime:
    """A deadline that every command meets: the runner's real-time tick order without a wall clock."""

    def missed(self, k: int) -> bool:
        return False


def episode_entry(log) -> dict:
    """What the record keeps of one episode: its deterministic figures and the hashes of its commands and path."""
    import numpy as np

    from mmact_ctrl.metrics import episode_metrics

    figures = {k: v for k, v in episode_metrics(log).items() if k not in WALL_CLOCK_KEYS}
    return {
        "ticks": int(len(log.tau_cmd_nm)),
        "tau_cmd_sha256": hashlib.sha256(np.ascontiguousarray(log.tau_cmd_nm, dtype=np.float64).tobytes()).hexdigest(),
        "ee_pos_sha256": hashlib.sha256(np.ascontiguousarray(log.ee_pos_m, dtype=np.float64).tobytes()).hexdigest(),
        "figures": json.loads(json.dumps(figures)),  # as the JSON file holds them (tuples as lists)
    }


class Episodes:
    """Runs cells; keeps one source and world at a time (built as the main job builds them), reused by consecutive
    cells of the same source and target as the main job reuses them across modes. A context manager: closes them."""

    def __init__(self) -> None:
        self._key: tuple[str, str] | None = None
        self._built = None

    def _source_world(self, args):
        from scenarios.moving_target import make_source_and_world

        key = (args.source, args.target)
        if key != self._key:
            self.close()
            self._built, self._key = make_source_and_world(args), key
        return self._built

    def run(self, cell: Cell) -> dict[str, dict]:
        """The record's entries of ``cell``'s episodes, by key (a mode the source cannot run: skipped entries)."""
        from mmact_ctrl.controller import HybridController
        from mmact_ctrl.executors import make_executor
        from mmact_ctrl.runner import EpisodeRunner
        from mmact_ctrl.sources.contract import SourceError, require_capabilities
        from scenarios import moving_target

        args = moving_target.build_parser().parse_args(cell.argv())
        config = moving_target.stack_config(args, cell.mode)
        source, world = self._source_world(args)
        try:
            require_capabilities(source, make_executor(cell.mode).needs, cell.mode)
        except SourceError as exc:
            return {cell.key(seed): {"skipped": str(exc)} for seed in cell.seeds}
        sensor = moving_target.make_sensor(args, world, config.dt_s)
        controller = HybridController(config)
        # the deadline order hands the MPC its problems after each command (mmact_ctrl.tick_order.DeadlineOrder), as
        # real time's MPC process is; solved inline at once: deterministic
        deadline = OnTime() if cell.order == DEADLINE_ORDER else None
        entries = {}
        try:
            for seed in cell.seeds:
                try:
                    runner = EpisodeRunner(world, source, controller, seed, sensor=sensor, deadline=deadline)
                    runner.advance()
                    entries[cell.key(seed)] = episode_entry(runner.finish())
                except Exception as exc:  # noqa: BLE001 - an episode that raises is a difference, not a crash
                    entries[cell.key(seed)] = {"error": f"{type(exc).__name__}: {exc}"[:300]}
        finally:
            getattr(sensor, "close", lambda: None)()
        return entries

    def close(self) -> None:
        """Close the source and world held (if any)."""
        if self._built is not None:
            from scenarios.sources import close_source

            source, world = self._built
            self._built, self._key = None, None
            world.close()
            close_source(source)

    def __enter__(self) -> "Episodes":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


_WORKER_EPISODES: Episodes | None = None  # a pool worker's own (one per worker process)


def _worker_run(cell: Cell) -> dict[str, dict]:
    """A pool worker: ``cell``'s entries, with the worker's own :class:`Episodes` (its world kept for the next cell)."""
    global _WORKER_EPISODES
    if _WORKER_EPISODES is None:
        _WORKER_EPISODES = Episodes()
    return _WORKER_EPISODES.run(cell)


def run_cells(cells: tuple[Cell, ...], jobs: int = 2, progress: bool = True) -> dict[str, dict]:
    """Every cell's episode entries, by key (the cells grouped by source and target, so that consecutive cells
    share a world); ``jobs`` > 1: in a pool of that many processes (spawned: each builds its own worlds), else in this
    process. An episode that raises is an ``{"error": ...}`` entry."""
    from tqdm import tqdm

    cells = tuple(sorted(cells, key=lambda c: (c.source, c.target)))  # consecutive cells share a world
    results: dict[Cell, dict[str, dict]] = {}
    with tqdm(total=sum(len(c.seeds) for c in cells), desc="episodes", unit="ep", disable=not progress,
              file=sys.stderr) as bar:
        if jobs <= 1:
            with Episodes() as episodes:
                for cell in cells:
                    results[cell] = episodes.run(cell)
                    bar.update(len(cell.seeds))
        else:
            import multiprocessing as mp
            from concurrent.futures import ProcessPoolExecutor, as_completed

            with ProcessPoolExecutor(jobs, mp_context=mp.get_context("spawn")) as pool:
                futures = {pool.submit(_worker_run, cell): cell for cell in cells}
                for future in as_completed(futures):
                    results[futures[future]] = future.result()
                    bar.update(len(futures[future].seeds))
    return {key: entry for cell in cells for key, entry in results[cell].items()}


# ---- the record ---------------------------------------------------------------------------------------------------
def made_with() -> dict:
    """Where the hashes are made: library versions, CPU model, Python, the git commit (best effort)."""
    versions = {}
    for name in LIBRARIES:
        try:
            versions[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            versions[name] = None
    cpu = next((line.split(":", 1)[1].strip() for line in _read_lines("/proc/cpuinfo")
                if line.startswith("model name")), platform.processor() or None)
    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True, timeout=10,
                                cwd=Path(__file__).resolve().parent).stdout.strip() or None
    except (OSError, subprocess.SubprocessError):
        commit = None
    return {"versions": versions, "cpu_model": cpu, "python": platform.python_version(),
            "machine": platform.machine(), "git_commit": commit}


def _read_lines(path: str) -> list[str]:
    try:
        return Path(path).read_text().splitlines()
    except OSError:
        return []


def make_record(subset: str, cells: tuple[Cell, ...], episodes: dict[str, dict]) -> dict:
    """The record's JSON payload."""
    return {"format": FORMAT, "subset": subset, "made_with": made_with(),
            "dropped_figures": sorted(WALL_CLOCK_KEYS),
            "cells": [dataclasses.asdict(c) for c in cells], "episodes": episodes}


def load_record(path: Path) -> dict:
    """The record at ``path``; ValueError (one line) when it is missing or malformed."""
    try:
        record = json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise ValueError(f"no record at {str(path)!r} (make one with {PROG} --write)") from None
    except (OSError, json.JSONDecodeError) as exc:
        raise ValueError(f"cannot read the record {str(path)!r}: {exc}") from None
    if not isinstance(record, dict) or record.get("format") != FORMAT:
        raise ValueError(f"{str(path)!r} is not a golden record of format {FORMAT}")
    if not isinstance(record.get("cells"), list) or not isinstance(record.get("episodes"), dict):
        raise ValueError(f"{str(path)!r} is not a golden record: it needs 'cells' (a list) and 'episodes' (a dict)")
    return record


def record_cells(record: dict) -> tuple[Cell, ...]:
    """The cells a record names; ValueError when one is malformed."""
    return tuple(Cell.from_json(c) for c in record["cells"])


# ---- comparing ----------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Difference:
    """One episode that does not reproduce its record.

    Attributes:
        key: the episode (``Cell.key``).
        figures: (name, recorded, now) of each figure that changed, as JSON text (``absent`` where one is missing).
        tau_changed: the torque commands' hash changed.
        ee_changed: the TCP path's hash changed.
        note: what else differs (skipped before and run now, in the record and not run, ...).
    """

    key: str
    figures: tuple[tuple[str, str, str], ...] = ()
    tau_changed: bool = False
    ee_changed: bool = False
    note: str = ""


def _text(value) -> str:
    """A figure as JSON text: equal text is equal bits (floats print their shortest exact repr; NaN is NaN)."""
    return json.dumps(value, sort_keys=True)


def compare_episode(key: str, old: dict, new: dict) -> Difference | None:
    """The difference between one episode's recorded and fresh entries, None when identical. Figures only the fresh
    run has (a figure added since) are not compared: they moved nothing that was recorded."""
    if "error" in new:
        return Difference(key, note=f"raised {new['error']}")
    if "skipped" in old or "skipped" in new:
        if old.get("skipped") == new.get("skipped"):
            return None
        note = (f"skipped in the record ({old['skipped']}), runs now" if "skipped" in old else
                f"recorded, skipped now ({new['skipped']})" if "skipped" not in old and "skipped" in new else
                f"skipped for another reason now: {new['skipped']}")
        return Difference(key, note=note)
    old_figures, new_figures = {"ticks": old.get("ticks"), **old.get("figures", {})}, \
        {"ticks": new.get("ticks"), **new.get("figures", {})}
    changed = tuple((name, _text(value), _text(new_figures[name]) if name in new_figures else "absent")
                    for name, value in old_figures.items()
                    if name not in new_figures or _text(value) != _text(new_figures[name]))
    tau = old.get("tau_cmd_sha256") != new.get("tau_cmd_sha256")
    ee = old.get("ee_pos_sha256") != new.get("ee_pos_sha256")
    return Difference(key, changed, tau, ee) if changed or tau or ee else None


def compare(recorded: dict[str, dict], fresh: dict[str, dict]) -> list[Difference]:
    """Every episode whose fresh entry differs from its recorded one (and those only one side has)."""
    diffs = [Difference(key, note="in the record, not run now") for key in recorded if key not in fresh]
    diffs += [Difference(key, note="run now, not in the record") for key in fresh if key not in recorded]
    for key in recorded.keys() & fresh.keys():
        diff = compare_episode(key, recorded[key], fresh[key])
        if diff is not None:
            diffs.append(diff)
    order = {key: i for i, key in enumerate(list(recorded) + list(fresh))}
    return sorted(diffs, key=lambda d: order[d.key])


def check(record: dict, jobs: int = 2, progress: bool = True) -> list[Difference]:
    """Rerun the episodes ``record`` names and compare them with it: the differences (empty: bit for bit)."""
    return compare(record["episodes"], run_cells(record_cells(record), jobs, progress))


def format_report(diffs: list[Difference], record: dict, path: Path) -> str:
    """The check's report: each differing episode's changed figures (recorded -> now) and hashes, then a total."""
    episodes = record["episodes"]
    skipped = sum("skipped" in e for e in episodes.values() if isinstance(e, dict))
    lines = []
    for d in diffs:
        hits = (("torque", d.tau_changed), ("TCP path", d.ee_changed))
        hashes = [f"{what} hash changed" for what, hit in hits if hit]
        if not hashes and not d.note:
            hashes = ["hashes unchanged"]
        lines.append(f"DIFF {d.key}: " + ", ".join(([d.note] if d.note else []) + hashes))
        lines += [f"    {name}: {old} -> {new}" for name, old, new in d.figures]
    if diffs:
        lines.append(f"{len(diffs)} of {len(episodes)} episodes differ from {path}")
    else:
        lines.append(f"all {len(episodes)} episodes identical to {path} ({skipped} skipped, as recorded)")
    now = made_with()
    where = [f"{k}: {record.get('made_with', {}).get(k)!r} then, {now[k]!r} now" for k in ("versions", "cpu_model")
             if record.get("made_with", {}).get(k) != now[k]]
    if where:
        lines.append("note: the record was made elsewhere (" + "; ".join(where) + "); the last bits may differ")
    return "\n".join(lines)


# ---- the command line ---------------------------------------------------------------------------------------------
def build_parser() -> argparse.ArgumentParser:
    """The command line (one-line errors, exit 2)."""
    p = OneLineErrorParser(prog=PROG, description=__doc__.split("\n\n")[0], formatter_class=HelpFormatter,
                           epilog="examples:\n  python -m scenarios.golden --write\n"
                                  "  python -m scenarios.golden --subset ci --check\n")
    what = p.add_mutually_exclusive_group(required=True)
    what.add_argument("--write", nargs="?", const="", metavar="PATH",
                      help="run the subset's episodes and write the record (default PATH: tests/golden/record.json, "
                           "with --subset ci tests/golden/record_ci.json)")
    what.add_argument("--check", nargs="?", const="", metavar="PATH",
                      help="rerun the episodes the record names and compare bit for bit: exit 0 identical, 1 any "
                           "difference (default PATH as for --write)")
    p.add_argument("--subset", choices=tuple(SUBSETS), default="full",
                   help="full: issue 31's set (every mode x 4 targets x 3 seeds x expert and policy, 6 s, and one "
                        "deadline-order episode); ci: 6 episodes of 2 s. --check runs what the record names")
    p.add_argument("--jobs", type=_jobs, default=2, help="processes running episodes (1: in this process)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p


def _jobs(text: str) -> int:
    """``--jobs``: an integer in [1, 64]."""
    from scenarios.cli import number

    return number(int, "--jobs", 1, True, 64)(text)


def main(argv: list[str] | None = None) -> int:
    """``--write``: 0 written (1: an episode raised); ``--check``: 0 identical, 1 any difference; 2 bad input."""
    parser = build_parser()
    args = parser.parse_args(argv)
    text = args.write if args.write is not None else args.check
    path = Path(text) if text else DEFAULT_PATHS[args.subset]
    if args.write is not None:
        cells = SUBSETS[args.subset]()
        record = make_record(args.subset, cells, run_cells(cells, args.jobs, not args.quiet))
        errors = [f"{key}: {e['error']}" for key, e in record["episodes"].items() if "error" in e]
        if errors:
            print("not written: episodes raised\n" + "\n".join(errors), file=sys.stderr)
            return 1
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(record, indent=1) + "\n")
        skipped = sum("skipped" in e for e in record["episodes"].values())
        import scenarios

        print(f"wrote {path}: {len(record['episodes'])} episodes ({skipped} skipped), made with the code in "
              f"{Path(scenarios.__file__).resolve().parent.parent}")
        return 0
    try:
        record = load_record(path)
        record_cells(record)
    except ValueError as exc:
        parser.error(str(exc).splitlines()[0])
    diffs = check(record, args.jobs, not args.quiet)
    print(format_report(diffs, record, path))
    return 1 if diffs else 0


if __name__ == "__main__":
    sys.exit(main())
