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
different CPU or a different numpy / MuJoCo / OSQP / torch may legitimately move the last bits. OpenBLAS's kernel,
which follows the CPU, is pinned (``scenarios.blas``: the command re-executes itself with ``OPENBLAS_CORETYPE``).
What no variable pins (the policy's episodes on an Intel Xeon against an AMD EPYC) is kept apart: each CPU model has
its own record beside the default one (``record.<cpu>.json``, :func:`scenarios.golden_record.host_record_path`), and
without a PATH ``--write`` and ``--check`` use this host's.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import sys
from dataclasses import dataclass
from pathlib import Path

from scenarios.blas import PINNED_CORETYPE, VARIABLE, pin_blas_kernel
from scenarios.cli import HelpFormatter, OneLineErrorParser
from scenarios.golden_record import (DEFAULT_PATHS, DEADLINE_ORDER, FORMAT, LIBRARIES, PROG, SIMULATED_ORDER,  # noqa: F401
                                     SEEDS, SOURCES, TARGETS, WALL_CLOCK_KEYS, Difference, compare, compare_episode,
                                     format_report, host_record_path, load_record, made_with, make_record,
                                     record_to_check)

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


def record_cells(record: dict) -> tuple[Cell, ...]:
    """The cells a record names; ValueError when one is malformed."""
    return tuple(Cell.from_json(c) for c in record["cells"])


def check(record: dict, jobs: int = 2, progress: bool = True) -> list[Difference]:
    """Rerun the episodes ``record`` names and compare them with it: the differences (empty: bit for bit)."""
    return compare(record["episodes"], run_cells(record_cells(record), jobs, progress))


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
    env = dict(os.environ)
    if argv is None and VARIABLE not in env and pin_blas_kernel(env):
        # the command line: run again on the pinned OpenBLAS kernel (read when numpy loads: scenarios.blas)
        sys.stdout.flush()
        os.execve(sys.executable, [sys.executable, "-m", "scenarios.golden", *sys.argv[1:]], env)
    if os.environ.get(VARIABLE) != PINNED_CORETYPE and pin_blas_kernel({}):
        print(f"note: {VARIABLE} is not {PINNED_CORETYPE}: OpenBLAS runs the host's own kernels and the last bits may "
              f"differ from the record's (scenarios.blas)", file=sys.stderr)
    text = args.write if args.write is not None else args.check
    default = DEFAULT_PATHS[args.subset]
    if text:
        path = Path(text)
    else:  # this host's CPU's record: written beside the default one, checked against it where it exists
        path = host_record_path(default) if args.write is not None else record_to_check(default)
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
