"""Conventions as presets: a foreign policy executed as it was trained, or one line that says what is wrong.

The presets against the anchors' values; the encoder as the adapter's inverse; the state's axis-angle continuous
across the half turn; how the client settles a convention from the server's metadata and the switches; the
privileged keys on the wire; a server's error text on screen and in the JSON (openpi's own server as the peer); the
conformance probe against a conforming and a wrong server; each refused switch; the expert served in each preset
running the native expert's episodes, and one piece wrong changing them; the watchdog's stops explained and gone at
the replan rate the connect block suggests. Real websockets on 127.0.0.1, real MuJoCo episodes; no mocks."""

import json
import socket
from dataclasses import replace
import threading
import time

import numpy as np
import pinocchio as pin
import pytest

from controllers.robot_model import PandaModel
from controllers.rotations import rotvec_from_rot
from mmact_ctrl.chunk import Observation
from mmact_ctrl.sources import ActionSpace, SourceError
from mmact_ctrl.sources.action_encoder import ActionEncoder
from mmact_ctrl.sources.action_space import ActionAdapter
from mmact_ctrl.sources.openpi import ClientConfig, PolicyServer
from mmact_ctrl.sources.remote import RemoteSource, load_mapping
from mmact_ctrl.sources.remote.connect import coverage, suggest_replan_hz
from mmact_ctrl.sources.presets import DROID, LIBERO, PRESETS, load_preset
from mmact_ctrl.sources.presets.resolve import ConventionSwitches, resolve
from scenarios import serve
from scenarios.moving_target import main

FAST = ClientConfig(connect_timeout_s=2.0, connect_tries=2, retry_wait_s=0.1, request_timeout_s=5.0,
                    reconnect_timeout_s=0.5, close_timeout_s=0.2)
URL = "ws://test:1"


@pytest.fixture(scope="module")
def model():
    return PandaModel()


def _observation(model, dq=(0.1, 0.05, -0.05, 0.1, 0.02, -0.05, 0.1)) -> Observation:
    q = model.home_q_rad + np.asarray(dq)
    pos, rot = model.fk(q)
    return Observation(t0_s=0.0, q_rad=q, dq_rad_s=np.zeros(7), ee_pos_m=pos,
                       ee_rotvec_rad=rotvec_from_rot(rot, model.fk(model.home_q_rad)[1]), gripper_m=0.08,
                       target_pos_m=np.array([0.5, 0.1, 0.25]), instruction="reach the red ball")


# ---- the presets say what their anchors say -------------------------------------------------------------------
def test_the_presets_hold_the_anchors_values():
    a = LIBERO.action  # robosuite 1.4.1 osc_pose.json + scale_action; LIBERO control_freq 20; openpi libero client
    assert (a.kind, a.delta_from, a.gripper, a.clip) == ("tcp_delta", "previous", "sign", (-1.0, 1.0))
    assert a.scale == (0.05, 0.05, 0.05, 0.5, 0.5, 0.5) and a.dt_s == pytest.approx(0.05) and LIBERO.horizon == 10
    assert [k.key for k in LIBERO.mapping.images] == ["observation/image", "observation/wrist_image"]
    assert all(k.size_hw == (224, 224) and k.rotate_deg == 0 for k in LIBERO.mapping.images)
    assert LIBERO.mapping.state[0].parts == ("ee_pos_m", "ee_axis_angle_rad", "gripper_fingers_m")
    d = DROID.action  # openpi droid client (joint_velocity, clip [-1, 1], 15 Hz); DROID max_joint_delta 0.2
    assert (d.kind, d.delta_from, d.gripper, d.scale, d.clip) == ("joint_delta", "previous", "close_1", (0.2,), (-1.0, 1.0))
    assert d.dt_s == pytest.approx(1 / 15) and DROID.horizon == 10
    assert all(p.sources for p in PRESETS.values())


