"""Running the fault suite: one episode of one cell (fault x mode x source x seed) as one row of ``faults.csv``,
the cells of a selection, and the suite (sequential or over worker processes). Worlds, sources and the robot
model are built once per process."""

from __future__ import annotations

import json
import math
import sys
import time
import traceback

import numpy as np

from scenarios.faults.injectors import FaultSpec
from scenarios.faults.settings import RECOVERY_HOLD_S, RECOVERY_RADIUS_M, SAFETY_COLUMNS, SOURCES
from scenarios.world.tasks.registry import task_stack_settings

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
        _record_metrics(row, log)
        row["applicable"] = bool(inj.applicable)
        row["recovery_s"] = recovery_time_s(log, end if math.isfinite(end) else start)
    except Exception as exc:  # noqa: BLE001 - the suite survives and reports whatever escaped
        row["raised"] = f"{type(exc).__name__}: {exc}"[:300]
        row["traceback"] = traceback.format_exc()
    row["wall_s"] = time.perf_counter() - t0
    return (row, log) if keep_log else row


def _record_metrics(row: dict, log) -> None:
    """The episode's metrics (``mmact_ctrl.metrics``) and abort into ``row``."""
    from mmact_ctrl.metrics import episode_metrics

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
