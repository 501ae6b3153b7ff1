"""Commands a real Panda accepts: the rate-limited QP in MuJoCo, the chunk intake, the watchdog, the gates."""

from __future__ import annotations

import numpy as np
import pytest

from controllers.qp_id import TaskReference, TaskSpaceQP
from controllers.safety import CommandLimits, SafetyMonitor
from controllers.stop import StopTrajectory
from controllers.target_estimator import EstimatorConfig, TargetEstimator
from mmact_ctrl.chunk import ActionChunk, Observation
from mmact_ctrl.chunk_intake import ChunkIntake
from mmact_ctrl.config import StackConfig
from mmact_ctrl.controller import HybridController
from mmact_ctrl.reference import ChunkReference
from scenarios.world.panda_scene import SceneConfig
from scenarios.world.sim_world import SimWorld
from scenarios.world.targets import TargetSpec


def test_rate_limited_qp_tracks_a_10cm_step_without_any_violation():
    """A 10 cm step of the TCP reference (the worst a chunk switch asks): the QP ramps the torque at < 1 N m per
    tick, keeps every other condition, and the TCP is within 5 mm of the new reference within 0.6 s."""
    world = SimWorld(SceneConfig(), TargetSpec(kind="static"), noise_m=0.0)
    controller = HybridController(StackConfig())
    qp = TaskSpaceQP()
    state = world.reset(0)
    start, rot = controller.model.fk(state.q_rad)
    qp.reset(controller.model.terms(state.q_rad, state.dq_rad_s).h)
    monitor = SafetyMonitor(CommandLimits())
    monitor.reset(qp.tau_last)
    goal = start + np.array([0.0, 0.1, 0.0])
    errors, steps = [], []
    for _ in range(1500):
        st = world.state()
        ref = TaskReference(goal, np.zeros(3), np.zeros(3), rot, np.zeros(3), np.zeros(3), controller.q_post)
        terms = controller.model.terms(st.q_rad, st.dq_rad_s)
        tau_before = qp.tau_last.copy()
        tau = qp.solve(terms, st.q_rad, st.dq_rad_s, ref)
        assert monitor.check(tau, st.q_rad, st.dq_rad_s, qp.last_ddq, terms.vel[:3]) == 0, monitor.counts
        steps.append(np.abs(tau - tau_before).max())
        world.step(tau, 0.08)
        errors.append(np.linalg.norm(world.state().ee_pos_m - goal))
    world.close()
    errors = np.asarray(errors)
    assert qp.failures == 0 and monitor.violations == 0
    assert max(steps) < 1.0, f"largest torque step {max(steps):.3f} N m in 1 ms"
    assert max(steps) > 0.9  # the rate limit was reached: the test exercised it
    reached = int(np.argmax(errors < 0.005))
    assert errors[reached] < 0.005 and reached * 1e-3 < 0.6, f"within 5 mm after {reached} ms"
    assert errors[reached:].max() < 0.008  # and it stays there (no limit cycle from the rate constraint)


def _obs(t0=1.0):
    return Observation(t0_s=t0, q_rad=np.zeros(7), dq_rad_s=np.zeros(7), ee_pos_m=np.zeros(3), ee_rotvec_rad=np.zeros(3),
                       gripper_m=0.08, target_pos_m=np.zeros(3))


def _chunk(t0=1.0, offset=0.0, tokens=None):
    wp = np.zeros((16, 7))
    wp[:, :3] = np.linspace([0.5, 0.0, 0.3], [0.6, 0.0, 0.3], 16) + offset
    return ActionChunk(waypoints=wp, dt_s=0.1, t0_s=t0, tokens=tokens)


