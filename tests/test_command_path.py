"""The command path: with a deadline (real time) only what a tick's command needs runs before it; fusing the
measurements, admitting chunks and the MPC's 50 Hz update run once the command is out. Simulated time keeps its
order (and its results). The QP's rare paths are warm before the first episode."""

import numpy as np
import pytest

from controllers.qp_id import TaskReference, TaskSpaceQP
from controllers.robot_model import PandaModel
from mmact_ctrl.config import StackConfig
from mmact_ctrl.controller import HybridController
from mmact_ctrl.loop import run_episode
from mmact_ctrl.mpc_worker import InlineMPC
from mmact_ctrl.runner import EpisodeRunner
from scenarios.world.factory import make_expert


class OnTime:
    """A deadline that every command meets (the order of real time, without the wall clock)."""

    def missed(self, k: int) -> bool:
        return False


class DeferringMPC(InlineMPC):
    """Solves at once, but, as the MPC process does, asks to be handed its problem after the command; records when
    it was handed one (``inside_tick``: whether the controller's tick was still running)."""

    defer_submit = True

    def __init__(self, mpc, controller) -> None:
        super().__init__(mpc)
        self.controller = controller
        self.handed: list[tuple[float, bool]] = []

    def submit(self, t_s: float, args: tuple) -> None:
        self.handed.append((t_s, self.controller.in_tick))
        super().submit(t_s, args)


def _trace(controller: HybridController, events: list) -> None:
    """Record the order of the controller's ticks and fusions into ``events``."""
    tick, perceive = controller.tick, controller.perceive
    controller.in_tick = False

    def traced_tick(t_s, q, dq):
        controller.in_tick = True
        try:
            events.append(("tick", round(t_s * 1000)))
            return tick(t_s, q, dq)
        finally:
            controller.in_tick = False

    def traced_perceive(t_capture_s, z):
        events.append(("fuse", round(t_capture_s * 1000)))
        return perceive(t_capture_s, z)

    controller.tick, controller.perceive = traced_tick, traced_perceive


@pytest.fixture(scope="module")
def world(make_test_world):
    return make_test_world("linear", 0.2, n_objects=1)


def _episode(world, deadline, duration_s: float = 0.5, seed: int = 3):
    controller = HybridController(StackConfig(mode="hybrid", duration_s=duration_s))
    controller.use_mpc_worker(DeferringMPC(controller.mpc, controller) if deadline is not None
                              else controller.mpc_worker)
    events: list = []
    _trace(controller, events)
    runner = EpisodeRunner(world, make_expert(lead="velocity", world=world), controller, seed, deadline=deadline)
    runner.advance()
    return runner.finish(), controller, events


def test_with_a_deadline_measurements_are_fused_after_the_command(world):
    log, _, events = _episode(world, OnTime())
    fused = [i for i, e in enumerate(events) if e[0] == "fuse"]
    assert len(fused) >= 40  # 100 Hz for 0.5 s, less the lost ones
    for i in fused:
        # the tick of the measurement's time came first: its command did not wait for the filter
        assert events[i - 1][0] in ("tick", "fuse") and any(e == ("tick", events[i][1]) for e in events[:i])
    assert log.abort is None and int(np.count_nonzero(log.safety_mask)) == 0


def test_a_tick_that_asks_the_source_leaves_its_measurements_to_the_next_tick(world):
    """Real time with the source in its worker: the tick that builds an observation defers the fusion of what arrived
    to the next tick's after-command work (the filter fuses each at its capture time); nothing is dropped."""
    from mmact_ctrl.realtime.async_source import AsyncQueries

    controller = HybridController(StackConfig(mode="hybrid", duration_s=1.5))
    controller.use_mpc_worker(DeferringMPC(controller.mpc, controller))
    events: list = []
    _trace(controller, events)
    queries = AsyncQueries()
    submit = queries.submit

    def traced_submit(*args):
        events.append(("ask", max((e[1] for e in events if e[0] == "tick"), default=-1) + 1))  # the tick asking
        return submit(*args)

    queries.submit = traced_submit
    runner = EpisodeRunner(world, make_expert(lead="velocity", world=world), controller, 3, deadline=OnTime(),
                           async_queries=queries)
    try:
        runner.advance()
    finally:
        queries.close()
    log = runner.finish()
    asked = [e[1] for e in events if e[0] == "ask"]
    assert len(asked) >= 2
    deferred = 0
    for k in asked:
        i, j = events.index(("tick", k)), events.index(("tick", k + 1))
        assert not any(e[0] == "fuse" for e in events[i:j])  # nothing fused after the asking tick's command
        deferred += sum(e[0] == "fuse" and e[1] <= k for e in events[j:j + 6])  # fused after the next one's
    assert deferred >= 1  # a query tick had measurements, and they were fused a tick later
    fused = sum(e[0] == "fuse" for e in events)
    assert fused == log.measurements >= 100  # 100 Hz for 1.5 s, none dropped
    assert log.abort is None and int(np.count_nonzero(log.safety_mask)) == 0


