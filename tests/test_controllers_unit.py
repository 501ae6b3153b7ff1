"""Control layers without the simulator: QP vs independent solvers, Ruckig limits, Kalman filter, retargeting."""

import numpy as np
import pytest
import qpsolvers

from controllers.qp_id import TaskReference, TaskSpaceQP
from controllers.retarget import RetargetConfig, progress, progresses, retarget_offset, trusted
from controllers.robot_description import JointLimits
from controllers.robot_model import PandaModel
from controllers.smoother import SmootherConfig, TaskSpaceSmoother
from controllers.target_estimator import EstimatorConfig, TargetEstimator


@pytest.fixture(scope="module")
def model():
    return PandaModel()


def _random_reference(rng, model, q):
    pos, rot = model.fk(q)
    return TaskReference(
        pos_m=pos + rng.normal(0, 0.05, 3),
        vel_m_s=rng.normal(0, 0.2, 3),
        acc_m_s2=rng.normal(0, 1.0, 3),
        rot=rot,
        ang_vel_rad_s=rng.normal(0, 0.2, 3),
        ang_acc_rad_s2=np.zeros(3),
        q_post_rad=model.home_q_rad,
    )


@pytest.mark.parametrize("other", ["clarabel", "daqp"])
def test_qp_matches_independent_solver_on_random_instances(model, other):
    if other not in qpsolvers.available_solvers:
        pytest.skip(f"{other} not installed")
    rng = np.random.default_rng(1)
    lim = JointLimits().arrays()
    qp = TaskSpaceQP()
    worst = 0.0
    for _ in range(25):
        q = rng.uniform(lim["q_min_rad"] + 0.2, lim["q_max_rad"] - 0.2)
        dq = rng.uniform(-0.5, 0.5, 7) * lim["v_max_rad_s"]
        terms = model.terms(q, dq)
        ref = _random_reference(rng, model, q)
        qp.reset(terms.h)  # an independent instance: the robot holding itself in this state
        P, g, A, lo, up = (x.copy() for x in qp.problem(terms, q, dq, ref))  # before solve updates tau_last
        qp.solve(terms, q, dq, ref)
        assert qp.last_ok
        x = qpsolvers.solve_qp(P, g, G=np.vstack([A, -A]), h=np.concatenate([up, -lo]), solver=other)
        assert x is not None
        cost = lambda v: 0.5 * v @ P @ v + g @ v  # noqa: E731
        # same optimum: equal cost, nearly equal torques
        assert cost(qp.last_ddq) == pytest.approx(cost(x), rel=1e-3, abs=1e-6)
        worst = max(worst, np.abs(terms.M @ (qp.last_ddq - x)).max())
    assert worst < 0.05  # N*m


def test_qp_failure_falls_back_and_counts(model):
    qp = TaskSpaceQP()
    q = model.home_q_rad
    dq = np.zeros(7)
    terms = model.terms(q, dq)
    ref = _random_reference(np.random.default_rng(0), model, q)
    ref = TaskReference(**{**ref.__dict__, "pos_m": np.full(3, np.nan)})
    tau = qp.solve(terms, q, dq, ref)
    assert qp.failures == 1 and not qp.last_ok
    assert np.allclose(tau, np.clip(terms.h, -JointLimits().arrays()["tau_max_nm"], JointLimits().arrays()["tau_max_nm"]))


def test_ruckig_output_respects_its_limits():
    cfg = SmootherConfig(v_max_m_s=0.8, a_max_m_s2=4.0, j_max_m_s3=50.0, relative=False)
    sm = TaskSpaceSmoother(cfg)
    sm.reset(np.zeros(3), np.zeros(3))
    rng = np.random.default_rng(0)
    target = np.zeros(3)
    pos, vel, acc = [], [], []
    for k in range(5000):
        if k % 400 == 0 and k < 3000:  # step changes of the reference, then 2 s to arrive
            target = rng.uniform(-0.4, 0.4, 3)
        p, v, a, *_ = sm.step(target, np.zeros(3), np.zeros(3))
        pos.append(p), vel.append(v), acc.append(a)
    vel, acc = np.array(vel), np.array(acc)
    jerk = np.diff(acc, axis=0) / cfg.dt_s
    assert np.abs(vel).max() <= cfg.v_max_m_s * (1 + 1e-6)
    assert np.abs(acc).max() <= cfg.a_max_m_s2 * (1 + 1e-6)
    assert np.abs(jerk).max() <= cfg.j_max_m_s3 * (1 + 1e-3)
    assert np.linalg.norm(pos[-1] - target) < 1e-4  # it arrives
    assert sm.failures == 0