def test_chunk_intake_rejects_each_kind_of_bad_chunk_and_counts_it():
    intake = ChunkIntake(splice_radius_m=0.1, token_range=(100, 100 + 2048))
    obs = _obs()

    def raises():
        raise RuntimeError("policy server crashed")

    def nan_chunk():
        wp = np.full((16, 7), np.nan)
        return ActionChunk(waypoints=wp, dt_s=0.1, t0_s=1.0)  # the constructor refuses it: the source raises

    good_tokens = np.full((16, 7), 150, dtype=np.int64)
    cases = {
        "source_raised": raises,
        "not_a_chunk": lambda: "garbage",
        "bad_time": lambda: _chunk(t0=0.5),
        "bad_tokens": lambda: _chunk(tokens=np.full((16, 7), 10**9, dtype=np.int64)),
    }
    for reason, call in cases.items():
        assert intake.request(call, obs) is None
        assert intake.rejections[reason] == 1, reason
    assert intake.request(nan_chunk, obs) is None and intake.rejections["source_raised"] == 2
    assert intake.request(lambda: _chunk(tokens=good_tokens.astype(float)), obs) is None
    assert intake.rejections["bad_tokens"] == 2  # float tokens: the wrong kind
    assert intake.request(lambda: None, obs) is None and intake.silent_calls == 1 and intake.rejected == 6
    ok = intake.request(lambda: _chunk(tokens=good_tokens), obs)
    assert ok is not None and intake.rejected == 6

    # when due: stale, out of order, spliced too far
    running = ChunkReference(chunk=_chunk(t0=1.0), t_active_s=1.2, target_at_obs_m=None)
    ref_pos = running.sample(1.3)[0][:3]
    intake.submit(1.3, _chunk(t0=1.1), None)
    intake.submit(1.3, _chunk(t0=1.1, offset=0.25), None)
    intake.submit(1.3, _chunk(t0=0.9), None)
    due = intake.due(1.3)
    assert len(due) == 3 and not intake.pending
    verdicts = [intake.admit(e, 1.3, running, ref_pos) for e in due]
    assert verdicts == [True, False, False]
    assert intake.rejections["splice"] == 1 and intake.rejections["out_of_order"] == 1
    intake.submit(3.5, _chunk(t0=1.2), None)  # a latency spike: it ends (2.8 s) before it is due
    assert not intake.admit(intake.due(3.5)[0], 3.5, running, ref_pos)
    assert intake.rejections["stale"] == 1


def test_intake_queue_is_ordered_by_activation_time_not_arrival():
    intake = ChunkIntake(splice_radius_m=0.1)
    intake.submit(3.0, _chunk(t0=1.0), None)  # a late one, submitted first
    intake.submit(2.2, _chunk(t0=2.0), None)
    assert [e.t_active_s for e in intake.due(2.5)] == [2.2]
    assert [e.t_active_s for e in intake.due(3.0)] == [3.0]


def test_watchdog_stop_brakes_within_the_smoother_limits_and_holds():
    cfg = StackConfig(mode="open_loop")
    sc = cfg.smoother
    action = np.array([0.5, 0.0, 0.3, 0.0, 0.0, 0.0, 0.08])
    rate = np.array([0.4, -0.3, 0.1, 0.3, 0.0, 0.0, 0.0])
    stop = StopTrajectory(2.0, action, rate, sc.a_max_m_s2, sc.j_max_m_s3, sc.dw_max_rad_s2, sc.ddw_max_rad_s3)
    ts = np.arange(2.0, 2.0 + stop.duration_s + 0.2, 1e-3)
    vel = np.array([stop.sample(t)[1][:3] for t in ts])
    acc = np.diff(vel, axis=0) / 1e-3
    np.testing.assert_allclose(vel[0], rate[:3], atol=1e-9)
    assert np.abs(acc).max() <= sc.a_max_m_s2 * (1 + 1e-6)
    assert np.abs(np.diff(acc, axis=0) / 1e-3).max() <= sc.j_max_m_s3 * 1.01
    assert np.all(vel[-100:] == 0) and np.allclose(stop.sample(ts[-1])[0], stop.rest_action)
    assert 0.0 < stop.duration_s < 1.0

    ctrl = HybridController(cfg)
    ctrl.reset(ctrl.model.home_q_rad)
    ctrl.activate(_chunk(t0=0.0), 0.2, None)
    assert ctrl.covered(1.0) and not ctrl.covered(1.7)
    assert ctrl.watchdog(1.7) and not ctrl.watchdog(1.8) and ctrl.watchdog_stops == 1
    pos, vel, *_ = ctrl.reference(5.0)
    assert np.allclose(vel, 0) and np.allclose(pos, _chunk().waypoints[-1, :3])  # it had stopped: holds there
    ctrl.activate(_chunk(t0=5.0), 5.2, None)
    assert ctrl.stop is None