def test_without_one_measurements_are_fused_before_the_command(world):
    _, _, events = _episode(world, None)
    fused = [i for i, e in enumerate(events) if e[0] == "fuse"]
    assert fused and all(("tick", events[i][1]) not in events[:i] for i in fused)


def test_with_a_deadline_the_mpc_is_handed_its_problem_after_the_command(world):
    log, controller, _ = _episode(world, OnTime())
    handed = controller.mpc_worker.handed
    assert len(handed) >= 20  # 50 Hz for 0.5 s
    assert not any(inside for _, inside in handed)  # never while the tick computed its command
    times = np.array([t for t, _ in handed])
    assert np.allclose(np.diff(times), 1.0 / controller.config.mpc.rate_hz)  # one per MPC period, from its tick
    assert log.mpc_bypass_ticks <= 10  # a plan drives the QP from the tick after the first update on
    assert np.all(np.isfinite(log.tau_cmd_nm)) and int(np.count_nonzero(log.safety_mask)) == 0


def test_chunks_become_active_on_the_same_ticks_either_way(world):
    sim, _, _ = _episode(world, None, duration_s=1.5)
    rt, _, _ = _episode(world, OnTime(), duration_s=1.5)
    assert len(sim.chunk_active_s) >= 2
    assert np.allclose(sim.chunk_active_s, rt.chunk_active_s)  # admitted after tick k's command, active at k + 1
    # the same episode up to a tick or two of delay in fusion and the MPC's hand-over: the TCP paths stay within 3 mm
    assert float(np.max(np.linalg.norm(sim.ee_pos_m - rt.ee_pos_m, axis=1))) < 3e-3


def test_simulated_time_records_the_work_real_time_does_after_the_command(world):
    controller = HybridController(StackConfig(mode="hybrid", duration_s=0.5))
    log = run_episode(world, make_expert(lead="velocity", world=world), controller, seed=0)
    assert log.after_us.shape == log.tick_us.shape and np.all(log.after_us >= 0)
    every = int(round(1.0 / (controller.config.mpc.rate_hz * controller.config.dt_s)))  # ticks per MPC period
    mpc_ticks = np.arange(0, len(log.t_s), every)  # the default phase is 0: the MPC's ticks are 0, 20, 40, ...
    assert controller.config.mpc_phase_s == 0.0
    assert np.all(log.after_us[mpc_ticks] > 0)  # every MPC update recorded apart from the command path


def test_the_qps_warm_up_leaves_no_trace():
    model = PandaModel()
    q = model.home_q_rad + 0.1
    dq = np.full(7, 0.2)
    terms = model.terms(q, dq)
    pos, rot = np.array(terms.pos_m), np.array(terms.rot)
    ref = TaskReference(pos + 0.03, np.zeros(3), np.zeros(3), rot, np.zeros(3), np.zeros(3), model.home_q_rad)
    warm, cold = TaskSpaceQP(), TaskSpaceQP()
    warm.warm_up(terms, q, dq, ref)
    assert warm.tau_last is None and warm.solves == warm.rescues == warm.failures == 0
    for qp in (warm, cold):
        qp.reset(np.array(terms.h))
    for _ in range(5):
        assert np.array_equal(warm.solve(terms, q, dq, ref), cold.solve(terms, q, dq, ref))
