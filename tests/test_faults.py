"""The fault-injection suite: every fault of the registry survives one short episode end to end, each fault is
seen by the part of the stack that should see it, and the CLI reports bad values in one line."""

import csv
import json
import subprocess
import sys

import numpy as np
import pytest

from controllers.robot_model import PandaModel
from mmact_ctrl.config import StackConfig
from mmact_ctrl.controller import HybridController
from mmact_ctrl.metrics import episode_metrics
from scenarios.world.factory import make_expert
from scenarios.faults.injectors import (
    FAULTS,
    UNREACHABLE_POS_M,
    FaultSpec,
    FaultyPerception,
    FaultySource,
    inject,
    run_fault_episode,
)
from scenarios.faults import main, recovery_time_s

ONSET_S = 0.5
DURATION_S = 2.0
SEED = 0
#: faults of the chunk source: also run open-loop (no filter, no retargeting)
SOURCE_FAULTS = ("none", "source_raises", "nan_chunk", "garbage_tokens", "splice_offset", "source_silent_0.1s",
                 "source_silent_1.5s", "source_silent_3s", "latency_spike_10x", "wire_error_frame", "wire_slow",
                 "wire_bad_shape", "wire_nan", "wire_server_dies")
CASES = [(f, "hybrid") for f in FAULTS] + [(f, "open_loop") for f in SOURCE_FAULTS]
_RESULTS: dict = {}


@pytest.fixture(scope="module")
def world(make_test_world):
    return make_test_world("linear", 0.2, n_objects=2)


@pytest.fixture(scope="module")
def controllers():
    """A fresh controller per episode (one shared robot model): a reused one carries its solvers' warm starts
    from episode to episode, so its results would depend on the order of the tests."""
    model = PandaModel()
    return lambda mode: HybridController(StackConfig(mode=mode, duration_s=DURATION_S), model=model)


def episode(world, controllers, fault: str, mode: str):
    """(metrics, log, injection, controller) of one episode, run once per module."""
    key = (fault, mode)
    if key not in _RESULTS:
        controller = controllers(mode)
        log, inj = run_fault_episode(FaultSpec(fault, t_fault_s=ONSET_S), world, make_expert(), controller, SEED)
        _RESULTS[key] = (episode_metrics(log), log, inj, controller)
    return _RESULTS[key][:3]


def _case(fault, mode):
    return pytest.param(fault, mode, id=f"{fault}-{mode}")


def test_registry_names_are_the_public_contract():
    assert list(FAULTS) == [
        "none", "source_raises", "nan_chunk", "garbage_tokens", "splice_offset", "source_silent_0.1s",
        "source_silent_1.5s", "source_silent_3s", "latency_spike_10x", "perception_dropout_50", "perception_frozen",
        "perception_outlier", "perception_nan", "qp_fail_burst", "mpc_late", "missed_ticks_1", "missed_ticks_5",
        "missed_ticks_19", "missed_ticks_20", "start_with_velocity", "unreachable_target", "near_singularity",
        "wire_error_frame", "wire_slow", "wire_bad_shape", "wire_nan", "wire_server_dies"]
    with pytest.raises(ValueError, match="unknown fault"):
        FaultSpec("cosmic_ray")


@pytest.mark.parametrize("fault,mode", [_case(f, m) for f, m in CASES])
def test_fault_survived_without_violations(world, controllers, fault, mode):
    m, log, _ = episode(world, controllers, fault, mode)  # anything raised fails the test
    assert m["limit_violations"] == 0, {k: v for k, v in m.items() if k.endswith(("_violations", "_commands")) and v}
    assert m["nonfinite_commands"] == 0 and np.all(np.isfinite(log.tau_cmd_nm))


def test_missed_ticks_abort_only_at_twenty(world, controllers):
    m20, log20, _ = episode(world, controllers, "missed_ticks_20", "hybrid")
    assert m20["aborts"] == 1 and log20.abort["reason"] == "communication_constraints_violation"
    assert m20["missed_ticks"] == 20 and log20.abort["t_s"] == pytest.approx(ONSET_S + 0.019, abs=1e-6)
    m19, log19, _ = episode(world, controllers, "missed_ticks_19", "hybrid")
    assert m19["aborts"] == 0 and log19.abort is None and m19["missed_ticks"] == 19
    assert len(log19.t_s) == int(round(DURATION_S / 1e-3))


@pytest.mark.parametrize("mode", ["hybrid", "open_loop"])
@pytest.mark.parametrize("fault,reason", [("source_raises", "source_raised"), ("nan_chunk", "source_raised"),
                                          ("garbage_tokens", "bad_tokens"), ("splice_offset", "splice"),
                                          ("wire_error_frame", "source_raised"), ("wire_slow", "source_raised"),
                                          ("wire_bad_shape", "source_raised"), ("wire_nan", "source_raised"),
                                          ("wire_server_dies", "source_raised")])
def test_bad_chunks_are_rejected(world, controllers, fault, reason, mode):
    base, _, _ = episode(world, controllers, "none", mode)
    m, _, _ = episode(world, controllers, fault, mode)
    assert m["rejected_chunks"] > base["rejected_chunks"]
    assert m["rejections"].get(reason, 0) >= 1, m["rejections"]


def test_silence_and_late_chunks_trigger_the_watchdog(world, controllers):
    for mode in ("hybrid", "open_loop"):
        assert episode(world, controllers, "source_silent_3s", mode)[0]["watchdog_stops"] >= 1
        assert episode(world, controllers, "none", mode)[0]["watchdog_stops"] == 0
    late, _, _ = episode(world, controllers, "latency_spike_10x", "hybrid")
    assert late["rejections"].get("stale", 0) + late["watchdog_stops"] >= 1


