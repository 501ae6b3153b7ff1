"""Shared test setup."""

import os
import sys

from scenarios.blas import pin_blas_kernel

# before numpy is loaded (torch loads it): the golden record's bits depend on OpenBLAS's kernel (scenarios.blas)
assert "numpy" not in sys.modules, "numpy was imported before tests/conftest.py could pin OpenBLAS's kernel"
pin_blas_kernel(os.environ)

import pytest  # noqa: E402
import torch  # noqa: E402


@pytest.fixture(scope="module")
def make_test_world():
    """A factory of the main job's worlds (``scenarios.world.factory.make_world``), closed when the module is done: a
    test file's ``world`` fixture is one line over it."""
    from scenarios.world.factory import make_world

    made = []

    def make(target: str = "linear", speed_m_s: float = 0.2, **kw):
        w = make_world(target, speed_m_s, **kw)
        made.append(w)
        return w

    yield make
    for w in made:
        w.close()


@pytest.fixture(autouse=True, scope="session")
def _one_torch_thread():
    """One intra-op thread: on a shared 2-core machine oversubscription makes small torch ops ~30x slower."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


def _first_query_aims(source, seeds, per_query=None):
    """A shipped checkpoint's first query on real rendered static scenes (one per seed, the checkpoint's own scene):
    each chunk is checked valid (token range, finite, inside the action tokenizer's bounds), ``per_query(source, obs,
    chunk, world)`` adds a checkpoint's own checks. Returns the arrays (start, end, other), m: the arm's start, the
    chunk's last waypoint and the other ball, each against the instructed ball."""
    import numpy as np

    from mmact_ctrl.chunk import Observation
    from scenarios.world.factory import make_world, policy_scene

    world = make_world("static", **policy_scene(source))
    lo, hi = source.action_token_range
    tok = source.policy.action_tokenizer
    start, end, other = [], [], []
    try:
        for seed in seeds:
            world.reset(seed)
            obs = Observation(t0_s=0.0, q_rad=world.state().q_rad, dq_rad_s=np.zeros(7),
                              ee_pos_m=world.home_tcp_pos_m(), ee_rotvec_rad=np.zeros(3), gripper_m=0.08,
                              target_pos_m=world.target_pos_m(), image=world.render(), instruction=world.instruction)
            chunk = source.plan(obs)
            assert chunk.tokens.shape == (16, 7) and chunk.tokens.min() >= lo and chunk.tokens.max() < hi
            assert np.all(np.isfinite(chunk.waypoints))
            assert np.all((chunk.waypoints >= tok.low) & (chunk.waypoints <= tok.high))
            if per_query is not None:
                per_query(source, obs, chunk, world)
            aim = chunk.waypoints[-1, :3]
            start.append(np.linalg.norm(world.home_tcp_pos_m() - world.target_pos_m()))
            end.append(np.linalg.norm(aim - world.target_pos_m()))
            other.append(np.linalg.norm(aim - world.objects_pos_m()[1 - world.target_index]))
    finally:
        world.close()
    return np.array(start), np.array(end), np.array(other)


@pytest.fixture
def first_query_aims():
    """:func:`_first_query_aims`: the shared loop of the shipped checkpoints' aim tests."""
    return _first_query_aims


def _one_line_exit_2(code, stderr: str, *needles: str) -> None:
    """A command's answer to bad input: exit status 2 and one line on stderr (no traceback) that names each of
    ``needles``."""
    assert code == 2, stderr
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, stderr
    assert "Traceback" not in stderr
    for n in needles:
        assert n in lines[0], lines[0]


@pytest.fixture
def one_line_exit_2():
    """:func:`_one_line_exit_2`: the shared check of the command lines' one-line errors."""
    return _one_line_exit_2
