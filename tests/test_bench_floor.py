"""The floor benchmark times the work the tick does: the replayed QPs are the ones the episode solved (their solutions
match), the replayed steps follow the episode's torques, and the report's ratios are the figures it prints. Nothing
here is timed against a threshold."""

from __future__ import annotations

import numpy as np
import pytest

from mmact_ctrl.bench_floor import floor_report, format_floor
from mmact_ctrl.config import StackConfig
from mmact_ctrl.controller import HybridController
from scenarios.bench_floor import record_main_job


@pytest.fixture(scope="module")
def recording():
    return record_main_job("--source expert", episodes=1, seed=3, duration_s=0.6)


def test_the_replayed_qps_are_the_ones_the_episode_solved(recording):
    solver = HybridController(StackConfig()).qp.bare_solver()
    ext = solver._solver
    P_x, g, A_x, lo, up = recording.qp_data
    assert len(g) > 500 and g.shape[1] == 7
    worst = 0.0
    for i in range(len(g)):
        ext.update_data_vec(q=g[i], l=lo[i], u=up[i])
        ext.update_data_mat(P_x=P_x[i], P_i=None, A_x=A_x[i], A_i=None)
        ext.solve()
        worst = max(worst, float(np.max(np.abs(np.array(ext.solution.x) - recording.ddq_rad_s2[i]))))
    assert worst < 1e-6, worst  # the same problems in the same order from the same start: the same solutions


def test_the_replayed_steps_follow_the_episodes_torques(recording):
    assert recording.mj_step_s.shape == (len(recording.tau_nm),)
    assert np.all(recording.mj_step_s > 0)
    assert recording.tau_nm.shape == recording.q_rad.shape == recording.dq_rad_s.shape


def test_the_report_holds_the_tick_against_the_sum_of_the_bare_calls(recording):
    r = floor_report(recording)
    floor = sum(r["calls"][k]["median_us"] for k in ("pinocchio", "osqp", "safety"))
    assert r["command_floor_us"] == pytest.approx(floor)
    assert r["episode_floor_us"] == pytest.approx(floor + r["calls"]["mj_step"]["median_us"])
    assert r["tick_median_over_floor"] == pytest.approx(r["tick"]["median_us"] / floor)
    per_tick = r["command_floor_per_tick"]  # summed tick by tick: never under the cheapest tick's calls
    assert per_tick["n"] == len(recording.q_rad) and per_tick["p99_us"] >= per_tick["median_us"] > 0
    assert r["tick_p99_over_floor_p99"] == pytest.approx(r["tick"]["p99_us"] / per_tick["p99_us"])
    text = format_floor(r)
    assert "tick median / floor" in text and "real-time factor" in text