def test_the_estimator_gates_nonfinite_frozen_and_outlier_measurements_and_still_follows_a_jump():
    kf = TargetEstimator(EstimatorConfig())
    rng = np.random.default_rng(0)
    truth = np.array([0.5, 0.1, 0.2])
    for k in range(50):
        kf.step(0.01 * k, truth + rng.normal(0, 0.002, 3))
    before = kf.pos_m
    signalling = np.array([0x7FF0000000000001], dtype=np.uint64).view(np.float64)[0]
    for bad in (np.array([np.nan, 0, 0]), np.array([signalling, 0, 0]), np.array([0, np.inf, 0]), np.zeros(2), "x"):
        assert kf.step(0.5, bad) == "nonfinite"
    assert kf.gated_nonfinite == 5
    z = truth + rng.normal(0, 0.002, 3)
    assert kf.step(0.51, z) == "fused"
    assert kf.step(0.52, z.copy()) == "frozen" and kf.step(0.53, z.copy()) == "frozen"
    for k in range(10):  # the gated steps only predicted: let the belief settle again
        kf.step(0.54 + 0.01 * k, truth + rng.normal(0, 0.002, 3))
    # scattered 10-sigma outliers (25 mm: 10 x the innovation's 2.5 mm; every 5th measurement) never move it
    for k in range(20):
        t = 0.64 + 0.05 * k
        direction = rng.normal(size=3)
        assert kf.step(t, truth + 0.025 * direction / np.linalg.norm(direction)) == "outlier"
        for i in range(1, 5):
            kf.step(t + 0.01 * i, truth + rng.normal(0, 0.002, 3))
    assert np.linalg.norm(kf.pos_m - before) < 0.003 and kf.resets == 0
    # a real jump: consistent measurements at a new place re-initialise it
    new = truth + np.array([0.15, 0, 0])
    statuses = [kf.step(1.7 + 0.01 * k, new + rng.normal(0, 0.002, 3)) for k in range(5)]
    assert "reset" in statuses and np.linalg.norm(kf.pos_m - new) < 0.005


@pytest.mark.parametrize("bad", [["--chunk-timeout-s", "-1"], ["--splice-radius-m", "0"]])
def test_cli_rejects_bad_safety_switches_in_one_line(bad, capsys):
    from scenarios.moving_target import main

    with pytest.raises(SystemExit) as exc:
        main(["--source", "expert", *bad])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and bad[0] in err[0]


def test_an_observation_that_already_saw_a_jump_is_not_shifted_by_it_twice():
    """A chunk observed on the tick of the jump's first measurement (the filter still believes the old place)
    gets the post-jump estimate at activation; one observed before the jump keeps the old one."""
    kf = TargetEstimator(EstimatorConfig())
    rng = np.random.default_rng(1)
    old, new = np.array([0.5, 0.0, 0.3]), np.array([0.5, 0.15, 0.3])
    for k in range(100):
        kf.step(0.01 * k, old + rng.normal(0, 0.002, 3))
    recorded_before, recorded_at = kf.pos_m, None
    for k in range(100, 103):
        kf.step(0.01 * k, new + rng.normal(0, 0.002, 3))
        if k == 100:
            recorded_at = kf.pos_m  # the observation of t = 1.00 s: the gate held the jump back
    assert kf.resets == 1 and np.linalg.norm(recorded_at - old) < 0.005
    assert np.linalg.norm(kf.estimate_at_observation(1.0, recorded_at) - new) < 0.006
    np.testing.assert_array_equal(kf.estimate_at_observation(0.98, recorded_before), recorded_before)
    assert kf.estimate_at_observation(1.0, None) is None


def test_the_safety_table_uses_the_one_wilson_interval():
    # the interval itself is tested against published values in tests/test_stats.py; here only that the safety
    # table reports with that one (no copy of its own)
    from mmact_ctrl.stats import wilson_interval
    from scenarios.safety_table import wilson_interval as table_wilson

    assert table_wilson is wilson_interval