@pytest.mark.parametrize("fault,gate", [("perception_frozen", "frozen"), ("perception_outlier", "outlier"),
                                        ("perception_nan", "nonfinite")])
def test_perception_faults_are_gated_in_hybrid(world, controllers, fault, gate):
    base, _, _ = episode(world, controllers, "none", "hybrid")
    m, _, _ = episode(world, controllers, fault, "hybrid")
    assert m["gated_measurements"] > base["gated_measurements"]
    assert m["gated"].get(gate, 0) >= 1, m["gated"]


def test_controller_faults_take_the_real_fallbacks(world, controllers):
    m, _, _ = episode(world, controllers, "qp_fail_burst", "hybrid")
    assert m["qp_failures"] >= 50
    late, _, inj = episode(world, controllers, "mpc_late", "hybrid")
    assert inj.applicable and late["mpc_failures"] >= 20  # 0.5 s of 50 Hz MPC solves
    # the patches are gone after the episode
    assert "solve" not in vars(_RESULTS[("qp_fail_burst", "hybrid")][3].qp)
    assert "solve" not in vars(_RESULTS[("mpc_late", "hybrid")][3].mpc)
    with inject(FaultSpec("mpc_late", t_fault_s=ONSET_S), world, make_expert(), controllers("open_loop")) as inj:
        assert not inj.applicable


def test_moved_targets_are_what_everyone_sees(world, controllers):
    m, log, _ = episode(world, controllers, "unreachable_target", "hybrid")
    after = log.t_s >= ONSET_S
    assert np.allclose(log.target_pos_m[after], UNREACHABLE_POS_M)
    assert np.allclose(log.objects_pos_m[after, log.target_index], UNREACHABLE_POS_M)
    assert not np.allclose(log.target_pos_m[~after][-1], UNREACHABLE_POS_M)
    assert np.isnan(recovery_time_s(log, ONSET_S))
    _, blog, _ = episode(world, controllers, "none", "hybrid")
    assert recovery_time_s(blog, ONSET_S) >= 0.0
    _, slog, _ = episode(world, controllers, "start_with_velocity", "hybrid")
    assert np.abs(slog.dq_rad_s[0]).max() == pytest.approx(0.6)


def test_wrappers_delegate_and_spoil_only_the_window(world):
    expert = make_expert()
    src = FaultySource(expert, "silent", (1.0, 2.0))
    assert src.needs_image is False and src.chunk_dt_s == expert.chunk_dt_s
    assert src.action_token_range == expert.action_token_range and src.config is expert.config
    assert callable(src.plan_inpaint)
    w = FaultyPerception(world, "nan", (0.0, 10.0))
    w.reset(3)
    assert w.instruction == world.instruction and w.n_objects == 2
    z = [w.measure_target() for _ in range(35)]
    assert all(np.isnan(z[i - 1]).all() for i in (5, 10, 35)) and all(np.isposinf(z[i - 1]).all() for i in (7, 14))
    frozen = FaultyPerception(world, "frozen", (0.005, 10.0))
    frozen.reset(3)
    first = None
    while first is None:
        first = frozen.measure_target()
    for _ in range(5):  # now in the window
        frozen.step(np.zeros(7), 0.08)
    assert all(np.array_equal(frozen.measure_target(), first) for _ in range(3))


def _one_line_error(argv, name):
    proc = subprocess.run([sys.executable, "-m", "scenarios.faults", *argv, "--quiet"], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 2, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, proc.stderr
    assert "error" in lines[0] and name in lines[0] and "Traceback" not in proc.stderr


def test_cli_unknown_fault_is_one_line():
    _one_line_error(["--faults", "none", "cosmic_ray"], "cosmic_ray")


def test_cli_zero_seeds_is_one_line():
    _one_line_error(["--seeds", "0"], "--seeds")


def test_cli_writes_csv_report_summary_and_plot(tmp_path):
    out = tmp_path / "faults"
    rc = main(["--faults", "none", "missed_ticks_20", "mpc_late", "--modes", "open_loop", "hybrid", "--sources",
               "expert", "--seeds", "1", "--duration-s", "1.5", "--onset-s", "0.5", "--out", str(out), "--quiet"])
    assert rc == 0
    rows = list(csv.DictReader((out / "faults.csv").open()))
    assert len(rows) == 6
    for col in ("fault", "mode", "source", "seed", "success", "final_error_m", "limit_violations",
                "torque_rate_violations", "accel_violations", "jerk_violations", "nonfinite_commands",
                "position_violations", "velocity_violations", "torque_violations", "tcp_speed_violations",
                "torque_rate_max_nm_s", "rejected_chunks", "watchdog_stops", "gated_measurements", "missed_ticks",
                "aborts", "abort_reason", "abort_t_s", "qp_failures", "mpc_failures", "raised", "recovery_s"):
        assert col in rows[0]
    assert all(r["raised"] == "" for r in rows)
    aborted = [r for r in rows if r["fault"] == "missed_ticks_20"]
    assert all(r["abort_reason"] == "communication_constraints_violation" for r in aborted)
    report = (out / "report.md").read_text()
    assert "| mpc_late | n/a |" in report and "fault_torque.png" in report and "## Totals" in report
    summary = json.loads((out / "summary.json").read_text())
    assert summary["totals"]["exceptions"] == 0 and summary["totals"]["unexpected_aborts"] == 0
    assert (out / "fault_torque.png").stat().st_size > 10_000
