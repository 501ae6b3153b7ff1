"""``python -m scenarios.collect --format lerobot`` in the simulator: the layout an independent checker accepts
(lerobot-doctor, run here, never skipped), the round trip of every rendered frame, the replay of the recorded
actions through ``--source lerobot:DIR``, any task, and the one-line refusals."""

import json
import shutil
import subprocess
import sys

import numpy as np
import pytest

from mmact_ctrl.datasets.reader import LeRobotDataset
from scenarios.collect import main as collect_main
from scenarios.lerobot_replay import replay

COMMON = ["--format", "lerobot", "--episodes", "2", "--duration-s", "2.5", "--image-size-px", "32", "--quiet"]


def _collect(tmp_path, name, *extra):
    out = tmp_path / name
    assert collect_main([*COMMON, "--out", str(out), *extra]) == 0
    return out


@pytest.fixture(scope="module")
def reach(tmp_path_factory):
    return _collect(tmp_path_factory.mktemp("reach"), "ds", "--target", "linear", "--seed", "11", "--verify")


def test_the_export_round_trips_every_frame(reach):
    meta = json.loads((reach / "meta/mmact.json").read_text())
    rt = meta["figures"]["round_trip"]
    assert rt["ok"] and rt["frames"] == 2 * 2 * 25 and rt["frames_missing"] == 0
    assert rt["psnr_min_db"] >= 35.0 and rt["timestamp_error_max_s"] <= 1e-4
    assert rt["timestamps_exact"] and rt["index_contiguous"]
    ds = LeRobotDataset.open(reach)
    assert ds.info["total_frames"] == 50 and ds.camera_keys == ("observation.images.front", "observation.images.side")
    state, action = ds.values(0, "observation.state"), ds.values(0, "action")
    assert state.shape == (25, 8) and action.shape == (25, 7)
    assert np.all(np.abs(state[:, 7] - 0.08) < 0.002)  # reach keeps the gripper open
    assert meta["episodes"][0]["seed"] == 11 and meta["episodes"][1]["seed"] == 12