def test_a_json_preset_file_defines_a_convention(tmp_path):
    conv = load_preset("examples/presets/droid_joint_position.json")
    assert conv.action.kind == "joint_pos" and conv.action.dt_s == pytest.approx(1 / 15) and conv.horizon == 16
    assert conv.mapping == DROID.mapping
    path = tmp_path / "mine.json"
    path.write_text(json.dumps({"based_on": "libero", "action": {"control_hz": 10}, "horizon": 5}))
    mine = load_preset(str(path))
    assert mine.name == "mine" and mine.action.dt_s == pytest.approx(0.1) and mine.action.scale == LIBERO.action.scale
    path.write_text(json.dumps({"based_on": "libero", "colour": 1}))
    with pytest.raises(ValueError, match="unknown field.*colour"):
        load_preset(str(path))
    with pytest.raises(ValueError, match="unknown preset 'robosuite'"):
        load_preset("robosuite")


# ---- the encoder is the adapter's inverse ----------------------------------------------------------------------
SPACES = [ActionSpace("tcp_pose", "width_m", 0.1), ActionSpace("tcp_pose", "sign", 0.05, rotation="world"),
          LIBERO.action, ActionSpace("tcp_delta", "open_1", 0.05, delta_from="observation"),
          ActionSpace("joint_pos", "close_1", 1 / 15), DROID.action, ActionSpace("joint_delta", "none", 0.1)]


@pytest.mark.parametrize("space", SPACES, ids=lambda s: s.describe()[:40])
def test_encoding_then_adapting_gives_the_waypoints_back(space, model):
    obs = _observation(model)
    s = np.linspace(0, 1, 10)[:, None]
    w = np.hstack([obs.ee_pos_m + s * [0.1, -0.05, -0.08], s * [0.05, 0.1, -0.2], 0.08 - 0.06 * s])
    enc = ActionEncoder(space, model).encode(w, obs)
    assert enc.actions.shape == (10, space.dims) and enc.n_clipped == 0
    back = ActionAdapter(space, model).to_chunk(enc.actions, obs).waypoints
    expected = w.copy()
    if space.gripper == "none":
        expected[:, 6] = 0.08
    np.testing.assert_allclose(back, expected, atol=1e-7)


# ---- the state's orientation is continuous ----------------------------------------------------------------------
def test_the_state_axis_angle_is_continuous_across_the_half_turn(model):
    """Near the nominal grasp (a half turn about x) a folded axis-angle jumps by 2 pi where nothing moved."""
    libero = load_mapping("libero")
    rot_nominal = model.fk(model.home_q_rad)[1]
    states, folded = [], []
    for a in np.linspace(-0.1, 0.1, 21):  # through the half turn: the angle goes from pi - 0.1 to pi + 0.1
        rot = pin.exp3(np.array([a, 0.03, -0.02])) @ rot_nominal
        obs = Observation(0.0, np.zeros(7), np.zeros(7), np.zeros(3), rotvec_from_rot(rot, rot_nominal), 0.08, np.zeros(3),
                          image=np.zeros((1, 8, 8, 3), np.uint8))
        states.append(libero.encode(obs, rot_nominal)["observation/state"][3:6])
        folded.append(rotvec_from_rot(rot, np.eye(3)))
        np.testing.assert_allclose(pin.exp3(states[-1]), rot, atol=1e-12)  # it is the same rotation
    assert np.abs(np.diff(states, axis=0)).max() < 0.02
    assert np.abs(np.diff(folded, axis=0)).max() > 6.0  # what the state was before: the jump the test guards


