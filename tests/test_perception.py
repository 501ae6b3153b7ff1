"""Perception in the loop: the oracle sensor's rate and latency, latency-aware fusion in an episode, the CLI."""

from __future__ import annotations

import numpy as np
import pytest

from mmact_ctrl.perception import Measurement, OracleSensor


class _Truth:
    """A world stand-in with a target moving at 0.2 m/s along x (what measure_target returns, noise-free)."""

    def __init__(self) -> None:
        self.t = 0.0

    def measure_target(self):
        return np.array([0.5 + 0.2 * self.t, 0.0, 0.3])


def test_oracle_sensor_rate_and_latency():
    world = _Truth()
    sensor = OracleSensor(world, rate_hz=100.0, latency_ms=50.0, dt_s=0.001)
    sensor.reset(0)
    arrived = []
    for k in range(1000):
        world.t = k * 0.001
        for m in sensor.poll(world.t):
            arrived.append((world.t, m))
    assert len(arrived) == 95  # 100 captures in 1 s, the last 5 still in flight
    for t_now, m in arrived:
        assert m.t_arrival_s == pytest.approx(m.t_capture_s + 0.05) and t_now == pytest.approx(m.t_arrival_s, abs=1e-9)
        assert m.pos_m[0] == pytest.approx(0.5 + 0.2 * m.t_capture_s)  # the scene at capture time


class _Naive(OracleSensor):
    """A latency the filter is not told about: each measurement is stamped with its arrival time."""

    def poll(self, t_s):
        return [Measurement(m.t_arrival_s, m.t_arrival_s, m.pos_m) for m in super().poll(t_s)]


def test_latency_compensation_in_the_loop_beats_treating_late_measurements_as_current():
    """Linear target, expert, hybrid, 100 ms sensor latency: fused at capture time and predicted to now, the
    tracking error stays below that of a filter that takes each late measurement for a current one."""
    from mmact_ctrl.config import StackConfig
    from mmact_ctrl.controller import HybridController
    from mmact_ctrl.loop import run_episode
    from mmact_ctrl.metrics import episode_metrics
    from scenarios.world.factory import make_expert, make_world

    world = make_world("linear", 0.2, n_objects=1)
    errors = {}
    for name, sensor in (("none", OracleSensor(world, 100.0, 0.0, 0.001)), ("compensated", OracleSensor(world, 100.0, 100.0, 0.001)),
                         ("naive", _Naive(world, 100.0, 100.0, 0.001))):
        ctrl = HybridController(StackConfig(duration_s=4.0))
        errors[name] = []
        for seed in (0, 1, 2, 3):
            log = run_episode(world, make_expert(), ctrl, seed, sensor=sensor)
            assert episode_metrics(log)["success"]
            err = np.linalg.norm(log.ee_pos_m - log.target_pos_m, axis=1)
            errors[name].append(float(err[2000:].mean()))  # tracking, after the approach
    world.close()
    mean = {k: float(np.mean(v)) for k, v in errors.items()}
    assert mean["none"] < 0.012, mean
    assert mean["compensated"] < mean["none"] + 0.012, mean
    # measured: none 6.1, compensated 14.1, naive 18.2 mm (cv): the constant-velocity extrapolation over the
    # latency costs noise, the naive filter a lag
    assert mean["compensated"] < 0.85 * mean["naive"], mean


@pytest.mark.parametrize("bad", [["--perception-hz", "0"], ["--perception-latency-ms", "-5"],
                                 ["--perception", "camera", "--cameras", "wrist"], ["--filter", "ukf"]])
def test_cli_rejects_bad_perception_values_in_one_line(bad, capsys):
    from scenarios.moving_target import main

    with pytest.raises(SystemExit) as exc:
        main(["--source", "expert", "--episodes", "1", "--duration-s", "0.5", "--quiet", *bad])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and (bad[-1] in err[0] or bad[0] in err[0]), err


def test_sweep_has_a_perception_axis():
    from scenarios.sweep import Study, default_grid, run_cell

    study = Study("perception", ("hybrid",), (1.0,), (200.0,), ("linear",), (0.2,), (2048,), (0,), ("oracle", "camera"))
    cells = study.cells()
    assert [c["perception"] for c in cells] == ["oracle", "camera"]
    rows = [run_cell(c, 1.5) for c in cells]
    assert [r["perception"] for r in rows] == ["oracle", "camera"]
    assert rows[1]["sensor_ms_per_sim_s"] > 10 * rows[0]["sensor_ms_per_sim_s"]  # the camera really rendered
    assert all(r["limit_violations"] == 0 for r in rows)
    assert any(s.name == "perception" for s in default_grid())
    with pytest.raises(ValueError, match="perception"):
        Study("x", ("hybrid",), (1.0,), (0.0,), ("linear",), (0.2,), (0,), (0,), ("lidar",))
