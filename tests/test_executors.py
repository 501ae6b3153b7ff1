"""Chunk executors: one protocol, one class per file; the loop and the controller know no mode names."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from mmact_ctrl.config import MODES, StackConfig
from mmact_ctrl.controller import HybridController
from mmact_ctrl.executors import EXECUTORS, ChunkExecutor, ClockedExecutor, Layers, make_executor
from mmact_ctrl.loop import run_episode
from mmact_ctrl.metrics import episode_metrics
from scenarios.world.factory import make_expert, make_world

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def world(make_test_world):
    return make_test_world("linear", 0.2)


def _strings(path: Path) -> set[str]:
    """Every string literal in a module (docstrings excluded)."""
    tree = ast.parse(path.read_text())
    docs = {id(n.body[0].value) for n in ast.walk(tree)
            if isinstance(n, (ast.Module, ast.FunctionDef, ast.ClassDef, ast.AsyncFunctionDef)) and n.body
            and isinstance(n.body[0], ast.Expr) and isinstance(n.body[0].value, ast.Constant)}
    return {n.value for n in ast.walk(tree) if isinstance(n, ast.Constant) and isinstance(n.value, str) and id(n) not in docs}


@pytest.mark.parametrize("module", ["mmact_ctrl/loop.py", "mmact_ctrl/runner.py", "mmact_ctrl/controller.py"])
def test_loop_and_controller_name_no_mode(module):
    named = _strings(ROOT / module) & set(EXECUTORS)
    assert not named, f"{module} branches on mode names {named}"


def test_every_builtin_executor_satisfies_the_protocol():
    assert tuple(EXECUTORS) == MODES
    for name in MODES:
        ex = make_executor(name)
        assert isinstance(ex, ChunkExecutor) and ex.name == name
    with pytest.raises(ValueError, match="unknown mode 'warp'"):
        make_executor("warp")


@pytest.mark.parametrize("mode", MODES)
def test_each_executor_runs_a_short_episode(world, mode):
    cfg = StackConfig(mode=mode, duration_s=2.5, replan_hz=2.0, latency_ms=100.0)
    ctrl = HybridController(cfg)
    log = run_episode(world, make_expert(lead="velocity", world=world), ctrl, seed=3)
    m = episode_metrics(log)
    assert ctrl.mode == mode
    assert len(log.chunk_active_s) >= 3
    assert m["limit_violations"] == 0 and m["aborts"] == 0
    assert m["final_error_m"] < 0.25  # every mode gets to the target's neighbourhood in 2.5 s
    assert 0.5 <= m["d_measured"] <= 2.0  # 100 ms latency = one 0.1 s waypoint (a few ms of tick rounding)


class RaisedExecutor(ClockedExecutor):
    """A fix registered from a test file: the open-loop reference, 3 cm higher."""

    name = "raised"
    layers = Layers()

    def offset(self, t_s, ref):
        return np.array([0.0, 0.0, 0.03]), np.zeros(3)


def test_an_executor_from_a_test_file_runs_without_touching_the_loop():
    w = make_world(target="static")
    cfg = StackConfig(mode="open_loop", duration_s=3.0)
    base = run_episode(w, make_expert(), HybridController(cfg), seed=1)
    ctrl = HybridController(cfg, executor=make_executor("raised", {"raised": RaisedExecutor}))
    raised = run_episode(w, make_expert(), ctrl, seed=1)
    assert ctrl.mode == "raised"
    dz = raised.ee_pos_m[-1, 2] - base.ee_pos_m[-1, 2]
    assert abs(dz - 0.03) < 0.005, dz
    np.testing.assert_allclose(raised.ee_pos_m[-1, :2], base.ee_pos_m[-1, :2], atol=0.005)


def test_receding_paces_queries_by_execution(world):
    cfg = StackConfig(mode="receding", duration_s=3.0, receding_k=5, latency_ms=100.0)
    log = run_episode(world, make_expert(), HybridController(cfg), seed=0)
    gaps = np.diff(log.chunk_active_s)
    # query when 5 waypoints (0.5 s) have run, then 0.1 s of latency: a new chunk every 0.6 s
    np.testing.assert_allclose(gaps, 0.6, atol=2e-3)


class DashExecutor(ClockedExecutor):
    """A correction that dashes 0.5 m sideways at 2 m/s (faster than a Panda's TCP may go), then stays there."""

    name = "dash"

    def offset(self, t_s, ref):
        if t_s < 1.5:
            return np.zeros(3), np.zeros(3)
        if t_s < 1.75:
            return np.array([0.0, 2.0 * (t_s - 1.5), 0.0]), np.array([0.0, 2.0, 0.0])
        return np.array([0.0, 0.5, 0.0]), np.zeros(3)


@pytest.mark.parametrize("cap_m_s,ok", [(1.4, True), (1e9, False)])
def test_the_qp_keeps_the_tcp_under_its_speed_limit_whatever_the_executor_asks(cap_m_s, ok):
    """With the QP's velocity-target cap (default 1.4 m/s) the dash is followed within 1.7 m/s; without it the
    same command breaks the limit (so the test can fail)."""
    from controllers.qp_id import QPConfig, TcpGains

    w = make_world(target="static")
    cfg = StackConfig(mode="open_loop", duration_s=2.5, qp=QPConfig(tcp=TcpGains(tcp_vel_cap_m_s=cap_m_s)))
    log = run_episode(w, make_expert(), HybridController(cfg, executor=DashExecutor()), seed=2)
    m = episode_metrics(log)
    speed = np.linalg.norm(np.diff(log.ee_pos_m, axis=0), axis=1) / 1e-3
    if ok:
        assert m["limit_violations"] == 0, {k: v for k, v in m.items() if k.endswith("violations") and v}
        assert 1.0 < speed.max() < 1.7  # it does move fast, within the limit
    else:
        assert m["tcp_speed_violations"] > 0


def test_a_late_chunk_planned_from_the_robots_state_is_not_refused_as_a_splice():
    """800 ms of inference delay: each chunk becomes active far along its own path, but it begins where the TCP
    was when it was observed: it is executed (the QP catches up within its bounds), not refused."""
    w = make_world(target="static")
    cfg = StackConfig(mode="open_loop", duration_s=4.0, latency_ms=800.0, replan_hz=1.25)
    log = run_episode(w, make_expert(), HybridController(cfg), seed=0)
    m = episode_metrics(log)
    assert log.rejections.get("splice", 0) == 0 and len(log.chunk_active_s) >= 3
    assert m["limit_violations"] == 0 and m["success"]
