"""The baselines behave as published (inpainting freezes, ensembling smooths); the sweep produces its tables and
figures, its RTC grid runs the delay it names. (Each executor's end-to-end episode: ``tests/test_executors.py``.)"""

import csv
import json
import subprocess
import sys

import numpy as np
import pytest

from mmact_ctrl.config import StackConfig
from mmact_ctrl.controller import HybridController
from mmact_ctrl.loop import run_episode
from mmact_ctrl.metrics import episode_metrics
from scenarios.world.factory import make_expert
from scenarios.sweep import Study, main as sweep_main


@pytest.fixture(scope="module")
def world(make_test_world):
    return make_test_world("linear", 0.2)


def test_inpaint_freezes_the_running_waypoints(world):
    cfg = StackConfig(mode="inpaint", duration_s=3.0, replan_hz=2.0, latency_ms=200.0)
    controller = HybridController(cfg)
    seen = []
    orig = controller.activate

    def spy(chunk, t, target):
        if controller.active is not None:
            # the new chunk agrees with the old one at the switch time: no jump
            old = controller.active.sample(t)[0]
            from mmact_ctrl.reference import ChunkReference

            new = ChunkReference(chunk, t, None).sample(t)[0]
            seen.append(np.linalg.norm(old[:3] - new[:3]))
        orig(chunk, t, target)

    controller.activate = spy
    run_episode(world, make_expert(), controller, seed=3)
    assert len(seen) >= 4 and max(seen) < 1e-3


def test_temporal_ensemble_is_smoother_than_open_loop_at_switches(world):
    res = {}
    for mode in ("open_loop", "temporal_ensemble"):
        log = run_episode(world, make_expert(), HybridController(StackConfig(mode=mode, duration_s=4.0, replan_hz=5.0)), seed=4)
        res[mode] = episode_metrics(log)["chunk_jump_acc_m_s2"]
    assert res["temporal_ensemble"] < res["open_loop"]


def test_quick_sweep_writes_table_report_and_figures(tmp_path):
    grid = [
        {"name": "replan", "modes": ["open_loop", "hybrid"], "replan_hz": [1.0], "latency_ms": [200.0],
         "target": ["linear"], "speed_m_s": [0.3], "bins": [2048], "seeds": [0]},
        {"name": "bins", "modes": ["open_loop"], "replan_hz": [1.0], "latency_ms": [200.0], "target": ["static"],
         "speed_m_s": [0.0], "bins": [64, 0], "seeds": [0]},
    ]
    out = tmp_path / "sweep"
    args = ["--out", str(out), "--grid", json.dumps(grid), "--duration-s", "2.5", "--workers", "1", "--quiet"]
    assert sweep_main(args) == 0
    rows = list(csv.DictReader((out / "results.csv").open()))
    assert len(rows) == 4
    for col in ("mode", "replan_hz", "latency_ms", "target", "speed_m_s", "bins", "seed", "success", "final_error_m",
                "tracking_ratio", "jerk_rms", "chunk_jump_acc_m_s2"):
        assert col in rows[0]
    report = (out / "report.md").read_text()
    assert "replan.png" in report and "bins.png" in report
    assert (out / "replan.png").stat().st_size > 5000 and (out / "bins.png").stat().st_size > 5000
    # resumable: a second run does no new work
    cells = sorted(p.stat().st_mtime for p in (out / "cells").iterdir())
    assert sweep_main(args) == 0
    assert sorted(p.stat().st_mtime for p in (out / "cells").iterdir()) == cells


@pytest.mark.parametrize("grid,needle", [
    ('[{"name": "x", "modes": ["warp"], "replan_hz": [1], "latency_ms": [0], "target": ["linear"], "speed_m_s": [0.2], "bins": [2048], "seeds": [0]}]', "warp"),
    ('[{"name": "x", "modes": ["hybrid"], "replan_hz": [-1], "latency_ms": [0], "target": ["linear"], "speed_m_s": [0.2], "bins": [2048], "seeds": [0]}]', "replan_hz"),
    ('[{"name": "x", "modes": ["hybrid"], "replan_hz": [1], "latency_ms": [0], "target": ["spiral"], "speed_m_s": [0.2], "bins": [2048], "seeds": [0]}]', "spiral"),
    ('[{"name": "x", "modes": ["hybrid"]}]', "bad grid"),
    ("not json", "bad grid"),
])
def test_bad_grid_gives_a_clear_error(tmp_path, grid, needle):
    proc = subprocess.run([sys.executable, "-m", "scenarios.sweep", "--out", str(tmp_path), "--grid", grid, "--quiet"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert needle in proc.stderr and "Traceback" not in proc.stderr


def test_study_validation():
    with pytest.raises(ValueError, match="bins"):
        Study("s", ("hybrid",), (1.0,), (0.0,), ("linear",), (0.2,), (1,), (0,))


def test_rtc_grid_cells_run_the_delay_and_horizon_they_name(tmp_path):
    grid = [{"name": "rtc_grid", "modes": ["open_loop", "receding"], "replan_hz": [1.0], "latency_ms": [0.0],
             "target": ["reversal"], "speed_m_s": [0.2], "bins": [2048], "seeds": [0], "d_steps": [3], "s_steps": [4]}]
    out = tmp_path / "rtc"
    assert sweep_main(["--out", str(out), "--grid", json.dumps(grid), "--duration-s", "2.5", "--workers", "1",
                       "--quiet"]) == 0
    rows = {r["mode"]: r for r in csv.DictReader((out / "results.csv").open())}
    for mode, r in rows.items():
        assert float(r["latency_ms"]) == 300.0 and float(r["replan_hz"]) == 2.5 and r["lead"] == "velocity"
        assert abs(float(r["d_measured"]) - 3.0) < 0.05, (mode, r["d_measured"])  # d steps consumed while computing
    assert "rtc_grid.png" in (out / "report.md").read_text()
