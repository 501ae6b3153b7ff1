"""The host check: the real-time loop's pacer and statistics around a fixed CPU work, nothing of ours in it."""

import json

import numpy as np
import pytest

from mmact_ctrl.realtime.host_check import ABORT_AFTER, HostCheckConfig, calibrate, main, run


def test_a_tick_longer_than_its_period_is_late_every_time_and_would_abort():
    # 5 ms of work on a 1 ms period: every command is late whatever the host, and 20 in a row abort a robot
    result = run(HostCheckConfig(work_us=5000, episodes=1, duration_s=0.05, fifo_priority=0, loop_cpu=None))
    s, e = result["summary"], result["episodes"][0]
    assert s["ticks"] == e["ticks"] == 50
    assert s["overruns"] == 50 and s["overrun_rate"] == 1.0
    assert s["control_command_success_rate_min"] == 0.0 and s["episodes_at_or_above_0_99"] == 0
    assert s["would_abort"] == 1 and ABORT_AFTER == 20  # once per run of late commands, not once per late command
    assert s["cycles_missed"] >= 40  # each tick starts later than the last
    assert s["work_us"]["median"] > 1000


def test_the_summary_adds_up_over_episodes():
    result = run(HostCheckConfig(work_us=50, episodes=2, duration_s=0.1, fifo_priority=0, loop_cpu=None))
    s, eps = result["summary"], result["episodes"]
    assert s["ticks"] == sum(e["ticks"] for e in eps) == 200
    assert s["overruns"] == sum(e["overruns"] for e in eps)
    assert s["control_command_success_rate_min"] == min(e["control_command_success_rate"] for e in eps)
    assert 0 <= s["slow_ticks"] <= s["ticks"] and s["iterations_per_tick"] >= 1
    assert s["work_us"]["median"] <= s["work_us"]["p99"] <= s["work_us"]["p999"] <= s["work_us"]["max"]
    # the slow ticks' CPU time / wall time is a share, present only when there were slow ticks
    assert (s["slow_cpu_over_wall"] is None) == (s["slow_ticks"] == 0)


def test_calibration_scales_with_the_work_asked_for():
    small, large = calibrate(100.0), calibrate(1000.0)
    assert small >= 1 and 5 <= large / small <= 20  # 10x the work, about 10x the iterations


BAD = [(["--work-us", "-3"], "--work-us"), (["--episodes", "0"], "--episodes"), (["--duration-s", "0"], "--duration-s"),
       (["--rt-priority", "120"], "--rt-priority")]


@pytest.mark.parametrize("argv, flag", BAD)
def test_bad_arguments_are_one_line_naming_the_switch(argv, flag, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert flag in err and "Traceback" not in err


def test_the_cli_prints_and_writes_its_figures(tmp_path, capsys):
    out = tmp_path / "host.json"
    assert main(["--work-us", "50", "--episodes", "1", "--duration-s", "0.1", "--rt-priority", "0", "--quiet",
                 "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "command success rate (min)" in text and "aborts a robot would have made" in text
    data = json.loads(out.read_text())
    assert data["summary"]["ticks"] == 100 and data["config"]["work_us"] == 50
    assert np.isfinite(data["summary"]["work_us"]["median"])