# ---- settling the convention: metadata cases --------------------------------------------------------------------
RESOLVED = [
    ({}, dict(preset="libero"), "libero", "previous"),
    ({"preset": "droid"}, {}, "droid", "previous"),
    ({"mmact": {"obs_mapping": "libero"}}, {}, "libero", "previous"),          # a server may name a preset
    ({"mmact": {"version": 1}}, dict(obs_mapping="libero", kind="tcp_delta", gripper="sign", dt_s=0.05,
                                     delta_from="previous"), "custom", "previous"),  # ours without a mapping
    ({"action_horizon": 25}, dict(preset="libero"), "libero", "previous"),
    ({"preset": "libero"}, dict(preset="libero"), "libero", "previous"),       # the same word twice
]


@pytest.mark.parametrize("meta,said,name,delta_from", RESOLVED, ids=[json.dumps(m)[:30] + str(s)[:30] for m, s, *_ in RESOLVED])
def test_metadata_and_switches_settle_one_convention(meta, said, name, delta_from):
    r = resolve(meta, ConventionSwitches(**said), URL)
    assert r.convention.name == name and r.convention.action.delta_from == delta_from
    if "action_horizon" in meta:
        assert r.convention.horizon == 25 and r.origin["horizon"] == "server (action_horizon)"


REFUSED = [
    ({}, {}, ["does not declare its convention", "--preset", "libero, droid, mmact"]),
    ({}, dict(kind="tcp_delta"), ["--action-space also need", "--obs-mapping", "--gripper", "--chunk-dt-s"]),
    ({}, dict(obs_mapping="libero", kind="tcp_delta", gripper="sign", dt_s=0.05), ["needs --delta-from"]),
    ({"preset": "droid"}, dict(preset="libero"), ["declares", "the droid preset", "--preset libero says"]),
    ({"preset": "libero"}, dict(delta_from="observation"), ["declares delta-from previous", "--delta-from observation"]),
    ({"preset": "robosuite"}, {}, ["names the convention 'robosuite'"]),
    ({"mmact": {"privileged": ["q_rad"]}}, dict(preset="libero"), ["not privileged parts"]),
    ({}, dict(preset="droid", rotation="world"), ["--action-rotation applies to tcp_pose"]),
    ({}, dict(preset="libero", obs_mapping="mmact", image_rotation_deg=180), ["--image-rotation applies to a key mapping"]),
]


@pytest.mark.parametrize("meta,said,needles", REFUSED, ids=[str(s)[:40] for _, s, _ in REFUSED])
def test_what_cannot_be_settled_is_one_line_naming_it(meta, said, needles):
    with pytest.raises(SourceError) as err:
        resolve(meta, ConventionSwitches(**said), URL)
    assert "\n" not in str(err.value)
    for n in needles:
        assert n in str(err.value), str(err.value)


# ---- peers: openpi's own server, and the expert served in a preset -----------------------------------------------
def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def openpi_server(policy, metadata=None) -> str:
    """openpi's own WebsocketPolicyServer (PyPI openpi-server, installed --no-deps) in a daemon thread."""
    from openpi_server import WebsocketPolicyServer

    port = _free_port()
    server = WebsocketPolicyServer(policy, host="127.0.0.1", port=port, metadata=metadata)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return f"ws://127.0.0.1:{port}"
        time.sleep(0.05)
    raise RuntimeError("openpi's server did not start")


class LiberoLike:
    """A LIBERO-style policy: reads observation/state, answers 10 zero steps (sign gripper, open); records keys;
    ``fail_every``: raise on every n-th call, as a real model can."""

    def __init__(self, fail_every: int = 0) -> None:
        self.keys: list[set] = []
        self.calls, self.fail_every = 0, fail_every

    def infer(self, obs: dict) -> dict:
        self.keys.append(set(obs))
        self.calls += 1
        state = obs["observation/state"]  # a KeyError for a client that sends other keys
        if self.fail_every and self.calls % self.fail_every == 0:
            raise RuntimeError(f"CUDA out of memory on call {self.calls} (state {state.shape})")
        actions = np.zeros((10, 7), np.float32)
        actions[:, 6] = -1.0
        return {"actions": actions}


