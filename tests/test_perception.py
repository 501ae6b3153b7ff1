"""Perception in the loop: the oracle sensor's rate and latency, latency-aware fusion in an episode, the CLI."""

from __future__ import annotations

import numpy as np
import pytest

from mmact_ctrl.perception import OracleSensor


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


def test_latency_compensation_in_the_loop_keeps_the_hybrid_final_error():
    """Linear target, expert, hybrid: a 100 ms sensor latency, fused at capture time and predicted to now, costs
    little final error against no latency (the filter does not treat a late measurement as a current one)."""
    from mmact_ctrl.config import StackConfig
    from mmact_ctrl.controller import HybridController
    from mmact_ctrl.loop import run_episode
    from mmact_ctrl.metrics import episode_metrics
    from scenarios.factory import make_expert, make_world

    world = make_world("linear", 0.2, n_objects=1)
    errors = {}
    for latency_ms in (0.0, 100.0):
        ctrl = HybridController(StackConfig(duration_s=4.0))
        sensor = OracleSensor(world, 100.0, latency_ms, 0.001)
        errors[latency_ms] = [episode_metrics(run_episode(world, make_expert(), ctrl, seed, sensor=sensor))["final_error_m"]
                              for seed in (0, 1)]
    world.close()
    assert np.mean(errors[0.0]) < 0.012
    assert np.mean(errors[100.0]) < np.mean(errors[0.0]) + 0.005, errors


@pytest.mark.parametrize("bad", [["--perception-hz", "0"], ["--perception-latency-ms", "-5"],
                                 ["--perception", "camera", "--cameras", "wrist"], ["--filter", "ukf"]])
def test_cli_rejects_bad_perception_values_in_one_line(bad, capsys):
    from scenarios.moving_target import main

    with pytest.raises(SystemExit) as exc:
        main(["--source", "expert", "--episodes", "1", "--duration-s", "0.5", "--quiet", *bad])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and (bad[-1] in err[0] or bad[0] in err[0]), err
