"""Bring your own policy: the action-space adapters, the capability check, the plugin loader and its one-line errors,
and the LeRobot-interface adapter (a small torch module of that interface)."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from controllers.robot_model import PandaModel
from controllers.rotations import rot_from_rotvec, rotvec_from_rot
from mmact_ctrl.chunk import ActionChunk, Observation
from mmact_ctrl.config import StackConfig
from mmact_ctrl.controller import HybridController
from mmact_ctrl.loop import run_episode
from mmact_ctrl.metrics import episode_metrics
from mmact_ctrl.sources import ActionAdapter, ActionSpace, SourceError, capabilities, require_capabilities
from mmact_ctrl.sources.action_space import GRIPPERS, gripper_values, gripper_width_m
from mmact_ctrl.sources.lerobot import LeRobotSource
from mmact_ctrl.sources.loader import load_source, parse_source_args
from scenarios.world.factory import make_expert, make_world
from scenarios.moving_target import main

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def model():
    return PandaModel()


@pytest.fixture(scope="module")
def world(make_test_world):
    return make_test_world("static", 0.0, n_objects=1)


def _observation(model, q):
    pos, rot = model.fk(q)
    _, rot_nom = model.fk(model.home_q_rad)
    return Observation(t0_s=0.0, q_rad=q, dq_rad_s=np.zeros(7), ee_pos_m=pos, ee_rotvec_rad=rotvec_from_rot(rot, rot_nom),
                       gripper_m=0.08, target_pos_m=np.array([0.5, 0.0, 0.2]))


def _random_q(rng, model):
    return model.home_q_rad + rng.uniform(-0.4, 0.4, 7)


def test_joint_positions_through_forward_kinematics_equal_the_tcp_mujoco_reports(model, world):
    world.reset(0)
    rng = np.random.default_rng(1)
    qs = np.array([_random_q(rng, model) for _ in range(6)])
    adapter = ActionAdapter(ActionSpace("joint_pos", gripper="none"), model)
    obs = _observation(model, model.home_q_rad)
    chunk = adapter.to_chunk(qs, obs)
    for q, w in zip(qs, chunk.waypoints):
        mj_pos = world.set_arm_state(q).ee_pos_m  # the TCP site of the simulated arm
        assert np.linalg.norm(w[:3] - mj_pos) < 1e-6
        assert w[6] == pytest.approx(0.08)  # no gripper value: open
    # joint deltas from the observation land on the same poses
    q0 = qs[0]
    deltas = adapter_delta = ActionAdapter(ActionSpace("joint_delta", gripper="none"), model)
    chunk_d = adapter_delta.to_chunk(qs - q0, _observation(model, q0))
    assert np.allclose(chunk_d.waypoints, chunk.waypoints, atol=1e-9)
    # accumulated deltas too
    steps = np.diff(np.vstack([q0, qs]), axis=0)
    chunk_p = ActionAdapter(ActionSpace("joint_delta", gripper="none", delta_from="previous"), model).to_chunk(
        steps, _observation(model, q0))
    assert np.allclose(chunk_p.waypoints, chunk.waypoints, atol=1e-9)
    assert deltas is adapter_delta


def test_tcp_deltas_and_world_rotations_give_the_known_poses(model):
    rng = np.random.default_rng(2)
    q = _random_q(rng, model)
    obs = _observation(model, q)
    _, rot_nom = model.fk(model.home_q_rad)
    d = np.array([[0.01, -0.02, 0.03, 0.0, 0.0, 0.1], [0.02, 0.0, -0.01, 0.1, 0.0, 0.0]])
    chunk = ActionAdapter(ActionSpace("tcp_delta", gripper="none"), model).to_chunk(d, obs)
    assert np.allclose(chunk.waypoints[:, :3], obs.ee_pos_m + d[:, :3])
    rot0 = rot_from_rotvec(obs.ee_rotvec_rad, rot_nom)
    for i in range(2):
        want = rot_from_rotvec(d[i, 3:], np.eye(3)) @ rot0
        assert np.allclose(rot_from_rotvec(chunk.waypoints[i, 3:6], rot_nom), want, atol=1e-9)
    acc = ActionAdapter(ActionSpace("tcp_delta", gripper="none", delta_from="previous"), model).to_chunk(d, obs)
    assert np.allclose(acc.waypoints[1, :3], obs.ee_pos_m + d[0, :3] + d[1, :3])
    # an absolute world-frame orientation (LIBERO's axis-angle) is turned into ours
    pos, rot = model.fk(q)
    world_rotvec = rotvec_from_rot(rot, np.eye(3))
    a = np.concatenate([pos, world_rotvec])[None]
    c = ActionAdapter(ActionSpace("tcp_pose", gripper="none", rotation="world"), model).to_chunk(a, obs)
    assert np.allclose(c.waypoints[0, :6], np.concatenate([obs.ee_pos_m, obs.ee_rotvec_rad]), atol=1e-9)


@pytest.mark.parametrize("convention", [g for g in GRIPPERS if g != "none"])
def test_gripper_conventions_round_trip(convention):
    width = np.array([0.0, 0.02, 0.08])
    assert np.allclose(gripper_width_m(gripper_values(width, convention), convention), width)


def test_closed_and_open_mean_what_each_convention_says():
    assert gripper_width_m(np.array([1.0]), "close_1")[0] == 0.0
    assert gripper_width_m(np.array([1.0]), "open_1")[0] == pytest.approx(0.08)
    assert gripper_width_m(np.array([-1.0]), "sign")[0] == pytest.approx(0.08)


def test_actions_that_do_not_fit_the_space_name_the_shape_and_the_bad_value(model):
    obs = _observation(model, model.home_q_rad)
    adapter = ActionAdapter(ActionSpace("joint_pos", gripper="open_1"), model)
    with pytest.raises(ValueError, match=r"\(10, 7\).*joint_pos.*\(H >= 1, 8\)"):
        adapter.to_chunk(np.zeros((10, 7)), obs)
    bad = np.tile(np.r_[model.home_q_rad, 1.0], (5, 1))
    bad[3, 2] = np.nan
    with pytest.raises(ValueError, match="NaN or inf.*waypoint 3"):
        adapter.to_chunk(bad, obs)
    with pytest.raises(ValueError, match="kind"):
        ActionSpace("joint_velocity")
    with pytest.raises(ValueError, match="dt_s"):
        ActionSpace(dt_s=0.0)


class _PlanOnly:
    needs_image = False

    def __init__(self):
        self.expert = make_expert()

    def plan(self, observation):
        return self.expert.plan(observation)


def test_a_mode_that_needs_inpainting_refuses_a_source_without_it_before_the_episode(world):
    src = _PlanOnly()
    assert capabilities(src) == frozenset() and "inpaint" in capabilities(make_expert())
    with pytest.raises(SourceError, match=r"'_PlanOnly' cannot run --mode inpaint: it lacks inpaint: plan_inpaint"):
        require_capabilities(src, {"inpaint"}, "inpaint")
    controller = HybridController(StackConfig(mode="inpaint", duration_s=0.5))
    with pytest.raises(SourceError, match="inpaint"):
        run_episode(world, src, controller, seed=0)
    # the same source runs every mode that needs nothing of it
    log = run_episode(world, src, HybridController(StackConfig(mode="open_loop", duration_s=0.5)), seed=0)
    assert sum(log.rejections.values()) == 0 and log.chunk_active_s


def _cli(*argv, timeout=180):
    return subprocess.run([sys.executable, "-m", "scenarios.moving_target", *argv, "--quiet"], capture_output=True,
                          text=True, timeout=timeout, cwd=REPO)


def test_inpaint_with_a_source_that_cannot_is_one_line_naming_source_and_mode(tmp_path, one_line_exit_2):
    plugin = tmp_path / "plan_only.py"
    plugin.write_text("from scenarios.world.factory import make_expert\n"
                      "class PlanOnly:\n    needs_image = False\n    def __init__(self):\n        self.e = make_expert()\n"
                      "    def plan(self, obs):\n        return self.e.plan(obs)\n"
                      "def make():\n    return PlanOnly()\n")
    proc = _cli("--source", f"{plugin}:make", "--mode", "inpaint", "--episodes", "1")
    one_line_exit_2(proc.returncode, proc.stderr, "PlanOnly", "--mode inpaint", "plan_inpaint")


BAD_SOURCES = [
    (["--source", "no_such_module_xyz:make"], ["no_such_module_xyz", "cannot import"]),
    (["--source", "examples.byo_source:no_such_factory"], ["no_such_factory", "no attribute"]),
    (["--source", "examples.byo_source:LeadingSource", "--source-arg", "horizon=0"], ["factory raised", "horizon"]),
    (["--source", "examples.byo_source:np"], ["'np' is a module, not a callable"]),
    (["--source", "builtins:object"], ["returned object, which is not a chunk source"]),
    (["--source", "examples/nothing_here.py:make"], ["no file", "nothing_here.py"]),
    (["--source", "examples.byo_source:make_source", "--source-arg", "horizon"], ["--source-arg", "key=value"]),
    (["--source", "examples.byo_source:make_source", "--source-arg", "wings=2"], ["factory raised", "wings"]),
    (["--source", "teleport"], ["--source", "teleport"]),
    (["--source", "expert", "--checkpoint", "/nonexistent.pt"], ["--checkpoint is for --source policy"]),
    (["--source", "expert", "--source-arg", "a=1"], ["--source-arg is for"]),
    (["--speed", "50"], ["--speed", "1.7"]),
    (["--replan-hz", "1000"], ["--replan-hz", "100"]),
    (["--checkpoint", "README.md"], ["README.md"]),
]


@pytest.mark.parametrize("argv,needles", BAD_SOURCES, ids=[" ".join(a)[:40] for a, _ in BAD_SOURCES])
def test_bad_sources_and_meaningless_settings_give_one_line(argv, needles, capsys, one_line_exit_2):
    """Through the command's ``main`` in this process (a process each cost 6 s of imports here; the entry point
    itself is tested by the inpaint case above, in a process of its own)."""
    with pytest.raises(SystemExit) as exc:
        main([*argv, "--episodes", "1", "--duration-s", "0.5", "--quiet"])
    one_line_exit_2(exc.value.code, capsys.readouterr().err, *needles)


def test_a_plugin_source_runs_end_to_end_with_the_same_table_and_json(tmp_path, capsys):
    out = tmp_path / "byo.json"
    rc = main(["--source", "examples/byo_source.py:make_source", "--source-arg", "horizon=20", "--source-arg", "dt_s=0.08",
               "--target", "static", "--mode", "open_loop", "hybrid", "--episodes", "2", "--duration-s", "3", "--quiet",
               "--json", str(out)])
    assert rc == 0
    import json

    payload = json.loads(out.read_text())
    for mode in ("open_loop", "hybrid"):
        s = payload["runs"][mode]["summary"]
        assert s["success_rate"] == 1.0 and s["limit_violations"] == 0 and s["rejected_chunks"] == 0
        assert set(s["round_trip_ms"]) == {"median", "p95", "max"}
    assert "examples/byo_source.py:make_source source" in capsys.readouterr().out


def test_parse_source_args_reads_json_values_and_keeps_strings():
    assert parse_source_args(["h=50", "dt_s=0.05", "on=true", "name=pi0", "xs=[1, 2]"]) == {
        "h": 50, "dt_s": 0.05, "on": True, "name": "pi0", "xs": [1, 2]}


@pytest.mark.parametrize("factory", ["make_joint_source", "make_delta_source"])
def test_a_joint_position_and_a_tcp_delta_source_reach_a_static_target_in_hybrid(world, factory):
    source = load_source(f"examples.action_spaces:{factory}", {})
    controller = HybridController(StackConfig(mode="hybrid", duration_s=3.0))
    for seed in (0, 1):
        m = episode_metrics(run_episode(world, source, controller, seed=seed))
        assert m["success"] and m["limit_violations"] == 0 and m["rejected_chunks"] == 0, m["final_error_m"]


class TinyChunkPolicy(torch.nn.Module):
    """A small module with LeRobot's policy interface: reads one camera and the joint state, answers a chunk of
    absolute joint positions (the observed joints plus a learned-looking offset that is zero here) + gripper."""

    def __init__(self, horizon=10):
        super().__init__()
        self.horizon = horizon
        self.conv = torch.nn.Conv2d(3, 4, 5, stride=4)
        self.head = torch.nn.Linear(4 + 8, 8)
        torch.nn.init.zeros_(self.head.weight)
        torch.nn.init.zeros_(self.head.bias)
        self.resets = 0
        self.batches = []

    def reset(self):
        self.resets += 1

    def predict_action_chunk(self, batch):
        self.batches.append({k: (v.shape, v.dtype, float(v.min()), float(v.max())) if torch.is_tensor(v) else v
                             for k, v in batch.items()})
        img, state = batch["observation.images.front"], batch["observation.state"]
        feat = self.conv(img).mean(dim=(2, 3))
        delta = self.head(torch.cat([feat, state], dim=1))
        hold = torch.cat([state[:, :7], torch.ones(len(state), 1)], dim=1)  # gripper open (open_1)
        return (hold + delta).unsqueeze(1).repeat(1, self.horizon, 1)


def test_the_lerobot_adapter_builds_the_batch_and_runs_a_torch_module_in_the_loop():
    policy = TinyChunkPolicy()
    source = LeRobotSource(policy, ActionSpace("joint_pos", gripper="open_1", dt_s=0.05), cameras={"front": "front"})
    assert source.needs_image and source.camera_names == ("front",) and source.state_dim == 8
    w = make_world("static", 0.0, n_objects=1, cameras=source.camera_names)
    try:
        controller = HybridController(StackConfig(mode="open_loop", duration_s=1.0))
        log = run_episode(w, source, controller, seed=0)
        run_episode(w, source, controller, seed=1)
    finally:
        w.close()
    assert policy.resets == 2  # reset() at the start of every episode
    shape, dtype, lo, hi = policy.batches[0]["observation.images.front"]
    assert tuple(shape) == (1, 3, 96, 96) and dtype == torch.float32 and 0.0 <= lo <= hi <= 1.0 and hi > 0.1
    assert tuple(policy.batches[0]["observation.state"][0]) == (1, 8)
    assert policy.batches[0]["task"] == [log.instruction]
    m = episode_metrics(log)
    assert m["rejected_chunks"] == 0 and m["limit_violations"] == 0 and log.chunk_active_s
    assert np.max(np.linalg.norm(log.ee_pos_m - log.ee_pos_m[0], axis=1)) < 0.01  # it holds the arm where it is


def test_the_lerobot_adapter_refuses_what_is_not_that_interface():
    with pytest.raises(ValueError, match="predict_action_chunk"):
        LeRobotSource(object(), ActionSpace())
    with pytest.raises(ValueError, match="state field"):
        LeRobotSource(TinyChunkPolicy(), ActionSpace(), state_fields=("joint_torques",))


def test_an_adapted_source_that_returns_our_chunk_for_a_foreign_space_is_refused(model):
    class Liar:
        needs_image = False
        action_space = ActionSpace("joint_pos")

        def plan(self, obs):
            return ActionChunk(waypoints=np.zeros((2, 7)), dt_s=0.1, t0_s=obs.t0_s)

    src = load_source.__globals__["wrap_source"](Liar(), "test")
    with pytest.raises(ValueError, match="returned an ActionChunk"):
        src.plan(_observation(model, model.home_q_rad))