def served(*argv: str):
    """``python -m scenarios.serve ARGV`` in a thread of this process (the same code path as the command)."""
    args = serve.build_parser().parse_args([*argv, "--port", "0"])
    source, scene, _ = serve.make_served_source(args)
    return PolicyServer(serve.make_policy(args, source, scene), port=0).start()


def run(argv, tmp_path, name="run.json"):
    out = tmp_path / name
    assert main([*argv, "--quiet", "--json", str(out)]) == 0
    return json.loads(out.read_text())


def test_no_privileged_key_reaches_a_server_that_did_not_ask(tmp_path, capsys):
    policy = LiberoLike()
    url = openpi_server(policy)
    payload = run(["--source", url, "--preset", "libero", "--target", "static", "--mode", "open_loop", "--episodes", "1",
                   "--duration-s", "1", "--replan-hz", "5"], tmp_path)
    assert policy.keys and not any(k.startswith("mmact/") for keys in policy.keys for k in keys)
    assert payload["config"]["connect"]["privileged_keys"] == []
    assert "privileged: none" in capsys.readouterr().out
    # the user's own choice of our keys sends the true target, and the connect block names it
    src = RemoteSource(url, ConventionSwitches(obs_mapping="mmact", kind="tcp_pose", gripper="width_m", dt_s=0.1,
                                               rotation="nominal"), FAST)
    assert "mmact/target_pos_m" in src.resolved.privileged_keys
    src.close()


def test_a_server_that_asks_gets_exactly_the_privileged_keys(model):
    handle = served("--source", "expert", "--preset", "libero")
    try:
        src = RemoteSource(handle.url, ConventionSwitches(preset="libero"), FAST)
        obs = replace(_observation(model), image=np.zeros((1, 96, 96, 3), np.uint8))
        sent = src.mapping.encode(obs, src._rot_nominal)
        assert sorted(k for k in sent if k.startswith("mmact/")) == ["mmact/frame_gap_s", "mmact/target_pos_m",
                                                                     "mmact/target_prev_pos_m"]
        assert src.resolved.word.privileged == ("target_pos_m", "target_prev_pos_m", "frame_gap_s")
        src.close()
    finally:
        handle.stop()


def test_a_server_that_raises_on_our_keys_stops_the_run_before_any_episode(capsys, one_line_exit_2):
    url = openpi_server(LiberoLike())
    with pytest.raises(SystemExit) as exc:
        main(["--source", url, "--preset", "droid", "--episodes", "1", "--duration-s", "1", "--quiet"])
    one_line_exit_2(exc.value.code, capsys.readouterr().err, "KeyError", "observation/state", "before any episode")


def test_a_foreign_server_without_a_convention_is_one_line_naming_preset(capsys, one_line_exit_2):
    url = openpi_server(LiberoLike())
    with pytest.raises(SystemExit) as exc:
        main(["--source", url, "--episodes", "1", "--duration-s", "1", "--quiet"])
    one_line_exit_2(exc.value.code, capsys.readouterr().err, "--preset", "libero, droid, mmact", "--obs-mapping")


def test_the_servers_error_text_reaches_the_screen_and_the_json(tmp_path, capsys):
    url = openpi_server(LiberoLike(fail_every=3))
    payload = run(["--source", url, "--preset", "libero", "--target", "static", "--mode", "open_loop",
                   "--episodes", "2", "--duration-s", "2", "--replan-hz", "5"], tmp_path)
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if "the source failed" in ln]
    assert len(lines) == 2 and all("RuntimeError: CUDA out of memory" in ln for ln in lines)  # once per episode
    for e in payload["episodes"]:
        texts = e["source_errors"]
        assert e["rejected_chunks"] == sum(t["count"] for t in texts) >= 2
        assert texts[0]["text"].startswith("Traceback") and "CUDA out of memory" in texts[0]["text"]


