"""The loop as an object that can be advanced: stepping it in pieces, or pausing at every query and answering from
outside, gives exactly the episode that one call gives."""

import numpy as np
import pytest

from mmact_ctrl.config import StackConfig
from mmact_ctrl.controller import HybridController
from mmact_ctrl.loop import run_episode
from mmact_ctrl.metrics import episode_metrics
from mmact_ctrl.runner import EpisodeRunner
from scenarios.world.factory import make_expert


@pytest.fixture(scope="module")
def world(make_test_world):
    return make_test_world("reversal", 0.2, n_objects=2)


def _same(a, b):
    for name in ("ee_pos_m", "tau_cmd_nm", "ref_pos_m", "q_rad", "safety_mask"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert a.chunk_active_s == b.chunk_active_s and a.rejections == b.rejections


@pytest.mark.parametrize("mode", ["open_loop", "receding", "hybrid"])
def test_advancing_in_pieces_is_one_call(world, mode):
    expert = make_expert(lead="velocity", world=world)
    cfg = StackConfig(mode=mode, duration_s=2.0, replan_hz=2.0)
    whole = run_episode(world, expert, HybridController(cfg), seed=3)
    runner = EpisodeRunner(world, expert, HybridController(cfg), seed=3)
    for until in (0.0004, 0.25, 0.2501, 1.0, 1.3337):
        runner.advance(until)
        assert runner.t_s >= until - 1e-9 and runner.t_s < until + 1e-3
        assert not runner.done
    runner.advance()
    assert runner.done
    _same(whole, runner.finish())


class _Answered:
    """A source whose answer is set from outside before each call (as the Gymnasium environment's agent does)."""

    needs_image = False

    def __init__(self, inner):
        self.inner, self.next = inner, None
        self.action_token_range = inner.action_token_range

    def plan(self, observation):
        chunk, self.next = self.next, None
        return chunk

    def plan_inpaint(self, observation, known):
        return self.plan(observation)


def test_pausing_at_queries_and_answering_from_outside_gives_the_same_episode(world):
    expert = make_expert(lead="velocity", world=world)
    cfg = StackConfig(mode="hybrid", duration_s=2.5, replan_hz=2.0)
    whole = run_episode(world, expert, HybridController(cfg), seed=5)
    agent = _Answered(expert)
    runner = EpisodeRunner(world, agent, HybridController(cfg), seed=5, pause_at_queries=True)
    queries = []
    while True:
        runner.advance()
        if runner.done:
            break
        obs = runner.pending_query
        assert obs is not None and obs.t0_s == pytest.approx(runner.t_s)
        queries.append(obs.t0_s)
        agent.next = expert.plan(obs)
    assert queries == pytest.approx([0.0, 0.5, 1.0, 1.5, 2.0])
    log = runner.finish()
    _same(whole, log)
    assert episode_metrics(log)["final_error_m"] == episode_metrics(whole)["final_error_m"]


class _Scribbler:
    """A source whose chunks carry notes of every wrong kind in ``info`` (as a foreign server may)."""

    needs_image = False

    def __init__(self, inner):
        self.inner, self.n = inner, 0

    def plan(self, observation):
        import dataclasses

        self.n += 1
        infos = [{"round_trip_ms": None, "server_infer_ms": "fast", "arrival_delay_s": float("nan")},
                 {"policy_infer_ms": float("inf"), "arrival_delay_s": None}, None]
        return dataclasses.replace(self.inner.plan(observation), info=infos[self.n % 3])


def test_malformed_notes_in_a_chunks_info_are_ignored_not_raised(world):
    source = _Scribbler(make_expert(lead="velocity", world=world))
    log = run_episode(world, source, HybridController(StackConfig(mode="hybrid", duration_s=3.0, replan_hz=2.0)), seed=0)
    assert len(log.chunk_active_s) >= 5 and sum(log.rejections.values()) == 0
    assert log.source_timing_ms == {}  # nothing that was not a finite number was kept


def test_an_inpaint_request_that_fails_on_the_sources_own_members_is_a_counted_rejection(world):
    class BadSpacing:
        needs_image = False
        chunk_dt_s = "a tenth of a second"  # the inpainting prefix is sampled at the source's spacing

        def __init__(self, inner):
            self.inner = inner

        def plan(self, obs):
            return self.inner.plan(obs)

        def plan_inpaint(self, obs, known):
            return self.inner.plan_inpaint(obs, known)

    log = run_episode(world, BadSpacing(make_expert(lead="velocity", world=world)),
                      HybridController(StackConfig(mode="inpaint", duration_s=2.5)), seed=0)
    assert log.rejections["source_raised"] >= 2 and len(log.t_s) == 2500  # survived, counted
