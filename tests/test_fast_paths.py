"""The fast paths of the 1 kHz loop (compiled kernels, the vectorized MPC preview) against their references."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from controllers.mpc import MPCPlan
from controllers.qp_id import QPConfig, TaskReference, TaskSpaceQP
from controllers.robot_model import PandaModel
from controllers.mpc.double_integrator import rollout
from controllers.tick_kernels import accel_bounds, assemble_qp, log3, sample_plan_blend, sample_plan_task


@pytest.fixture(scope="module")
def model():
    return PandaModel()


def _rot(rng, angle=None):
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    theta = rng.uniform(0, np.pi) if angle is None else angle
    return np.asarray(pin.exp3(axis * theta))


@pytest.mark.parametrize("angle", [None, 0.0, 1e-7, 1e-5, 2e-4, np.pi - 1e-2, np.pi - 1e-4, np.pi - 1e-7])
def test_log3_matches_pinocchio(angle):
    rng = np.random.default_rng(0)
    out = np.empty(3)
    for _ in range(50):
        R = _rot(rng, angle)
        log3(R, out)
        ref = np.asarray(pin.log3(R))
        # near pi the axis sign is defined only up to the skew part's tiny signal: compare rotations there
        if angle is not None and angle > np.pi - 1e-3:
            np.testing.assert_allclose(np.asarray(pin.exp3(out)), R, atol=1e-6)
            assert abs(np.linalg.norm(out) - np.linalg.norm(ref)) < 1e-6
        else:
            np.testing.assert_allclose(out, ref, atol=1e-9)


def test_accel_bounds_match_numpy_reference_including_outside_the_viable_set():
    qp = TaskSpaceQP(QPConfig())
    b = qp.default_limits.viability.bounds
    rng = np.random.default_rng(1)
    lb, ub = np.empty(7), np.empty(7)
    crossed = 0
    for k in range(500):
        q = rng.uniform(b.q_lo - 0.1, b.q_hi + 0.1)  # some states beyond the margined limits
        dq = rng.normal(0, 1.5, 7)
        # half the draws with an unlimited jerk (the one-step bounds), half with a torque-rate-limited one
        j_eff = np.full(7, np.inf) if k % 2 else rng.uniform(100.0, 10000.0, 7)
        accel_bounds(q, dq, b.q_hi, b.q_lo, b.v_max, b.a_max, b.dt_s, b.inv_h, j_eff, lb, ub)
        ref_lb, ref_ub = b(q, dq, None if k % 2 else j_eff)
        np.testing.assert_allclose(lb, ref_lb, rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(ub, ref_ub, rtol=1e-12, atol=1e-9)
        crossed += int(np.any(ref_lb == ref_ub))
    assert crossed > 0  # the braking branch was exercised


def test_assembled_qp_equals_the_dense_problem(model):
    qp = TaskSpaceQP(QPConfig())
    rng = np.random.default_rng(2)
    for _ in range(50):
        q = model.home_q_rad + rng.normal(0, 0.3, 7)
        dq = rng.normal(0, 0.5, 7)
        terms = model.terms(q, dq)
        # a last torque near the bias torque and a last commanded acceleration: the rate and jerk boxes bind
        qp.reset(terms.h + rng.normal(0, 3.0, 7), rng.normal(0, 8.0, 7))
        ref = TaskReference(terms.pos_m + rng.normal(0, 0.05, 3), rng.normal(0, 0.2, 3), rng.normal(0, 1, 3),
                            _rot(rng) @ terms.rot if rng.random() < 0.5 else terms.rot, rng.normal(0, 0.3, 3),
                            rng.normal(0, 1, 3), model.home_q_rad + rng.normal(0, 0.1, 7))
        _assert_kernel_equals_problem(qp, terms, q, dq, ref, ref.acc_m_s2)


def _assert_kernel_equals_problem(qp, terms, q, dq, ref, acc) -> None:
    """``assemble_qp`` (the position rows' desired acceleration given as ``acc``, as ``TaskSpaceQP._solve_fast``
    passes it) equals ``qp.problem``, the QP summed from the task objects in numpy."""
    P, g, A, lower, upper = qp.problem(terms, q, dq, ref)
    P_x, g_k, A_x, lo_k, up_k = np.empty(28), np.empty(7), np.empty(56), np.empty(14), np.empty(14)
    assemble_qp(terms.M, terms.h, terms.J, terms.dJv, terms.pos_m, terms.rot, terms.vel, ref.pos_m, ref.vel_m_s,
                acc, ref.rot, ref.ang_vel_rad_s, ref.ang_acc_rad_s2, ref.q_post_rad, q, dq,
                qp.tau_last, qp.last_ddq, qp._params, P_x, g_k, A_x, lo_k, up_k)
    upper_triangle = P.ravel(order="F")[np.flatnonzero(np.triu(np.ones((7, 7))).ravel(order="F"))]
    np.testing.assert_allclose(P_x, upper_triangle, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(g_k, g, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(A_x.reshape(7, 8)[:, :7].T, A[:7], rtol=1e-12)
    np.testing.assert_array_equal(A_x.reshape(7, 8)[:, 7], np.ones(7))
    np.testing.assert_allclose(lo_k, lower, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(up_k, upper, rtol=1e-12, atol=1e-9)


def test_compliance_qp_runs_the_fast_path_and_equals_the_dense_problem(model):
    """``--compliance``'s QP (the impedance task in place of the stiff position task) is assembled by the kernels:
    the impedance's desired acceleration (``impedance_acc``) on the position rows equals the task objects summed in
    numpy, with the force cap binding in some states and not in others; its solve keeps the torque rate."""
    from dataclasses import replace

    from controllers.qp.impedance import ImpedanceTask
    from controllers.qp.state import QPState
    from controllers.tick_kernels import impedance_acc

    config = QPConfig()
    task = ImpedanceTask(force_max_n=20.0)
    qp = TaskSpaceQP(replace(config, tcp=replace(config.tcp, w_pos=0.0)), extra_tasks=(task,))
    assert qp.fast_path and qp.impedance is task
    assert not TaskSpaceQP(config, extra_tasks=(task,)).fast_path  # the stiff task weighed too: the general path
    rng = np.random.default_rng(7)
    k, d = task.gains()
    capped = 0
    for _ in range(60):
        q = model.home_q_rad + rng.normal(0, 0.3, 7)
        dq = rng.normal(0, 0.5, 7)
        terms = model.terms(q, dq)
        qp.reset(terms.h + rng.normal(0, 3.0, 7), rng.normal(0, 8.0, 7))
        ref = TaskReference(terms.pos_m + rng.normal(0, 0.01, 3), rng.normal(0, 0.1, 3), rng.normal(0, 2, 3),
                            terms.rot, rng.normal(0, 0.3, 3), rng.normal(0, 1, 3), model.home_q_rad)
        state = QPState(terms, q, dq, ref, qp.tau_last, qp.last_ddq)
        acc = np.empty(3)
        impedance_acc(terms.M, terms.J, terms.pos_m, terms.rot, terms.vel, ref.pos_m, ref.vel_m_s, ref.acc_m_s2, k, d,
                      task.force_max_n, np.zeros(3), acc)
        np.testing.assert_allclose(acc, task.desired_acc(state), rtol=1e-9, atol=1e-9)
        capped += int(np.linalg.norm(task.force_n(state)) >= task.force_max_n - 1e-9)
        _assert_kernel_equals_problem(qp, terms, q, dq, ref, acc)
        tau_was = qp.tau_last.copy()
        tau = qp.solve(terms, q, dq, ref)  # the fast path solves it within the torque rows (the robot's condition)
        assert np.all(np.isfinite(tau)) and np.all(np.abs(tau - tau_was) <= qp.dtau_hard_nm + 1e-12)
    assert 0 < capped < 60  # the cap bound in some states and not in others


def test_the_pressing_only_impedance_kernel_equals_the_task_and_caps_only_the_push_into_the_contact(model):
    """``ImpedanceTask(pressing_only=True)`` (pick's ``--compliance``): with a measured contact normal the kernel's
    desired acceleration equals the task object's; the force's push into the contact (``-f . n``) is never over the
    cap, the rest of it (along the contact, away from it) is the uncapped force's; without a normal the kernel caps
    the magnitude, as the plain task does."""
    from controllers.qp.impedance import ImpedanceTask
    from controllers.qp.state import QPState
    from controllers.tick_kernels import impedance_acc

    task, plain = ImpedanceTask(force_max_n=20.0, pressing_only=True), ImpedanceTask(force_max_n=20.0)
    rng = np.random.default_rng(11)
    k, d = task.gains()
    pressed = free = 0
    for _ in range(80):
        q = model.home_q_rad + rng.normal(0, 0.3, 7)
        dq = rng.normal(0, 0.5, 7)
        terms = model.terms(q, dq)
        ref = TaskReference(terms.pos_m + rng.normal(0, 0.05, 3), rng.normal(0, 0.2, 3), rng.normal(0, 2, 3),
                            terms.rot, np.zeros(3), np.zeros(3), model.home_q_rad)
        n = rng.normal(0, 1, 3)
        n /= np.linalg.norm(n)
        state = QPState(terms, q, dq, ref, terms.h, np.zeros(7), n)
        acc = np.empty(3)
        impedance_acc(terms.M, terms.J, terms.pos_m, terms.rot, terms.vel, ref.pos_m, ref.vel_m_s, ref.acc_m_s2, k, d,
                      task.force_max_n, n, acc)
        np.testing.assert_allclose(acc, task.desired_acc(state), rtol=1e-9, atol=1e-9)
        f = task.force_n(state)
        lam_inv = terms.J[:3] @ np.linalg.solve(terms.M, terms.J[:3].T)
        raw = np.linalg.solve(lam_inv, ref.acc_m_s2) + task.spring_damper_n(state)
        assert -f @ n <= task.force_max_n + 1e-9
        np.testing.assert_allclose(f - (f @ n) * n, raw - (raw @ n) * n, atol=1e-9)  # along the contact: as asked
        pressed += int(-raw @ n > task.force_max_n)
        free += int(np.linalg.norm(f) > task.force_max_n + 1.0)  # more than the magnitude cap would have allowed
        impedance_acc(terms.M, terms.J, terms.pos_m, terms.rot, terms.vel, ref.pos_m, ref.vel_m_s, ref.acc_m_s2, k, d,
                      task.force_max_n, np.zeros(3), acc)
        np.testing.assert_allclose(acc, plain.desired_acc(state), rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(acc, task.desired_acc(state._replace(contact_normal=None)), rtol=1e-9, atol=1e-9)
    assert 0 < pressed < 80 and free > 0


def _random_plan(rng, t0_s, n=20, dt=0.02):
    ddq = rng.normal(0, 2, (n, 7))
    q, dq = np.zeros((n + 1, 7)), np.zeros((n + 1, 7))
    q[0], dq[0] = rng.normal(0, 0.5, 7), rng.normal(0, 0.3, 7)
    for k in range(n):
        q[k + 1] = q[k] + dq[k] * dt + 0.5 * ddq[k] * dt * dt
        dq[k + 1] = dq[k] + ddq[k] * dt
    return MPCPlan(t0_s, dt, q, dq, ddq, rng.normal(0.4, 0.1, (n + 1, 3)), True, 0.0, rng.normal(0, 0.5, (3, 7)))


def test_plan_sample_kernel_matches_mpc_plan():
    rng = np.random.default_rng(3)
    plan = _random_plan(rng, 1.0)
    q_out, task = np.empty(7), np.empty((3, 3))
    for t in np.concatenate([[0.9, 1.0, 1.4, 1.5], rng.uniform(0.95, 1.5, 40)]):
        sample_plan_task(t, plan.t0_s, plan.dt_s, plan.q_rad, plan.dq_rad_s, plan.ddq_rad_s2, plan.ee_pos_m[0],
                         plan.ee_jacobian_lin, q_out, task)
        np.testing.assert_allclose(q_out, plan.sample(t)[0], atol=1e-12)
        for row, ref in zip(task, plan.sample_task(t)):
            np.testing.assert_allclose(row, ref, atol=1e-12)


def test_plan_blend_kernel_equals_the_numpy_hand_over_bit_for_bit():
    """The hand-over (PlanTracker._sample) was two samples and a smoothstep in numpy; the kernel gives the same bits."""
    rng = np.random.default_rng(5)
    old, new, blend_s = _random_plan(rng, 0.98), _random_plan(rng, 1.0), 0.02
    for t, blend_from in [(t, 1.0) for t in np.concatenate([[1.0, 1.005, 1.0199999], rng.uniform(1.0, 1.02, 60)])] + \
            [(t, 1.02) for t in rng.uniform(1.02, 1.04, 20)]:  # a plan taken a period after it was asked for
        q_new, task_new, q_old, task_old = np.empty(7), np.empty((3, 3)), np.empty(7), np.empty((3, 3))
        for plan, qo, to in ((new, q_new, task_new), (old, q_old, task_old)):
            sample_plan_task(t, plan.t0_s, plan.dt_s, plan.q_rad, plan.dq_rad_s, plan.ddq_rad_s2, plan.ee_pos_m[0],
                             plan.ee_jacobian_lin, qo, to)
        x = (t - blend_from) / blend_s
        w = x * x * (3.0 - 2.0 * x)
        q_ref, task_ref = q_old + w * (q_new - q_old), task_old + w * (task_new - task_old)
        q_out, task_out = np.empty(7), np.empty((3, 3))
        sample_plan_blend(t, new.t0_s, new.dt_s, new.q_rad, new.dq_rad_s, new.ddq_rad_s2, new.ee_pos_m[0],
                          new.ee_jacobian_lin, old.t0_s, old.dt_s, old.q_rad, old.dq_rad_s, old.ddq_rad_s2,
                          old.ee_pos_m[0], old.ee_jacobian_lin, blend_from, blend_s, q_out, task_out)
        assert np.array_equal(q_out, q_ref) and np.array_equal(task_out, task_ref), t


def test_compiled_rollout_equals_the_numpy_rows_bit_for_bit():
    rng = np.random.default_rng(6)
    for n in (0, 1, 20):
        q0, dq0, ddq, dt = rng.normal(size=7), rng.normal(size=7), rng.normal(0, 10, (n, 7)), float(rng.uniform(0.001, 0.05))
        q_ref, dq_ref = np.empty((n + 1, 7)), np.empty((n + 1, 7))
        q_ref[0], dq_ref[0] = q0, dq0
        for k in range(n):
            dq_ref[k + 1] = dq_ref[k] + dt * ddq[k]
            q_ref[k + 1] = q_ref[k] + dt * dq_ref[k] + 0.5 * dt * dt * ddq[k]
        q, dq = rollout(q0, dq0, ddq, dt)
        assert np.array_equal(q, q_ref) and np.array_equal(dq, dq_ref)


@pytest.mark.parametrize("tail", ["resting", "leading"])
@pytest.mark.parametrize("rule", ["warp", "snap", "displacement", "none"])
def test_vectorized_preview_equals_pointwise_reference(rule, tail):
    from controllers.retarget import RetargetConfig
    from mmact_ctrl.chunk import ActionChunk
    from mmact_ctrl.config import StackConfig
    from mmact_ctrl.controller import HybridController

    ctrl = HybridController(StackConfig(retarget=RetargetConfig(rule=rule), use_mpc=False))
    ctrl.reset(ctrl.model.home_q_rad)
    rng = np.random.default_rng(4)
    for k in range(30):  # a target moving at 0.2 m/s, measured at 100 Hz
        ctrl.perceive(0.01 * k, np.array([0.5 + 0.002 * k, 0.1, 0.2]) + rng.normal(0, 0.001, 3))
    times = 0.29 + np.linspace(-0.5, 2.5, 61)  # before, inside and after the chunk
    np.testing.assert_allclose(ctrl.reference_positions(times), np.array([ctrl.reference(t)[0] for t in times]))
    wp = np.zeros((16, 7))
    if tail == "resting":  # min-jerk to rest at the aim: the rule's resting-chunk form
        s = np.linspace(0.0, 1.0, 16)
        s = s**3 * (10 - 15 * s + 6 * s**2)
        wp[:, :3] = np.array([0.3, 0.0, 0.5]) + s[:, None] * np.array([0.22, 0.12, -0.29])
    else:  # a constant-velocity tail that passes the target's course: a leading chunk
        wp[:, :3] = np.linspace([0.4, 0.05, 0.3], [0.56, 0.12, 0.2], 16)
    ctrl.activate(ActionChunk(waypoints=wp, dt_s=0.1, t0_s=0.1), 0.3, ctrl.target_estimate(0.29))
    preview = ctrl.reference_positions(times)
    np.testing.assert_allclose(preview, np.array([ctrl.reference(t)[0] for t in times]), atol=1e-12)
    # the retargeting branch was exercised for warp / snap / displacement
    assert (rule == "none") != bool(np.any(ctrl.executor.offset(1.0, ctrl.active)[0]))


def test_linear_motion_fast_path_equals_numpy_fold():
    from scenarios.world.targets import LinearMotion, _fold

    rng = np.random.default_rng(5)
    for _ in range(100):
        lo = rng.uniform(-1, 0, 3)
        hi = lo + rng.uniform(0.1, 1, 3)
        start, vel = rng.uniform(lo, hi), rng.normal(0, 0.3, 3)
        motion = LinearMotion(start, vel, lo, hi)
        for t in rng.uniform(0, 60, 10):
            p = motion.pos_m(t)
            np.testing.assert_allclose(p, _fold(start + vel * t, lo, hi), atol=1e-12)
            assert np.all(p >= lo - 1e-12) and np.all(p <= hi + 1e-12)
