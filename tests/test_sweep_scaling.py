"""The sweep's scaling benchmark (``scenarios.sweep_scaling``): the CPU time of the whole process tree, the
comparison of the runs' results, and one real run of a tiny grid with 1 and 2 workers. No figure is timed here: the
test holds what the benchmark counts, not how fast this host is."""

from __future__ import annotations

import json
import os
import sys

import pytest

from scenarios.sweep_scaling import differences, is_timing, main, run_tree_measured

if os.environ.get("MMACT_REQUIRE_EXTRAS") != "1":
    pytest.importorskip("psutil")

TINY_GRID = [{"name": "tiny", "modes": ["open_loop", "hybrid"], "replan_hz": [1.0], "latency_ms": [200.0],
              "target": ["linear"], "speed_m_s": [0.2], "bins": [2048], "seeds": [0, 1]}]


def test_timings_are_not_results_and_a_changed_result_is_reported():
    assert is_timing("tick_us_median") and is_timing("mpc_solve_us_p99") and is_timing("realtime_factor")
    assert is_timing("sensor_ms_per_sim_s") and not is_timing("success") and not is_timing("final_error_m")
    a = {("s", "hybrid", "0"): {"success": "True", "final_error_m": "0.01", "tick_us_median": "80.0"}}
    b = {("s", "hybrid", "0"): {"success": "True", "final_error_m": "0.01", "tick_us_median": "95.0"}}
    assert differences(a, b) == []  # only a timing moved
    c = {("s", "hybrid", "0"): {"success": "False", "final_error_m": "0.01", "tick_us_median": "80.0"}}
    assert differences(a, c) == ["cell ('s', 'hybrid', '0'): success 'True' != 'False'"]
    assert differences(a, {}) == ["cell ('s', 'hybrid', '0') only in the first run"]


def test_the_cpu_time_of_forked_grandchildren_is_counted(tmp_path):
    """A child that forks two busy grandchildren and waits on neither's rusage: its own rusage would show almost
    nothing (as /usr/bin/time shows for the sweep's fork-server workers); the tree's sampled time shows their work."""
    code = ("import multiprocessing as mp, time\n"
            "def spin():\n"
            "    t = time.process_time()\n"
            "    while time.process_time() - t < 0.6: pass\n"
            "if __name__ == '__main__':\n"
            "    ctx = mp.get_context('forkserver')\n"
            "    ps = [ctx.Process(target=spin) for _ in range(2)]\n"
            "    [p.start() for p in ps]; [p.join() for p in ps]\n"
            "    assert all(p.exitcode == 0 for p in ps)\n")
    script = tmp_path / "spin.py"
    script.write_text(code)
    status, wall_s, cpu_s = run_tree_measured([sys.executable, str(script)], poll_s=0.02)
    assert status == 0 and cpu_s >= 0.9, (wall_s, cpu_s)  # 1.2 s of spinning, less the last samples' gaps


def test_a_tiny_grid_gives_the_same_results_with_one_and_two_workers(tmp_path, capsys):
    grid = tmp_path / "grid.json"
    grid.write_text(json.dumps(TINY_GRID))
    status = main(["--grid", str(grid), "--workers", "1", "2", "--out", str(tmp_path / "runs"),
                   "--sweep-arg=--duration-s=2", "--json", str(tmp_path / "scaling.json")])
    report = json.loads((tmp_path / "scaling.json").read_text())
    assert status == 0 and report["identical"] and report["differences"] == []
    one, two = report["runs"]
    assert (one["workers"], two["workers"]) == (1, 2) and one["episodes"] == two["episodes"] == 4
    # the two workers' CPU is counted, not only the parent's (which alone is a fraction of one worker's)
    assert two["cpu_s"] >= 0.7 * one["cpu_s"] > 0, report
    assert "results identical" in capsys.readouterr().out


def test_bad_input_is_one_line_naming_the_switch(tmp_path, capsys):
    for argv, switch in ((["--grid", str(tmp_path / "none.json")], "--grid"), (["--workers", "0"], "--workers"),
                         (["--poll-s", "0"], "--poll-s")):
        with pytest.raises(SystemExit) as e:
            main(argv)
        assert e.value.code == 2 and switch in capsys.readouterr().err
