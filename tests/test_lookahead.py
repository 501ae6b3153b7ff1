"""Simulated time's look-ahead (``mmact_ctrl.lookahead``): a source that declares its plan pure is called in a worker
thread until its chunk is due, and every result is the one of the call in line, bit for bit: the commands, the
counts of what it refused, the source's own error text, a query still in flight when the episode ends."""

import threading
import time

import numpy as np
import pytest

from controllers.robot_model import PandaModel
from mmact_ctrl.config import StackConfig
from mmact_ctrl.controller import HybridController
from mmact_ctrl.lookahead import can_look_ahead
from mmact_ctrl.runner import EpisodeRunner
from mmact_ctrl.sources.spec import SourceSpec
from scenarios.world.factory import make_expert

SEED = 7
#: queries at 0, 1 and 2 s (1 Hz); the last one's chunk is due at 2.2 s, after the end: in flight when it ends
DURATION_S = 2.1


class PureExpert:
    """The scripted expert, declared pure (its plan reads only the observation); it notes the thread of each call,
    takes 5 ms (so that the ticks really run beside it) and raises at the query of ``raise_at_s``."""

    answers_concurrently = True

    def __init__(self, raise_at_s: float | None = None) -> None:
        self._inner = make_expert(lead="velocity")
        self.raise_at_s = raise_at_s
        self.threads: list[str] = []

    def __getattr__(self, name):
        return getattr(self._inner, name)

    def plan(self, observation):
        self.threads.append(threading.current_thread().name)
        time.sleep(0.005)
        if self.raise_at_s is not None and abs(observation.t0_s - self.raise_at_s) < 1e-6:
            raise RuntimeError(f"planned failure at t={observation.t0_s:.3f} s")
        return self._inner.plan(observation)


class Wrapper:
    """A wrapper that delegates everything, the declaration included: it is not trusted to be pure."""

    def __init__(self, inner) -> None:
        self._inner = inner

    def __getattr__(self, name):
        return getattr(self._inner, name)


@pytest.fixture(scope="module")
def world(make_test_world):
    return make_test_world("reversal", 0.2)


@pytest.fixture(scope="module")
def model():
    return PandaModel()


def _episode(world, model, source, lookahead: bool, mode: str = "hybrid"):
    controller = HybridController(StackConfig(mode=mode, duration_s=DURATION_S), model=model)
    runner = EpisodeRunner(world, source, controller, SEED, lookahead=lookahead)
    ran_ahead = runner.lookahead is not None
    runner.advance()
    return runner.finish(), ran_ahead


@pytest.mark.parametrize("mode", ["hybrid", "open_loop"])
def test_the_answer_taken_ahead_is_the_answer_in_line_bit_for_bit(world, model, mode):
    inline_source, ahead_source = PureExpert(), PureExpert()
    inline, inline_ran_ahead = _episode(world, model, inline_source, lookahead=False, mode=mode)
    ahead, ran_ahead = _episode(world, model, ahead_source, lookahead=True, mode=mode)
    assert ran_ahead and not inline_ran_ahead
    # the calls really ran in the worker (not in line with a flag that changed nothing)
    assert ahead_source.threads and all(n.startswith("chunk-source-ahead") for n in ahead_source.threads)
    assert inline_source.threads == [threading.main_thread().name] * len(inline_source.threads)
    assert len(ahead.plan_ms) == len(inline.plan_ms) == 3  # the last one, in flight at the end, counted too
    np.testing.assert_array_equal(ahead.tau_cmd_nm, inline.tau_cmd_nm)
    np.testing.assert_array_equal(ahead.ee_pos_m, inline.ee_pos_m)
    np.testing.assert_array_equal(ahead.ref_pos_m, inline.ref_pos_m)
    assert ahead.events == inline.events


def test_a_failure_taken_ahead_is_counted_with_its_own_words_as_in_line(world, model):
    inline, _ = _episode(world, model, PureExpert(raise_at_s=1.0), lookahead=False)
    ahead, ran_ahead = _episode(world, model, PureExpert(raise_at_s=1.0), lookahead=True)
    assert ran_ahead
    assert inline.rejections["source_raised"] == 1
    assert ahead.rejections == inline.rejections
    assert ahead.source_errors == inline.source_errors
    assert "planned failure at t=1.000 s" in ahead.source_errors[0]["text"]
    np.testing.assert_array_equal(ahead.tau_cmd_nm, inline.tau_cmd_nm)


def test_only_a_source_that_declares_itself_pure_runs_ahead(world, model):
    assert SourceSpec.of(PureExpert()).answers_concurrently
    assert not SourceSpec.of(make_expert()).answers_concurrently
    assert not SourceSpec.of(Wrapper(PureExpert())).answers_concurrently  # a delegation is not a declaration
    _, ran_ahead = _episode(world, model, Wrapper(PureExpert()), lookahead=True)
    assert not ran_ahead


@pytest.mark.parametrize("change, allowed", [
    ({}, True),
    ({"answers_concurrently": False}, False),
    ({"measured_latency": True}, False),     # the latency is the call's own wall time: it must run in line
    ({"stepped": True}, False),              # an agent answers between advances (the Gymnasium environment)
    ({"prev_frame_gap_s": 0.1}, False),      # an earlier frame would be rendered inside the window
    ({"latency_s": 0.001}, False),           # under two ticks: nothing to overlap
    ({"latency_s": 1.0}, False),             # not shorter than the period: the next query would come first
])
def test_the_rules_of_looking_ahead(change, allowed):
    args = dict(answers_concurrently=True, latency_s=0.2, period_s=1.0, prev_frame_gap_s=0.0, dt_s=0.001,
                measured_latency=False, stepped=False)
    args.update(change)
    assert can_look_ahead(**args) is allowed
