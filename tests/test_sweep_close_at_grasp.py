"""The sweep's axis for pick's ``--close-at-grasp`` (README, Contact, point 14): a study's ``close_at_grasp`` list
and the sweep's ``--close-at-grasp`` flag, the cells' keys as before with it off, and the switch reaching the stack
of a cell that runs."""

from __future__ import annotations

import csv
import json
import subprocess
import sys

import pytest

from scenarios.sweep.cells import _task_stack
from scenarios.sweep.cli import main as sweep_main
from scenarios.sweep.study import Study, cell_key, task_grid


def _pick_study(**kw) -> Study:
    return Study("pick", ("hybrid",), (1.0,), (200.0,), ("reversal",), (0.2,), (2048,), (0,), task="pick", **kw)


def test_the_axis_multiplies_the_cells_and_off_keeps_the_published_keys():
    off, both = _pick_study().cells(), _pick_study(close_at_grasp=(False, True)).cells()
    assert [c["close_at_grasp"] for c in both] == [False, True]
    old = {k: v for k, v in off[0].items() if k != "close_at_grasp"}  # a cell as the sweep built it before the axis
    assert cell_key(off[0], 6.0) == cell_key(old, 6.0) == cell_key(both[0], 6.0)
    assert cell_key(both[1], 6.0) != cell_key(both[0], 6.0)
    for study in task_grid("pick") + task_grid("insert"):  # the published grids: every cell off
        assert all(c["close_at_grasp"] is False for c in study.cells())


def test_the_switch_reaches_the_cells_stack_only_when_on():
    off, on = _pick_study(close_at_grasp=(False, True)).cells()
    assert "close_below_reading_m" not in _task_stack(off)
    assert _task_stack(on)["close_below_reading_m"] < _task_stack(on)["close_below_m"]
    assert "close_stops_descent_m" in _task_stack(on)


@pytest.mark.parametrize("task", ["insert", "reach"])
def test_only_pick_has_the_switch(task):
    with pytest.raises(ValueError, match="close_at_grasp is a switch of pick"):
        Study("s", ("hybrid",), (1.0,), (200.0,), ("static",), (0.0,), (2048,), (0,), task=task,
              close_at_grasp=(True,))
    with pytest.raises(ValueError, match="close_at_grasp must be a list"):
        _pick_study(close_at_grasp=())


def test_the_flag_on_a_task_without_the_switch_is_one_line(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "scenarios.sweep", "--out", str(tmp_path), "--task", "insert",
                           "--close-at-grasp", "--quick", "--quiet"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert "close_at_grasp is a switch of pick" in proc.stderr and "Traceback" not in proc.stderr


def test_a_sweep_with_both_runs_the_wedge_seed_each_way(tmp_path):
    """Fresh seed 6058 on the reversal (``tests/test_closing_stop.py``): the default closing wedges the cube against
    the belt (over 30 N); with the switch the pad pushes it along the belt. The sweep's two cells show both."""
    grid = [{"name": "pick", "modes": ["hybrid"], "replan_hz": [1.0], "latency_ms": [200.0], "target": ["reversal"],
             "speed_m_s": [0.2], "bins": [2048], "seeds": [6058], "task": "pick", "close_at_grasp": [False, True]}]
    out = tmp_path / "cag"
    assert sweep_main(["--out", str(out), "--grid", json.dumps(grid), "--duration-s", "4.9", "--workers", "1",
                       "--quiet"]) == 0
    rows = {r["close_at_grasp"]: r for r in csv.DictReader((out / "results.csv").open())}
    assert int(rows["False"]["contact_force_violations"]) > 0, rows["False"]
    assert int(rows["True"]["contact_force_violations"]) == 0 and int(rows["True"]["limit_violations"]) == 0
    assert "close at grasp" in (out / "report.md").read_text()
