"""The study: where does the control layer beat the best fixes the field uses, and where does it add nothing?

    python -m scenarios.sweep --out docs/sweep               # default grid, expert source, ~10 min on 2 cores
    python -m scenarios.sweep --quick --out out/quick        # < 2 min
    python -m scenarios.sweep --source policy --out ...      # the same grid with the learned policy
    python -m scenarios.sweep --backend ray --out ...        # spread the same grid over a Ray cluster

The grid is the union of studies, each a cartesian product over mode x replan_hz x latency_ms x target x speed_m_s x
bins x seed x perception x lead (the expert's: ``velocity`` aims where two frames say the target will be, ``none``
where one frame shows it) x (d, s) (RTC's grid: inference delay d and execution horizon s in chunk steps of
0.1 s; then latency = d steps, the replan period = s steps, and ``receding`` runs s waypoints per chunk):

- ``lead``:     every mode, lead velocity vs none, linear target at 0.2 / 0.3 / 0.4 m/s (1 Hz, 200 ms);
- ``families``: every mode on the motions that change after the shot (reversal, swerve, jump, random_walk,
                accelerating) at 1 and 5 Hz (200 ms, lead velocity): the archery question;
- ``replan``:   every mode vs replan frequency (linear 0.3 m/s, 200 ms, lead velocity);
- ``rtc_grid``: every mode on d x s, d beyond the chunk (16 steps) included (reversal 0.2 m/s, lead velocity);
- ``bins``:     the quantization trap, 64 to 8192 bins and none (static target, open_loop and hybrid);
- ``perception``: hybrid with the oracle target channel vs the camera (30 Hz, 50 ms; linear, 0.2 m/s, 1 Hz).

Every mode of a study runs on the same seeds and the same target motions, and is given the same information: the
same chunks (the same source and lead), and the residual and hybrid layers the same 100 Hz measurement channel.
One episode per cell; each result is a JSON file under ``OUT/cells/`` so an interrupted sweep resumes where it
stopped. ``OUT/results.csv`` has one row per episode (every grid axis and every episode metric); ``OUT/report.md``
holds the tables with 95 % Wilson intervals, the paired comparisons (same seeds: McNemar, Wilcoxon) and the
conditions where the control layer adds nothing, and links the PNG figures.
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import json
import math
import sys
import time
from dataclasses import dataclass
from itertools import product
from pathlib import Path

import numpy as np

from mmact_ctrl.config import MODES
from mmact_ctrl.executors import make_executor
from mmact_ctrl.sources.contract import SourceError, require_capabilities
from scenarios.sources import build_source, close_source, settings_from_args, source_spec_arg

AXES: tuple[str, ...] = ("study", "mode", "replan_hz", "latency_ms", "target", "speed_m_s", "bins", "seed", "perception",
                         "lead", "d_steps", "s_steps")
#: the axes of a contact task's cells (``--task pick|insert``); reach's cells carry none of them (their keys, and the
#: published reach sweeps, are unchanged)
TASK_AXES: tuple[str, ...] = ("task", "clearance_mm", "noise_m", "compliance")
PERCEPTIONS: tuple[str, ...] = ("oracle", "camera")
LEADS: tuple[str, ...] = ("velocity", "none")
#: the expert's waypoint spacing: one RTC step, s
STEP_S = 0.1


@dataclass(frozen=True)
class Study:
    """One cartesian product of the grid. With ``d_steps`` and ``s_steps`` (RTC's grid) the latency is
    ``d * STEP_S`` and the replan period ``s * STEP_S`` (``latency_ms`` and ``replan_hz`` are then ignored)."""

    name: str
    modes: tuple[str, ...]
    replan_hz: tuple[float, ...]
    latency_ms: tuple[float, ...]
    target: tuple[str, ...]
    speed_m_s: tuple[float, ...]
    bins: tuple[int, ...]
    seeds: tuple[int, ...]
    perception: tuple[str, ...] = ("oracle",)
    lead: tuple[str, ...] = ("velocity",)
    d_steps: tuple[int, ...] = ()
    s_steps: tuple[int, ...] = ()
    task: str = "reach"
    clearance_mm: tuple[float, ...] = (1.0,)
    noise_m: tuple[float, ...] = (0.002,)
    compliance: tuple[bool, ...] = (False,)

    def __post_init__(self) -> None:
        from scenarios.world.tasks.registry import TASKS

        if self.task not in TASKS:
            raise ValueError(f"study {self.name!r}: unknown task {self.task!r}; expected one of {TASKS}")
        if any(not (c > 0 and math.isfinite(c)) for c in self.clearance_mm) or \
                any(not (n >= 0 and math.isfinite(n)) for n in self.noise_m):
            raise ValueError(f"study {self.name!r}: clearance_mm must be > 0 and noise_m >= 0, got "
                             f"{self.clearance_mm} and {self.noise_m}")
        bad = [m for m in self.modes if m not in MODES]
        if bad:
            raise ValueError(f"study {self.name!r}: unknown mode(s) {bad}; expected some of {MODES}")
        if any(not (f > 0 and math.isfinite(f)) for f in self.replan_hz):
            raise ValueError(f"study {self.name!r}: replan_hz must be > 0, got {self.replan_hz}")
        if any(not (x >= 0) for x in self.latency_ms):
            raise ValueError(f"study {self.name!r}: latency_ms must be >= 0, got {self.latency_ms}")
        if any(not (x >= 0) for x in self.speed_m_s):
            raise ValueError(f"study {self.name!r}: speed_m_s must be >= 0, got {self.speed_m_s}")
        if any(b < 0 or b == 1 for b in self.bins):
            raise ValueError(f"study {self.name!r}: bins must be 0 or >= 2, got {self.bins}")
        if not self.seeds:
            raise ValueError(f"study {self.name!r}: needs at least one seed")
        bad = [x for x in self.perception if x not in PERCEPTIONS]
        if bad or not self.perception:
            raise ValueError(f"study {self.name!r}: perception must be some of {PERCEPTIONS}, got {self.perception}")
        bad = [x for x in self.lead if x not in LEADS]
        if bad or not self.lead:
            raise ValueError(f"study {self.name!r}: lead must be some of {LEADS}, got {self.lead}")
        if bool(self.d_steps) != bool(self.s_steps):
            raise ValueError(f"study {self.name!r}: d_steps and s_steps go together, got {self.d_steps} and {self.s_steps}")
        if any(int(d) != d or d < 0 for d in self.d_steps) or any(int(x) != x or x < 1 for x in self.s_steps):
            raise ValueError(f"study {self.name!r}: d_steps must be ints >= 0 and s_steps ints >= 1, got "
                             f"{self.d_steps} and {self.s_steps}")

    def cells(self) -> list[dict]:
        base = dict(study=self.name)
        if self.d_steps:
            timing = [dict(latency_ms=round(1000.0 * d * STEP_S, 6), replan_hz=round(1.0 / (s * STEP_S), 6),
                           d_steps=int(d), s_steps=int(s)) for d, s in product(self.d_steps, self.s_steps)]
        else:
            timing = [dict(latency_ms=lat, replan_hz=f, d_steps=None, s_steps=None)
                      for f, lat in product(self.replan_hz, self.latency_ms)]
        contact = [{}] if self.task == "reach" else [
            dict(task=self.task, clearance_mm=c, noise_m=n, compliance=bool(k))
            for c, n, k in product(self.clearance_mm, self.noise_m, self.compliance)]
        return [
            {**base, "mode": m, **tm, "target": tg, "speed_m_s": sp, "bins": b, "seed": sd, "perception": pc, "lead": ld,
             **ct}
            for m, tm, tg, sp, b, ct, sd, pc, ld in product(
                self.modes, timing, self.target, self.speed_m_s, self.bins, contact, self.seeds, self.perception,
                self.lead,
            )
        ]


#: the motions that change after the shot (the archery question)
FAMILIES: tuple[str, ...] = ("reversal", "swerve", "jump", "random_walk", "accelerating")


def default_grid(quick: bool = False, seeds: int = 10) -> list[Study]:
    """The default grid: ``seeds`` seeds per cell in the lead and families studies (a paired test on n seeds cannot
    reach p < 0.05 below 6), fewer on the wide d x s grid and the replan curve."""
    all_modes = MODES
    if quick:
        s = (0, 1)
        return [
            Study("lead", all_modes, (1.0,), (200.0,), ("linear",), (0.3,), (2048,), s, lead=LEADS),
            Study("families", all_modes, (1.0,), (200.0,), ("reversal", "jump"), (0.3,), (2048,), s),
            Study("rtc_grid", all_modes, (1.0,), (200.0,), ("reversal",), (0.2,), (2048,), (0,), d_steps=(1, 4),
                  s_steps=(2, 8)),
            Study("bins", ("open_loop",), (1.0,), (200.0,), ("static",), (0.0,), (64, 2048, 0), (0,)),
        ]
    s = tuple(range(seeds))
    few = tuple(range(max(1, min(seeds, 3))))
    return [
        Study("lead", all_modes, (1.0,), (200.0,), ("linear",), (0.2, 0.3, 0.4), (2048,), s, lead=LEADS),
        Study("families", all_modes, (1.0, 5.0), (200.0,), FAMILIES, (0.3,), (2048,), s),
        Study("replan", all_modes, (0.5, 1.0, 2.0, 5.0, 10.0), (200.0,), ("linear",), (0.3,), (2048,), few),
        Study("rtc_grid", all_modes, (1.0,), (200.0,), ("reversal",), (0.2,), (2048,), few,
              d_steps=(0, 1, 2, 4, 8, 16, 20), s_steps=(1, 2, 4, 8)),
        Study("bins", ("open_loop", "hybrid"), (1.0,), (200.0,), ("static",), (0.0,), (64, 256, 1024, 2048, 8192, 0), few),
        Study("perception", ("hybrid",), (1.0,), (200.0,), ("linear",), (0.2,), (2048,), few, PERCEPTIONS),
    ]


def task_grid(task: str, quick: bool = False, seeds: int = 10) -> list[Study]:
    """The grid of a contact task (``--task``): open_loop vs hybrid at 1 Hz, 200 ms, expert lead velocity.

    - pick: static, linear at 0.2 and 0.4 m/s, reversal and jump at 0.2 m/s;
    - insert: the table the seed asks for, a static fixture: bins (256, 1024, 2048, 8192) x clearance (3, 1, 0.5,
      0.25 mm) x sensing noise (0, 2 mm) x mode (open_loop, hybrid) x compliance (off, on)."""
    modes = ("open_loop", "hybrid")
    s = tuple(range(2 if quick else seeds))
    if task == "pick":
        if quick:
            return [Study("pick", modes, (1.0,), (200.0,), ("static", "linear"), (0.2,), (2048,), s, task="pick")]
        return [Study("pick", modes, (1.0,), (200.0,), ("static",), (0.0,), (2048,), s, task="pick"),
                Study("pick", modes, (1.0,), (200.0,), ("linear",), (0.2, 0.4), (2048,), s, task="pick"),
                Study("pick", modes, (1.0,), (200.0,), ("reversal", "jump"), (0.2,), (2048,), s, task="pick")]
    if task == "insert":
        if quick:
            return [Study("insert", modes, (1.0,), (200.0,), ("static",), (0.0,), (2048,), s, task="insert",
                          clearance_mm=(1.0,), noise_m=(0.002,), compliance=(False, True))]
        return [Study("insert", modes, (1.0,), (200.0,), ("static",), (0.0,), (256, 1024, 2048, 8192), s,
                      task="insert", clearance_mm=(3.0, 1.0, 0.5, 0.25), noise_m=(0.0, 0.002),
                      compliance=(False, True))]
    return default_grid(quick, seeds)


def cell_key(cell: dict, duration_s: float) -> str:
    text = json.dumps({**{k: cell.get(k) for k in AXES if k not in ("study", "perception")}, "duration_s": duration_s,
                       **({k: cell.get(k) for k in TASK_AXES} if cell.get("task", "reach") != "reach" else {}),
                       **({"perception": cell["perception"]} if cell.get("perception", "oracle") != "oracle" else {}),
                       **({"source": cell["source"], "checkpoint": cell.get("checkpoint")}
                          if cell.get("source", "expert") != "expert" else {}),
                       **({"source_args": cell["source_args"]} if cell.get("source_args") else {}),
                       **({"preset": cell["preset"]} if cell.get("preset") else {})}, sort_keys=True)
    return hashlib.sha1(text.encode()).hexdigest()[:16]


# ---- running one cell (in a worker process) ------------------------------------------------

_CACHE: dict = {}


def _source_and_world(cell: dict):
    """The cell's chunk source and world, built once per process (``scenarios.sources``): the expert with the cell's
    bins and lead in a world of the cell's motion; any other source (our policy, ``module:factory``, ``ws://``) in
    the scenes it asks for."""
    from scenarios.world.factory import make_expert, make_world
    from scenarios.sources import SourceSettings, build_source, scene_settings

    spec = cell.get("source", "expert")
    task = cell.get("task", "reach")
    contact = {} if task == "reach" else dict(task=task, clearance_mm=cell["clearance_mm"], noise_m=cell["noise_m"])
    if spec == "expert":
        wkey = ("world", cell["target"], cell["speed_m_s"], spec, json.dumps(contact, sort_keys=True))
        if wkey not in _CACHE:
            _CACHE[wkey] = make_world(target=cell["target"], speed_m_s=cell["speed_m_s"], **contact)
        world = _CACHE[wkey]
        return make_expert(bins=cell["bins"], lead=cell.get("lead", "velocity"), world=world), world
    skey = ("source", spec, json.dumps(cell.get("source_args") or {}, sort_keys=True), cell.get("checkpoint"),
            cell.get("preset"))
    if skey not in _CACHE:
        _CACHE[skey] = build_source(SourceSettings(spec=spec, args=dict(cell.get("source_args") or {}),
                                                   checkpoint=cell.get("checkpoint") or None, preset=cell.get("preset")))
    source = _CACHE[skey]
    wkey = ("world", cell["target"], cell["speed_m_s"], skey, json.dumps(contact, sort_keys=True))
    if wkey not in _CACHE:  # the source's scenes (our policy's: two balls, its cameras and training plane)
        scene = {"n_objects": 2, **scene_settings(source), **contact}
        _CACHE[wkey] = make_world(target=cell["target"], speed_m_s=cell["speed_m_s"], **scene)
    return source, _CACHE[wkey]


def _task_stack(cell: dict) -> dict:
    """A contact task's stack settings (``task_stack_settings``); none for reach."""
    task = cell.get("task", "reach")
    if task == "reach":
        return {}
    from scenarios.world.tasks.registry import task_stack_settings

    return task_stack_settings(task, bool(cell.get("compliance", False)))


def run_cell(cell: dict, duration_s: float) -> dict:
    """One episode for one grid cell; returns the row (axes + episode metrics)."""
    from mmact_ctrl.config import StackConfig
    from mmact_ctrl.controller import HybridController
    from mmact_ctrl.loop import run_episode
    from mmact_ctrl.metrics import episode_metrics

    source, world = _source_and_world(cell)
    if "model" not in _CACHE:
        from controllers.robot_model import PandaModel

        _CACHE["model"] = PandaModel()
    sensor = None
    if cell.get("perception", "oracle") == "camera":  # the ball measured in rendered frames (30 Hz, 50 ms)
        skey = ("camera", id(world))
        if skey not in _CACHE:
            from scenarios.world.camera_sensor import CameraSensor, CameraSensorConfig

            _CACHE[skey] = CameraSensor(world, CameraSensorConfig())
        sensor = _CACHE[skey]
    cfg = StackConfig(mode=cell["mode"], replan_hz=cell["replan_hz"], latency_ms=cell["latency_ms"], bins=cell["bins"],
                      duration_s=duration_s, perception_hz=sensor.config.rate_hz if sensor is not None else 100.0,
                      receding_k=int(cell.get("s_steps") or 0), **_task_stack(cell))
    controller = HybridController(cfg, model=_CACHE["model"])
    log = run_episode(world, source, controller, seed=cell["seed"], sensor=sensor)
    m = episode_metrics(log)
    m["jump_recovery_s"] = float(np.median(m["jump_recovery_s"])) if m["jump_recovery_s"] else float("nan")
    m.pop("instruction", None)
    for key in ("plan_ms", "d_steps", "mpc_solve_us", "exec_us", "source_timing_ms"):  # per-chunk/tick lists:
        m.pop(key, None)  # the row keeps their medians
    m.pop("target_start_pos_m", None)  # a vector; the cell's seed fixes it
    return {**cell, "duration_s": duration_s, **{k: v for k, v in m.items() if k != "seed"}}


def _run_and_store(args: tuple[dict, float, str]) -> dict:
    cell, duration_s, path = args
    row = run_cell(cell, duration_s)
    Path(path).write_text(json.dumps(row))
    return row


# ---- backends ------------------------------------------------------------------------------


def run_local(todo: list[tuple[dict, float, str]], workers: int, progress) -> None:
    import multiprocessing as mp

    if workers <= 1:
        for item in todo:
            _run_and_store(item)
            progress()
        return
    with mp.get_context("spawn").Pool(workers) as pool:
        for _ in pool.imap_unordered(_run_and_store, todo):
            progress()


def run_ray(todo: list[tuple[dict, float, str]], address: str | None, progress) -> None:
    try:
        import ray
    except ImportError:
        raise SystemExit("--backend ray needs Ray: pip install -e '.[cluster]'") from None
    ray.init(address=address or "auto", ignore_reinit_error=True, log_to_driver=False)
    remote = ray.remote(num_cpus=1)(run_cell)
    refs = {remote.remote(cell, duration_s): path for cell, duration_s, path in todo}
    pending = list(refs)
    while pending:
        done, pending = ray.wait(pending, num_returns=1)
        row = ray.get(done[0])
        Path(refs[done[0]]).write_text(json.dumps(row))  # results are files on the driver: resumable
        progress()


# ---- report --------------------------------------------------------------------------------


def write_csv(rows: list[dict], path: Path) -> None:
    keys: list[str] = []
    for r in rows:
        keys += [k for k in r if k not in keys]
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m scenarios.sweep", description=__doc__,
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
                                                  "speed_m_s, bins, seeds[, perception, lead, d_steps, s_steps]}) instead "
                                                  "of the default grid")
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
    args = p.parse_args(argv)
    if args.seeds < 1 or args.workers < 1:
        p.error(f"--seeds and --workers must be >= 1, got {args.seeds} and {args.workers}")
    # a contact task needs its 6 s even in a quick run (a peg seats at 3-5 s)
    duration_s = args.duration_s if args.duration_s is not None else (4.0 if args.quick and args.task == "reach" else 6.0)
    if not duration_s > 0:
        p.error(f"--duration-s must be > 0, got {duration_s}")
    try:
        if args.grid:
            text = args.grid.strip()
            spec = json.loads(text if text.startswith("[") or not Path(text).is_file() else Path(text).read_text())
            studies = [Study(**{k: tuple(v) if isinstance(v, list) else v for k, v in s.items()}) for s in spec]
        else:
            studies = task_grid(args.task, args.quick, args.seeds)
        from scenarios.world.targets import KINDS

        for s in studies:
            bad = [t for t in s.target if t not in KINDS]
            if bad:
                raise ValueError(f"study {s.name!r}: unknown target(s) {bad}; expected some of {KINDS}")
            lats = [d * STEP_S * 1000.0 for d in s.d_steps] if s.d_steps else list(s.latency_ms)
            if any(lat / 1000.0 >= duration_s for lat in lats):
                raise ValueError(f"study {s.name!r}: a latency of {max(lats):g} ms is not shorter than the episode")
        if not isinstance(spec if args.grid else [], list):
            raise ValueError("--grid must be a JSON list of studies")
    except (ValueError, TypeError, OSError) as exc:
        p.error(f"bad grid: {exc}")

    out = Path(args.out)
    (out / "cells").mkdir(parents=True, exist_ok=True)
    cells = [c for s in studies for c in s.cells()]
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
    if settings.kind != "expert":
        ckpt = None
        if settings.kind == "policy":
            from policy.inference import DEFAULT_CHECKPOINT

            ckpt = args.checkpoint or str(DEFAULT_CHECKPOINT)
        # a source's own chunks: no expert lead axis (one cell per lead-free condition), no bins study
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
        cells = own_cells
    else:
        cells = [{**c, "source": "expert"} for c in cells]
    todo, rows = [], []
    for c in cells:
        path = out / "cells" / f"{cell_key(c, duration_s)}.json"
        if path.is_file():
            continue
        todo.append((c, duration_s, str(path)))
    from tqdm import tqdm

    t0 = time.perf_counter()
    bar = tqdm(total=len(cells), initial=len(cells) - len(todo), desc="cells", unit="ep", disable=args.quiet,
               file=sys.stderr)
    try:
        if args.backend == "ray":
            run_ray(todo, args.ray_address, lambda: bar.update(1))
        else:
            run_local(todo, args.workers, lambda: bar.update(1))
    finally:
        bar.close()
    for c in cells:  # rows in grid order, each cell's study label from this grid
        row = json.loads((out / "cells" / f"{cell_key(c, duration_s)}.json").read_text())
        rows.append({**row, "study": c["study"]})
    write_csv(rows, out / "results.csv")
    from scenarios.sweep.report import write_report

    write_report(rows, out, wall_s=time.perf_counter() - t0, resumed=len(cells) - len(todo), notes=notes)
    for n in notes:
        print(n)
    print(f"{len(rows)} episodes ({len(cells) - len(todo)} resumed) -> {out / 'results.csv'}, {out / 'report.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