def test_lerobot_doctor_finds_no_fail(reach, tmp_path):
    exe = shutil.which("lerobot-doctor")
    assert exe is not None, "lerobot-doctor is part of the dev set-up (pip install -e '.[dev]'): the peer checker"
    run = subprocess.run([exe, "check", str(reach), "--ci", "--fail-on", "fail", "--json"],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    text = run.stdout
    summary = json.loads(text[text.index("{"): text.rindex("}") + 1])["summary"]
    assert summary["FAIL"] == 0 and summary["PASS"] >= 7


def test_the_recorded_actions_replay_to_the_same_result(reach):
    out = replay(reach, progress=False)
    s = out["summary"]
    assert s["episodes"] == 2 and s["agree"] == 2, out["rows"]
    assert s["final_error_diff_max_mm"] <= 2.0


def test_joint_pos_at_20_fps_replays_too(tmp_path):
    out = _collect(tmp_path, "joints", "--target", "static", "--seed", "5", "--fps", "20", "--action-space",
                   "joint_pos", "--cameras", "top")
    ds = LeRobotDataset.open(out)
    assert ds.fps == 20 and ds.values(1, "action").shape == (50, 8)
    assert ds.features["action"]["names"][0] == "panda_joint1_rad"
    s = replay(out, progress=False)["summary"]
    assert s["agree"] == 2, s


def test_a_contact_task_exports(tmp_path):
    out = _collect(tmp_path, "pick", "--task", "pick", "--target", "static", "--seed", "3", "--episodes", "1")
    ds = LeRobotDataset.open(out)
    assert ds.info["total_episodes"] == 1 and "pick" in json.loads((out / "meta/mmact.json").read_text())["args"]["task"]
    g = ds.values(0, "action")[:, 6]
    assert g.max() - g.min() > 0.02  # the expert's gripper channel: it closes on the cube


def _one_line(capsys, argv):
    with pytest.raises(SystemExit) as exc:
        collect_main(argv)
    err = capsys.readouterr().err.strip()
    assert exc.value.code == 2 and "Traceback" not in err
    return err.splitlines()[-1]


def test_bad_input_is_one_line(tmp_path, capsys):
    full = tmp_path / "full"
    full.mkdir()
    (full / "notes.txt").write_text("mine")
    line = _one_line(capsys, [*COMMON, "--out", str(full)])
    assert "--out" in line and "not empty" in line
    line = _one_line(capsys, [*COMMON, "--out", str(tmp_path / "a"), "--fps", "7"])
    assert "--fps 7" in line and "1 kHz" in line
    line = _one_line(capsys, [*COMMON, "--out", str(tmp_path / "b"), "--image-size-px", "33"])
    assert "--image-size-px 33" in line
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


def test_a_replay_of_nothing_or_of_unknown_actions_is_one_line(tmp_path, reach):
    from mmact_ctrl.sources.contract import SourceError
    from mmact_ctrl.sources.replay import LeRobotReplay

    with pytest.raises(SourceError, match="not a LeRobot dataset"):
        LeRobotReplay(tmp_path / "nothing")
    with pytest.raises(SourceError, match="no such episode"):
        LeRobotReplay(reach, 7)
    foreign = tmp_path / "foreign"
    shutil.copytree(reach, foreign)
    info = json.loads((foreign / "meta/info.json").read_text())
    info["features"]["action"]["names"] = [f"a{i}" for i in range(7)]  # someone else's actions: meaning unknown
    (foreign / "meta/info.json").write_text(json.dumps(info))
    with pytest.raises(SourceError, match="not a space this project knows"):
        LeRobotReplay(foreign)
    run = subprocess.run([sys.executable, "-m", "scenarios.moving_target", "--source", f"lerobot:{tmp_path / 'nothing'}",
                          "--episodes", "1", "--quiet"], capture_output=True, text=True, timeout=300)
    assert run.returncode == 2 and "Traceback" not in run.stderr and "not a LeRobot dataset" in run.stderr


def test_show_summarises_a_dataset(reach, capsys):
    assert collect_main(["--format", "lerobot", "--show", str(reach)]) == 0
    out = capsys.readouterr().out
    assert "episodes 2, frames 50, fps 10" in out and "observation.state" in out and "success" in out


class RecordedChunkPolicy:
    """An object with LeRobot's policy interface whose chunks are a dataset's recorded actions (16 frames from the
    observation's time: it reads the time from nothing but the number of calls, 1 per second of the run)."""

    def __init__(self, actions, fps):
        import torch

        self.actions, self.fps, self.calls, self.torch = actions, fps, 0, torch
        self.batches = []

    def reset(self):
        self.calls = 0

    def predict_action_chunk(self, batch):
        self.batches.append({k: (tuple(v.shape) if hasattr(v, "shape") else v) for k, v in batch.items()})
        m = min(self.calls * self.fps, len(self.actions) - 1)
        self.calls += 1
        return self.torch.as_tensor(self.actions[m:m + 16][None])


def test_a_policy_trained_on_an_export_runs_in_its_conventions(reach):
    """examples/lerobot_trained.py: the dataset's conventions configure the LeRobot adapter (the cameras and their
    size, the state, the action space); the policy then drives the arm as the recorded one did."""
    from examples.lerobot_trained import source_for_policy
    from mmact_ctrl.controller import HybridController
    from mmact_ctrl.loop import run_episode
    from mmact_ctrl.metrics import episode_metrics
    from mmact_ctrl.config import StackConfig
    from scenarios.sources import scene_settings
    from scenarios.world.factory import make_world

    ds = LeRobotDataset.open(reach)
    policy = RecordedChunkPolicy(ds.values(0, "action"), ds.fps)
    source = source_for_policy(policy, str(reach))
    scene = scene_settings(source)
    assert scene == {"cameras": ("front", "side"), "image_size_px": 32}
    meta = json.loads((reach / "meta/mmact.json").read_text())
    world = make_world("linear", 0.2, n_objects=2, **scene)
    try:
        log = run_episode(world, source, HybridController(StackConfig(mode="open_loop", duration_s=2.5)),
                          seed=meta["episodes"][0]["seed"])
    finally:
        world.close()
    b = policy.batches[0]
    assert b["observation.images.front"] == (1, 3, 32, 32) and b["observation.state"] == (1, 8)
    assert b["task"] == [meta["episodes"][0]["task"]]
    m = episode_metrics(log)
    assert m["success"] == meta["episodes"][0]["success"]
    assert abs(m["final_error_m"] - meta["episodes"][0]["final_error_m"]) < 0.002


def test_joint_actions_are_the_commanded_pose_in_joints():
    """``joint_pos`` records the command (its inverse kinematics from the posture reached), not the joints reached:
    the forward kinematics of each action is the commanded TCP pose, and the posture stays the arm's."""
    from controllers.rotations import rotvec_from_rot
    from mmact_ctrl.config import StackConfig
    from mmact_ctrl.controller import HybridController
    from scenarios.lerobot_episode import joint_actions

    ctrl = HybridController(StackConfig())
    rng = np.random.default_rng(0)
    q_cmd = ctrl.model.home_q_rad + rng.normal(0.0, 0.15, size=(6, 7))
    tcp = np.empty((6, 7))
    for m, q in enumerate(q_cmd):
        pos, rot = ctrl.model.fk(q)
        tcp[m, :3], tcp[m, 3:6], tcp[m, 6] = pos, rotvec_from_rot(rot, ctrl.rot_nominal), 0.08 - 0.01 * m
    q_reached = q_cmd + rng.normal(0.0, 0.02, size=q_cmd.shape)  # the arm lags its command
    act = joint_actions(ctrl, tcp, q_reached)
    assert act.shape == (6, 8) and np.allclose(act[:, 7], tcp[:, 6])
    for m in range(6):
        pos, rot = ctrl.model.fk(act[m, :7])
        assert np.linalg.norm(pos - tcp[m, :3]) < 1e-5
        assert np.linalg.norm(rotvec_from_rot(rot, ctrl.rot_nominal) - tcp[m, 3:6]) < 1e-4
        assert np.abs(act[m, :7] - q_reached[m]).max() < 0.1  # the nearby solution, not another branch
        assert np.abs(act[m, :7] - q_reached[m]).max() > 1e-4  # not the joints reached
