"""The main job's command line: clear one-line errors for bad values, and the JSON/plot contract."""

import json
import subprocess
import sys

import pytest

from scenarios.moving_target import main
from scenarios.world.targets import KINDS

BAD = [
    (["--replan-hz", "-1"], "--replan-hz"),
    (["--replan-hz", "0"], "--replan-hz"),
    (["--bins", "-4"], "--bins"),
    (["--bins", "1"], "bins"),
    (["--latency-ms", "-5"], "--latency-ms"),
    (["--target", "zigzag"], "--target"),
    (["--speed", "-0.1"], "--speed"),
    (["--episodes", "0"], "--episodes"),
    (["--dropout", "1.5"], "--dropout"),
    (["--latency-ms", "7000", "--duration-s", "6"], "latency_ms"),
    (["--replan-hz", "nan"], "--replan-hz"),
    (["--instruction", "reach the green ball"], "instruction"),
    (["--latency-ms", "soon"], "--latency-ms"),
    (["--source", "policy", "--checkpoint", "/nonexistent/ckpt.pt"], "checkpoint"),
    (["--refine-bins", "-3"], "--refine-bins"),
    (["--expert-lead", "psychic"], "--expert-lead"),
    (["--mode", "warp"], "--mode"),
    (["--filter", "ct-imm"], "--filter"),
    (["--mode", "residual", "--residual-checkpoint", "/nonexistent/res.pt"], "residual"),
    (["--mpc-delay-ms", "25"], "--mpc-delay-ms"),
    (["--mpc-delay-ms", "5", "--no-mpc"], "--mpc-delay-ms"),
    (["--mpc-delay-ms", "5", "--realtime"], "--mpc-delay-ms"),
]


def test_the_command_itself_gives_one_line_and_exit_2(one_line_exit_2):
    """The real entry point (``python -m``, imports and all) writes one line to stderr and exits 2."""
    argv, name = BAD[0]
    proc = subprocess.run([sys.executable, "-m", "scenarios.moving_target", *argv, "--quiet"],
                          capture_output=True, text=True, timeout=120)
    one_line_exit_2(proc.returncode, proc.stderr, "error", name)


@pytest.mark.parametrize("argv,name", BAD)
def test_bad_values_give_one_clear_line(argv, name, capsys, one_line_exit_2):
    """Every bad value, through the command's ``main`` in this process (the entry point's own test is above: a
    process each cost 6 s of imports here)."""
    with pytest.raises(SystemExit) as exc:
        main([*argv, "--quiet"])
    one_line_exit_2(exc.value.code, capsys.readouterr().err, "error", name)


def test_json_and_plot_outputs(tmp_path, capsys):
    out_json, out_png = tmp_path / "run.json", tmp_path / "run.png"
    rc = main(["--episodes", "1", "--duration-s", "2", "--quiet", "--json", str(out_json), "--plot", str(out_png)])
    assert rc == 0
    payload = json.loads(out_json.read_text())
    assert set(payload) >= {"config", "summary", "episodes"}
    s = payload["summary"]
    for key in ("success_rate", "wrong_object_rate", "policy_latency_ms", "final_error_m", "time_to_reach_s", "tracking_ratio", "jerk_rms", "limit_violations",
                "qp_failures", "tick_us", "realtime_factor", "jump_recovered_rate", "jump_recovery_s"):
        assert key in s
    assert set(s["tick_us"]) == {"median", "p99"}
    assert set(payload["runs"]) == {"open_loop", "hybrid"}
    assert len(payload["episodes"]) == 1 and payload["episodes"][0]["mode"] == "hybrid"
    assert out_png.stat().st_size > 10_000
    table = capsys.readouterr().out
    assert "open_loop" in table and "hybrid" in table and "success rate" in table


@pytest.mark.parametrize("source", ["expert", "policy"])
@pytest.mark.parametrize("target", KINDS)
def test_every_target_runs_with_every_source(target, source, capsys):
    """Each motion family in the source's own scene (the policy's: two balls on its plane), one short episode."""
    assert main(["--source", source, "--target", target, "--mode", "open_loop", "--episodes", "1", "--duration-s", "0.6",
                 "--quiet"]) == 0
    assert "success rate" in capsys.readouterr().out
