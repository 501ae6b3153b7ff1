"""The sweep's one cell, run in a worker process: its chunk source and world (built once per process, ``_CACHE``),
a contact task's stack settings, one episode and its row of metrics, and the row stored as the cell's JSON file."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

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

    return task_stack_settings(task, bool(cell.get("compliance", False)), bool(cell.get("close_at_grasp", False)))


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