# ---- the probe ----------------------------------------------------------------------------------------------------
class AbsoluteLibero(LiberoLike):
    """Answers absolute positions where LIBERO expects normalised steps (a misread convention)."""

    def infer(self, obs: dict) -> dict:
        state = np.asarray(obs["observation/state"], dtype=np.float64)
        return {"actions": np.tile(np.r_[state[:6], 3.0], (10, 1)).astype(np.float32)}


def test_the_probe_passes_a_conforming_server_and_flags_a_wrong_one(tmp_path, capsys):
    from scenarios.probe import main as probe

    handle = served("--source", "expert", "--preset", "libero")
    try:
        t0 = time.perf_counter()
        assert probe([handle.url, "--preset", "libero", "--json", str(tmp_path / "p.json")]) == 0
        assert time.perf_counter() - t0 < 10
        found = json.loads((tmp_path / "p.json").read_text())
        assert found["actions_shape"] == [10, 7] and found["problems"] == []
    finally:
        handle.stop()
    assert probe([openpi_server(AbsoluteLibero()), "--preset", "libero"]) == 1
    out = capsys.readouterr().out
    assert "absolute positions sent as deltas" in out and "outside [-1, 1]" in out and "outside the sign" in out


# ---- switches that do not apply ------------------------------------------------------------------------------------
BAD_SWITCHES = [
    (["--source", "ws://127.0.0.1:9", "--horizon", "10"], ["--horizon is for --source expert", "chunk length"]),
    (["--source", "expert", "--delta-from", "previous"], ["--delta-from", "ws://HOST:PORT"]),
    (["--source", "expert", "--preset", "libero"], ["--preset", "ws://HOST:PORT"]),
    (["--source", "examples.byo_source:make_source", "--chunk-dt-s", "0.1"], ["--chunk-dt-s is for"]),
    (["--source", "policy", "--expert-lead", "none"], ["--expert-lead is for --source expert"]),
    (["--source", "expert", "--action-steps", "2"], ["--action-steps is for --source policy"]),
    (["--source", "expert", "--action-scale", "0,1"], ["--action-scale", "> 0"]),
    (["--source", "expert", "--action-clip", "1,-1"], ["--action-clip", "LO < HI"]),
]


@pytest.mark.parametrize("argv,needles", BAD_SWITCHES, ids=[" ".join(a)[:45] for a, _ in BAD_SWITCHES])
def test_a_switch_that_does_not_apply_is_refused_in_one_line(argv, needles, capsys, one_line_exit_2):
    with pytest.raises(SystemExit) as exc:
        main([*argv, "--episodes", "1", "--duration-s", "0.5", "--quiet"])
    one_line_exit_2(exc.value.code, capsys.readouterr().err, *needles)


def test_a_delta_space_without_delta_from_is_refused_at_a_foreign_server(capsys, one_line_exit_2):
    """The README's old command read LIBERO's successive steps as deltas from the observation, silently."""
    url = openpi_server(LiberoLike())
    with pytest.raises(SystemExit) as exc:
        main(["--source", url, "--obs-mapping", "libero", "--action-space", "tcp_delta", "--gripper", "sign",
              "--chunk-dt-s", "0.05", "--episodes", "1", "--quiet"])
    one_line_exit_2(exc.value.code, capsys.readouterr().err, "needs --delta-from", "previous")


# ---- invariance: the expert through each preset runs the native expert's episodes ---------------------------------
COMMON = ["--target", "static", "--episodes", "2", "--duration-s", "3", "--replan-hz", "5", "--seed", "3"]


