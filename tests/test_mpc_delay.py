"""The MPC solved beside the loop in simulated time (``StackConfig.mpc_delay_s``, ``mmact_ctrl.mpc_worker.DeferredMPC``):
with no delay it is the inline MPC bit for bit; with one it is deterministic, takes each plan when due, and survives
a process that dies."""

import dataclasses
import hashlib

import numpy as np
import pytest

from mmact_ctrl.config import StackConfig
from mmact_ctrl.controller import HybridController
from mmact_ctrl.loop import run_episode
from mmact_ctrl.mpc_worker import DeferredMPC, InlineMPC
from scenarios.world.factory import make_expert

DURATION_S = 1.5


@pytest.fixture(scope="module")
def world(make_test_world):
    return make_test_world("reversal", 0.3, n_objects=1)


def _episode(world, delay_s, seed=3):
    """(torque hash, log, solves) of one hybrid episode of the expert with the MPC inline (None) or deferred."""
    cfg = dataclasses.replace(StackConfig(mode="hybrid", duration_s=DURATION_S), mpc_delay_s=delay_s)
    controller = HybridController(cfg)
    try:
        worker = controller.mpc_worker
        assert isinstance(worker, InlineMPC if delay_s is None else DeferredMPC)
        log = run_episode(world, make_expert(lead="velocity"), controller, seed=seed)
        solves = len(worker.solve_us)
    finally:
        controller.close()
    assert isinstance(controller.mpc_worker, InlineMPC)  # closed: its process is gone, the MPC inline again
    return hashlib.sha256(log.tau_cmd_nm.tobytes()).hexdigest(), log, solves


def test_no_delay_is_the_inline_mpc_bit_for_bit_and_a_delay_is_deterministic(world):
    inline, log_inline, n_inline = _episode(world, None)
    beside, _, n_beside = _episode(world, 0.0)
    assert beside == inline and n_beside == n_inline == int(DURATION_S * 50)  # the transport loses nothing
    late_a, log_a, _ = _episode(world, 0.02)
    late_b, _, _ = _episode(world, 0.02)
    assert late_a == late_b  # whatever the load: the plan is taken at a simulated time
    assert late_a != inline  # the plan starts from a state 20 ms old: a different run
    for log in (log_inline, log_a):
        assert not any(log.safety_counts.values()), log.safety_counts
        assert log.mpc_failures == 0
    # before the first plan is due the QP holds the start pose (the bypass), then never again
    assert log_inline.mpc_bypass_ticks == 0 and log_a.mpc_bypass_ticks == 20
    # a plan one period old still tracks: the TCP ends as near the target as inline, within a centimetre
    err = [float(np.linalg.norm(lg.ee_pos_m[-200:] - lg.target_pos_m[-200:], axis=1).mean()) for lg in (log_inline, log_a)]
    assert err[1] < err[0] + 0.01, err


def _problem(controller, t_s):
    """A real MPC problem (``TaskSpaceMPC.solve``'s arguments after the time): from the home posture at rest, the
    TCP asked 5 cm along x over the horizon."""
    model, n = controller.model, controller.config.mpc.horizon_steps
    q = model.home_q_rad
    terms = model.terms(q, np.zeros(7))
    preview = terms.pos_m + np.outer(np.linspace(0.005, 0.05, n), [1.0, 0.0, 0.0])
    return q.copy(), np.zeros(7), terms.pos_m.copy(), terms.J.copy(), preview, np.zeros(3)


def test_a_plan_is_taken_when_due_in_order_and_a_dead_process_is_survived():
    cfg = StackConfig(mode="hybrid", duration_s=1.0)
    controller = HybridController(cfg)
    worker = DeferredMPC(cfg.mpc, controller.model.home_q_rad, delay_s=0.02)
    try:
        worker.submit(0.0, _problem(controller, 0.0))
        worker.submit(0.02, _problem(controller, 0.02))
        assert worker.poll(t_s=0.019) is None  # not due: the loop goes on with the plan it has
        t_asked, plan = worker.poll(t_s=0.02)
        assert t_asked == 0.0 and plan.ok and plan.t0_s == 0.0  # the oldest first
        t_asked, plan = worker.poll(t_s=0.05)
        assert t_asked == 0.02 and len(worker.solve_us) == 2
        assert worker.poll(t_s=1.0) is None  # nothing in flight
        worker._proc.kill()
        worker._proc.join(5.0)
        worker.submit(0.04, _problem(controller, 0.04))  # a fault never escapes: no plan, counted
        assert worker.poll(t_s=0.1) is None and worker.errors >= 1
    finally:
        worker.close()
    with pytest.raises(ValueError, match="delay_s"):
        DeferredMPC(cfg.mpc, controller.model.home_q_rad, delay_s=float("nan"))


@pytest.mark.parametrize("delay_s", [-0.001, 0.021])
def test_a_delay_outside_one_period_is_refused(delay_s):
    with pytest.raises(ValueError, match="mpc_delay_s"):
        StackConfig(mpc_delay_s=delay_s)