def test_the_estimator_converges_on_a_linear_target_and_survives_dropout():
    cfg = EstimatorConfig(meas_noise_m=0.003)
    kf = TargetEstimator(cfg)
    rng = np.random.default_rng(0)
    v_true = np.array([0.2, -0.1, 0.05])
    p0 = np.array([0.5, 0.0, 0.3])
    errs = []
    for k in range(300):  # 3 s at 100 Hz, 30 % dropout and a 0.5 s blackout
        t = k * cfg.dt_s
        truth = p0 + v_true * t
        blackout = 1.5 <= t < 2.0
        z = None if (blackout or rng.random() < 0.3) else truth + rng.normal(0, cfg.meas_noise_m, 3)
        kf.step(t, z)
        if kf.initialized:
            errs.append(np.linalg.norm(kf.pos_m - truth))
    assert kf.missed > 50
    assert np.linalg.norm(kf.vel_m_s - v_true) < 0.03
    assert errs[-1] < 0.004
    assert np.linalg.norm(kf.predict_pos(3.5) - (p0 + v_true * 3.5)) < 0.02


@pytest.mark.parametrize("noise_m", [0.002, 0.0])
def test_the_estimator_reinitialises_on_a_jump(noise_m):
    """A jump is followed with a noisy sensor and with a noise-free simulated one (frozen gate off)."""
    kf = TargetEstimator(EstimatorConfig(frozen_gate=noise_m > 0))
    rng = np.random.default_rng(0)
    for k in range(100):
        kf.step(k * 0.01, np.array([0.5, 0.0, 0.3]) + rng.normal(0, noise_m, 3))
    for k in range(100, 105):
        kf.step(k * 0.01, np.array([0.5, 0.15, 0.3]) + rng.normal(0, noise_m, 3))
    assert kf.resets == 1
    assert np.linalg.norm(kf.pos_m - [0.5, 0.15, 0.3]) < 0.005
    assert kf.step(1.1, np.array([np.nan, 0, 0])) == "nonfinite" and kf.gated_nonfinite == 1  # gated, not raised


def test_retarget_rules_and_trust_radius():
    aim = np.array([0.5, 0.0, 0.3])
    at_obs = aim + 0.01
    now = aim + np.array([0.1, 0.0, 0.0])
    vel = np.array([0.2, 0.0, 0.0])
    disp = RetargetConfig("displacement", 0.1)
    off, dv = retarget_offset(disp, 1.0, aim, at_obs, now, vel, 0.5, 2.0)
    assert np.allclose(off, now - at_obs) and np.allclose(dv, vel)
    snap = RetargetConfig("snap", 0.1)
    off0, _ = retarget_offset(snap, 0.5, aim, at_obs, now, vel, 0.5, 2.0)
    off1, _ = retarget_offset(snap, 2.0, aim, at_obs, now, vel, 0.5, 2.0)
    assert np.allclose(off0, now - at_obs)  # at activation: the displacement only
    assert np.allclose(aim + off1, now)  # at the last waypoint: exactly on the filtered target
    # warp: the aim error is weighed by the chunk's progress along its path (start -> aim), not by time
    warp = RetargetConfig("warp", 0.1)
    start = aim - np.array([0.2, 0.0, 0.0])
    w_half = progress(warp, aim, start, aim - np.array([0.1, 0.0, 0.0]), np.array([0.5, 0.0, 0.0]))
    assert np.isclose(w_half[0], 0.5) and np.isclose(w_half[1], 0.5 / 0.2)  # halfway, closing at 0.5 m/s on 0.2 m
    off_w, dv_w = retarget_offset(warp, 0.6, aim, at_obs, now, vel, 0.5, 2.0, w_half)
    assert np.allclose(off_w, now - at_obs + 0.5 * (at_obs - aim)) and np.allclose(dv_w, vel + 2.5 * (at_obs - aim))
    assert progress(warp, aim, start, aim, np.zeros(3)) == (1.0, 0.0)  # at its aim: exactly on the filtered target
    assert progress(warp, aim, start, start - 0.05, np.zeros(3)) == (0.0, 0.0)  # moving away from the aim: clipped
    assert progress(warp, aim, aim + 0.005, aim, np.zeros(3)) is None  # a resting chunk: blended in time as snap
    assert np.allclose(retarget_offset(warp, 2.0, aim, at_obs, now, vel, 0.5, 2.0, None)[0], off1)
    assert np.allclose(progresses(warp, aim, start, np.array([start, aim - [0.05, 0, 0], aim])), [0.0, 0.75, 1.0])
    with pytest.raises(ValueError, match="min_travel_m"):
        RetargetConfig("warp", min_travel_m=0.0)
    assert trusted(disp, aim, at_obs)
    assert not trusted(disp, aim, aim + 0.2)  # not the chunk's target
    assert not trusted(RetargetConfig("none"), aim, at_obs)
    with pytest.raises(ValueError, match="rule"):
        RetargetConfig("teleport")