@pytest.mark.parametrize("preset", ["libero", "droid"])
def test_the_expert_served_in_a_preset_runs_the_native_experts_episodes(preset, tmp_path):
    conv = PRESETS[preset]
    native = run(["--source", "expert", "--horizon", str(conv.horizon), "--chunk-dt-s", repr(conv.action.dt_s),
                  "--mode", "open_loop", "hybrid", *COMMON], tmp_path, "native.json")
    handle = served("--source", "expert", "--preset", preset)
    try:
        through = run(["--source", handle.url, "--preset", preset, "--mode", "open_loop", "hybrid", *COMMON], tmp_path)
        wrong = run(["--source", handle.url, "--preset", preset, "--delta-from", "observation", "--mode", "open_loop",
                     *COMMON], tmp_path, "wrong.json")
    finally:
        handle.stop()
    for mode in ("open_loop", "hybrid"):
        a, b = native["runs"][mode]["episodes"], through["runs"][mode]["episodes"]
        assert [e["success"] for e in a] == [e["success"] for e in b] == [True, True]
        assert max(abs(x["final_error_m"] - y["final_error_m"]) for x, y in zip(a, b)) < 1e-3
        assert all(e["limit_violations"] == 0 and e["rejected_chunks"] == 0 for e in b)
    # one piece wrong (rows read as deltas from the observation, not as successive steps): the result changes
    w = wrong["runs"]["open_loop"]["episodes"]
    assert sum(e["success"] for e in w) < 2 or min(e["final_error_m"] for e in w) > 0.02


def test_our_frames_are_upright_and_the_served_expert_refuses_turned_ones(capsys, one_line_exit_2):
    from scenarios.world.factory import make_world
    from scenarios.world.frame_check import UprightCheck

    world = make_world("static", n_objects=2, image_size_px=224, cameras=("front",))
    check = UprightCheck(world.model, "front", "img", 2)
    try:
        for seed in range(6):
            world.reset(seed)
            frame = world.render()[0]
            obs = Observation(0.0, np.zeros(7), np.zeros(7), np.zeros(3), np.zeros(3), 0.08, world.target_pos_m(),
                              instruction=world.instruction)
            check({"img": frame}, obs)  # upright: accepted
            with pytest.raises(ValueError, match="upside down"):
                check({"img": frame[::-1, ::-1]}, obs)
    finally:
        world.close()
    handle = served("--source", "expert", "--preset", "libero")
    try:
        with pytest.raises(SystemExit) as exc:
            main(["--source", handle.url, "--preset", "libero", "--image-rotation", "180", "--episodes", "1", "--quiet"])
        one_line_exit_2(exc.value.code, capsys.readouterr().err, "upside down", "before any episode")
    finally:
        handle.stop()


# ---- coverage: the arm brakes between chunks, the connect block says why and what rate would not ------------------
def test_coverage_and_the_suggested_replan_rate():
    c = coverage(chunk_s=1.0, replan_hz=1.0, latency_s=0.2, latency_from="--latency-ms")
    assert not c.covers and c.suggested_replan_hz == 1.5
    assert coverage(1.0, 1.5, 0.2, "x").covers
    assert suggest_replan_hz(0.5, 0.2) == 5.0 and suggest_replan_hz(0.2, 0.2) is None


def test_watchdog_stops_vanish_at_the_suggested_rate_for_10_waypoints_at_150_ms(tmp_path, capsys):
    handle = served("--source", "expert", "--horizon", "10", "--infer-delay-ms", "150")
    argv = ["--source", handle.url, "--latency-ms", "measured", "--target", "linear", "--mode", "open_loop",
            "--episodes", "1", "--duration-s", "4"]
    try:
        slow = run(argv, tmp_path, "slow.json")
        out = capsys.readouterr().out
        cov = slow["config"]["connect"]["coverage"]
        assert not cov["covers"] and slow["summary"]["watchdog_stops"] > 0
        assert f"--replan-hz {cov['suggested_replan_hz']:g} covers" in out and "note: " in out
        fixed = run([*argv, "--replan-hz", f"{cov['suggested_replan_hz']:g}"], tmp_path)
    finally:
        handle.stop()
    assert fixed["config"]["connect"]["coverage"]["covers"] and fixed["summary"]["watchdog_stops"] == 0