def test_relative_ruckig_absorbs_reference_jumps_within_limits_and_follows_without_lag():
    cfg = SmootherConfig(a_max_m_s2=6.0, j_max_m_s3=80.0)  # relative (default)
    sm = TaskSpaceSmoother(cfg)
    start = np.array([0.4, 0.0, 0.3])
    sm.reset(start, np.zeros(3))
    vel = np.array([0.2, -0.1, 0.0])
    out_p, out_a = [], []
    for k in range(3000):
        t = k * cfg.dt_s
        ref = start + vel * t + (np.array([0.05, 0.02, -0.03]) if t >= 1.0 else 0.0)  # a chunk switch at 1 s
        p, v, a, *_ = sm.step(ref, vel, np.zeros(3), np.zeros(3))
        out_p.append(p), out_a.append(a)
    p, a = np.array(out_p), np.array(out_a)
    step = np.linalg.norm(np.diff(p, axis=0), axis=1)
    # the 6 cm jump never shows up as a jump: per tick the output moves at most (v_max + |ref vel|) * dt
    assert step.max() <= (cfg.v_max_m_s * np.sqrt(3) + np.linalg.norm(vel)) * cfg.dt_s
    assert np.abs(a).max() <= cfg.a_max_m_s2 * (1 + 1e-6)
    assert np.abs(np.diff(a, axis=0) / cfg.dt_s).max() <= cfg.j_max_m_s3 * (1 + 1e-3)
    final_ref = start + vel * 2.999 + np.array([0.05, 0.02, -0.03])
    assert np.linalg.norm(p[-1] - final_ref) < 1e-6  # no lag behind a moving reference
    assert sm.failures == 0


def test_relative_ruckig_passes_a_curving_reference_through_and_still_absorbs_a_jump():
    """At the MPC's 20 ms step, a circle's centripetal acceleration (2 m/s^2, below a_max) is the reference's own
    motion: it passes through with no offset; a chunk-switch jump is still absorbed and smoothed."""
    cfg = SmootherConfig(dt_s=0.02)
    sm = TaskSpaceSmoother(cfg)
    centre, radius, omega = np.array([0.5, 0.0, 0.3]), 0.08, 5.0  # 0.4 m/s, 2 m/s^2
    circle = lambda t: (centre + radius * np.array([np.cos(omega * t), np.sin(omega * t), 0.0]),
                        radius * omega * np.array([-np.sin(omega * t), np.cos(omega * t), 0.0]))
    sm.reset(circle(0.0)[0], np.zeros(3))
    sm._pos.prev_vel = circle(0.0)[1]  # already moving
    gaps = []
    for k in range(1, 100):
        ref, vel = circle(k * cfg.dt_s)
        p, *_ = sm.step(ref, vel, np.zeros(3))
        gaps.append(np.linalg.norm(p - ref))
    assert max(gaps) < 1e-9  # followed exactly, nothing absorbed
    old = SmootherConfig(dt_s=0.02, pass_through=0.0)  # absorbing every change lags the curve
    sm_old = TaskSpaceSmoother(old)
    sm_old.reset(circle(0.0)[0], np.zeros(3))
    sm_old._pos.prev_vel = circle(0.0)[1]
    lag = [np.linalg.norm(sm_old.step(*circle(k * old.dt_s), np.zeros(3))[0] - circle(k * old.dt_s)[0])
           for k in range(1, 100)]
    assert np.mean(lag[20:]) > 1e-3
    jump = np.array([0.03, 0.0, 0.0])  # a chunk switch on the curve
    ref, vel = circle(100 * cfg.dt_s)
    p, *_ = sm.step(ref + jump, vel, np.zeros(3))
    assert np.linalg.norm(p - ref) < 0.01  # the 3 cm step does not show up at once
    for k in range(101, 150):
        ref, vel = circle(k * cfg.dt_s)
        p, *_ = sm.step(ref + jump, vel, np.zeros(3))
    assert np.linalg.norm(p - (ref + jump)) < 1e-6 and sm.failures == 0
    with pytest.raises(ValueError, match="pass_through"):
        SmootherConfig(pass_through=-1.0)
