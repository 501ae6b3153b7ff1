"""openpi's websocket policy protocol: the codec, our server driven by openpi's own client, our client against our
server, the observation mappings, every wire fault as a clear, bounded-time error, the serve CLI's one-line errors,
and short MuJoCo episodes driven through a server. Real websockets on 127.0.0.1 only; no mocks."""

import json
import socket
import subprocess
import sys
import threading
import time
import urllib.request

import numpy as np
import pytest

# openpi's real client, installed with `pip install --no-deps openpi-client` (it pins numpy < 2, so it is not a
# dependency); the peer tests must run, not skip: a missing package is an error here.
from openpi_client import msgpack_numpy as openpi_msgpack
from openpi_client.websocket_client_policy import WebsocketClientPolicy

from mmact_ctrl.chunk import Observation
from mmact_ctrl.sources import ActionSpace, SourceError, require_capabilities
from mmact_ctrl.sources.openpi import (ClientConfig, ConnectionLost, FrameError, PolicyClient, PolicyServer,
                                       RequestTimeout, ServerError, ServerUnreachable, codec)
from mmact_ctrl.sources.remote import KeyMapping, MmactMapping, RemoteSource, SourcePolicy, StateKey, load_mapping
from mmact_ctrl.sources.remote.mapping import SCENE_CAMERAS, resize_bilinear
from scenarios.world.factory import make_expert

FAST = ClientConfig(connect_timeout_s=1.0, connect_tries=2, retry_wait_s=0.1, request_timeout_s=2.0,
                    reconnect_timeout_s=0.5, close_timeout_s=0.2)


def observation(t0_s: float = 0.3, image: np.ndarray | None = None, prev_image: np.ndarray | None = None,
                **kw) -> Observation:
    rng = np.random.default_rng(int(t0_s * 1000))
    args = dict(t0_s=t0_s, q_rad=rng.normal(0, 0.3, 7), dq_rad_s=rng.normal(0, 0.1, 7),
                ee_pos_m=np.array([0.45, 0.02, 0.31]) + rng.normal(0, 0.01, 3), ee_rotvec_rad=rng.normal(0, 0.05, 3),
                gripper_m=0.08, target_pos_m=np.array([0.52, 0.11, 0.22]), target_prev_pos_m=np.array([0.5, 0.1, 0.22]),
                frame_gap_s=0.1, image=image, prev_image=prev_image, instruction="reach the red ball")
    args.update(kw)
    return Observation(**args)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def expert():
    return make_expert(lead="velocity")


@pytest.fixture(scope="module")
def expert_server(expert):
    handle = PolicyServer(SourcePolicy(expert, scene={"plane_z_m": 0.0, "n_objects": 1}), port=0).start()
    yield handle
    handle.stop()


# ---- codec ------------------------------------------------------------------------------------------------------
DTYPES = ["?", "i1", "i2", "i4", "i8", "u1", "u2", "u4", "u8", "f2", "f4", "f8", ">f8", "c8", "c16", "S4", "U3",
          "M8[ms]", "m8[s]"]


@pytest.mark.parametrize("dtype", DTYPES)
def test_codec_round_trips_every_dtype_and_matches_openpi_bytes(dtype):
    a = np.arange(6).reshape(2, 3).astype(dtype) if dtype[0] not in "SU" else np.array([["ab", "c", "d"], ["e", "f", "g"]], dtype)
    obj = {"a": a, "transposed": a.T, "zero_d": np.array(a[0, 0]), "empty": np.zeros((0, 3), a.dtype), "nested": [a, {"b": a}]}
    back = codec.unpackb(codec.packb(obj))
    for got, want in [(back["a"], a), (back["transposed"], a.T), (back["zero_d"], obj["zero_d"]),
                      (back["empty"], obj["empty"]), (back["nested"][0], a), (back["nested"][1]["b"], a)]:
        assert got.dtype == want.dtype and got.shape == want.shape and np.array_equal(got, want)
    if a.dtype.kind != "c":  # openpi refuses complex; everything else is byte for byte the same frame
        assert codec.packb(obj) == openpi_msgpack.packb(obj)
        assert np.array_equal(openpi_msgpack.unpackb(codec.packb(obj))["transposed"], a.T)


def test_codec_scalars_and_plain_values():
    obj = {"i": np.int64(-3), "b": np.bool_(True), "f32": np.float32(1.5), "u8": np.uint8(7), "f64": np.float64(2.5),
           "text": "prompt", "raw": b"\x00\x01", "none": None, "list": [1, 2.0, "x"]}
    data = codec.packb(obj)
    assert data == openpi_msgpack.packb(obj)
    back = codec.unpackb(data)
    assert back["i"] == -3 and back["i"].dtype == np.int64 and back["b"] is np.True_ and back["f32"].dtype == np.float32
    assert back["text"] == "prompt" and back["raw"] == b"\x00\x01" and back["none"] is None and back["list"] == [1, 2.0, "x"]


@pytest.mark.parametrize("bad", [np.array([1, "a"], dtype=object), np.zeros(2, dtype=[("x", "f4")]), np.complex128(1j),
                                 object()])
def test_codec_refuses_what_needs_pickle(bad):
    with pytest.raises(ValueError, match="cannot send"):
        codec.packb({"x": bad})


def test_codec_refuses_malformed_frames():
    for frame, match in [(b"\xc1", "undecodable"), (codec.packb({"x": np.zeros(3)})[:-3], "undecodable"),
                         (openpi_msgpack.packb({b"__ndarray__": True, b"data": b"123", b"dtype": "<f8", b"shape": [3]}),
                          "shape \\(3,\\)"),
                         (openpi_msgpack.packb({b"__ndarray__": True, b"data": b"12345678", b"dtype": "|O", b"shape": [1]}),
                          "object")]:
        with pytest.raises(FrameError, match=match):
            codec.unpackb(frame)


# ---- openpi's own client drives our server -----------------------------------------------------------------------
@pytest.mark.filterwarnings("ignore:connect\\(\\) must be used as a context manager:DeprecationWarning")
def test_openpi_client_drives_our_server(expert_server, expert):
    peer = WebsocketClientPolicy(expert_server.url)
    meta = peer.get_server_metadata()["mmact"]
    assert meta["obs_mapping"] == "mmact" and meta["action_space"]["kind"] == "tcp_pose"
    assert meta["chunk_dt_s"] == pytest.approx(0.1) and meta["capabilities"] == ["inpaint"]
    assert meta["needs_image"] is False and meta["scene"] == {"plane_z_m": 0.0, "n_objects": 1}
    obs = observation()
    first = peer.infer(MmactMapping(needs_image=False).encode(obs))
    second = peer.infer(MmactMapping(needs_image=False).encode(obs))
    np.testing.assert_array_equal(first["actions"], expert.plan(obs).waypoints)
    assert first["actions"].shape == (16, 7) and first["actions"].dtype == np.float64
    for reply in (first, second):
        assert reply["server_timing"]["infer_ms"] >= reply["policy_timing"]["infer_ms"] > 0
    assert "prev_total_ms" not in first["server_timing"] and second["server_timing"]["prev_total_ms"] > 0


def test_healthz(expert_server):
    with urllib.request.urlopen(expert_server.healthz_url, timeout=5) as r:
        assert r.status == 200 and r.read().decode().strip() == "OK"


# ---- our client against our server -------------------------------------------------------------------------------
def test_served_expert_gives_the_in_process_chunks(expert_server, expert):
    src = RemoteSource(expert_server.url, config=FAST)
    try:
        assert src.declared_capabilities == frozenset({"inpaint"}) and not src.needs_image
        assert src.chunk_dt_s == pytest.approx(0.1) and src.action_token_range == expert.action_token_range
        assert src.name == expert_server.url and src.scene == {"plane_z_m": 0.0, "n_objects": 1}
        for t0 in (0.0, 0.3, 1.7):
            obs = observation(t0, target_prev_pos_m=None, frame_gap_s=0.0) if t0 == 0 else observation(t0)
            remote, local = src.plan(obs), expert.plan(obs)
            np.testing.assert_array_equal(remote.waypoints, local.waypoints)
            np.testing.assert_array_equal(remote.tokens, local.tokens)
            assert remote.t0_s == local.t0_s and remote.dt_s == local.dt_s
            assert set(remote.info) >= {"round_trip_ms", "server_infer_ms", "policy_infer_ms"}
            assert remote.info["round_trip_ms"] >= remote.info["server_infer_ms"] >= remote.info["policy_infer_ms"] > 0
        obs, known = observation(), expert.plan(observation()).waypoints[:3]
        np.testing.assert_array_equal(src.plan_inpaint(obs, known).waypoints, expert.plan_inpaint(obs, known).waypoints)
        assert len(src.client.calls) == 4 and all(c.error is None for c in src.client.calls)
    finally:
        src.close()


@pytest.mark.parametrize("checkpoint", ["mmact_small.pt", "mmact_3d.pt"])
def test_served_token_policy_is_bit_identical(checkpoint):
    from mmact_ctrl.policy_source import PolicyChunkSource
    from policy.inference import DEFAULT_CHECKPOINT

    policy = PolicyChunkSource(DEFAULT_CHECKPOINT.parent / checkpoint)
    with PolicyServer(SourcePolicy(policy), port=0).start() as handle:
        src = RemoteSource(handle.url, config=FAST)
        try:
            assert src.camera_names == policy.camera_names and src.prev_frame_gap_s == policy.prev_frame_gap_s
            assert src.needs_image and src.action_token_range == policy.action_token_range
            rng = np.random.default_rng(2)
            views = len(policy.camera_names)
            img, prev = (rng.integers(0, 256, (views, 96, 96, 3), dtype=np.uint8) for _ in range(2))
            obs = observation(image=img, prev_image=prev if policy.prev_frame_gap_s > 0 else None)
            local, remote = policy.plan(obs), src.plan(obs)
            np.testing.assert_array_equal(remote.waypoints, local.waypoints)
            np.testing.assert_array_equal(remote.tokens, local.tokens)
            known = local.waypoints[:2]
            np.testing.assert_array_equal(src.plan_inpaint(obs, known).waypoints, policy.plan_inpaint(obs, known).waypoints)
        finally:
            src.close()


class _NoInpaint:
    needs_image = False
    chunk_dt_s = 0.1

    def __init__(self, inner):
        self.inner = inner

    def plan(self, observation):
        return self.inner.plan(observation)


def test_inpainting_is_offered_only_when_the_server_declares_it(expert):
    with PolicyServer(SourcePolicy(_NoInpaint(expert)), port=0).start() as handle:
        src = RemoteSource(handle.url, config=FAST)
        try:
            assert src.declared_capabilities == frozenset()
            with pytest.raises(SourceError, match="cannot run --mode inpaint"):
                require_capabilities(src, ["inpaint"], "inpaint")
            with pytest.raises(SourceError, match="does not declare the inpaint capability"):
                src.plan_inpaint(observation(), np.zeros((2, 7)))
        finally:
            src.close()


def test_remote_source_refuses_what_contradicts_the_server(expert_server):
    with pytest.raises(SourceError, match="declares action-space tcp_pose; --action-space joint_pos contradicts it"):
        RemoteSource(expert_server.url, action_space=ActionSpace("joint_pos", "none", 0.1), config=FAST)
    with pytest.raises(SourceError, match="declares obs-mapping 'mmact'.*--obs-mapping 'libero' contradicts it"):
        RemoteSource(expert_server.url, mapping="libero", config=FAST)


# ---- mappings ----------------------------------------------------------------------------------------------------
def test_scene_cameras_are_the_scenes():
    from scenarios.world.panda_scene import AVAILABLE_CAMERAS

    assert SCENE_CAMERAS == AVAILABLE_CAMERAS


def test_mmact_mapping_rebuilds_the_exact_observation():
    rng = np.random.default_rng(1)
    img, prev = (rng.integers(0, 256, (2, 96, 96, 3), dtype=np.uint8) for _ in range(2))
    m = MmactMapping(camera_names=("front", "side"), prev_frame_gap_s=0.1)
    for obs in (observation(image=img, prev_image=prev), observation(0.0, image=img, target_prev_pos_m=None, frame_gap_s=0.0)):
        back = m.decode(codec.unpackb(codec.packb(m.encode(obs))))
        for f in Observation.__dataclass_fields__:
            a, b = getattr(obs, f), getattr(back, f)
            assert (a is None and b is None) or (type(a) is type(b) and np.array_equal(a, b)), f


def test_libero_and_droid_presets():
    img = np.zeros((1, 96, 96, 3), np.uint8)
    img[0, :, :48] = 200
    obs = observation(image=img, gripper_m=0.06)
    libero = load_mapping("libero")
    assert libero.camera_names == ("front",) and libero.missing_cameras == ("wrist",) and libero.image_size_px == 224
    d = libero.encode(obs, rot_nominal=np.eye(3))
    assert d["observation/image"].shape == (224, 224, 3) and d["observation/image"].dtype == np.uint8
    assert d["observation/image"][:, :100].min() == 200 and d["observation/image"][:, 124:].max() == 0
    assert not d["observation/wrist_image"].any() and d["prompt"] == "reach the red ball"
    state = d["observation/state"]
    assert state.shape == (8,)
    np.testing.assert_allclose(state[:3], obs.ee_pos_m)
    np.testing.assert_allclose(state[3:6], obs.ee_rotvec_rad, atol=1e-12)  # nominal = identity: the same rotation
    np.testing.assert_allclose(state[6:], [0.03, -0.03])
    droid = load_mapping("droid").encode(obs)
    np.testing.assert_allclose(droid["observation/joint_position"], obs.q_rad)
    np.testing.assert_allclose(droid["observation/gripper_position"], [0.25])
    assert droid["observation/exterior_image_1_left"].shape == (224, 224, 3) and "wrist" in load_mapping("droid").describe()


def test_user_mapping_file(tmp_path):
    spec = {"images": [{"key": "cam", "camera": "side", "size_px": [64, 80]}, {"key": "cam_prev", "camera": "side",
                                                                            "size_px": 64, "previous": True}],
            "state": [{"key": "s", "parts": ["q_rad", "gripper_open_1"], "dtype": "float32"}],
            "prompt": "pick it", "prev_frame_gap_s": 0.2}
    path = tmp_path / "mine.json"
    path.write_text(json.dumps(spec))
    m = load_mapping(str(path))
    assert m.name == "mine" and m.camera_names == ("side",) and m.image_size_px == 80 and m.prev_frame_gap_s == 0.2
    img = np.full((1, 80, 80, 3), 7, np.uint8)
    d = m.encode(observation(image=img))  # no earlier frame yet: the current one stands in
    assert d["cam"].shape == (64, 80, 3) and (d["cam"] == 7).all() and d["cam_prev"].shape == (64, 64, 3)
    assert d["s"].dtype == np.float32 and d["s"].shape == (8,) and d["prompt"] == "pick it"
    assert KeyMapping.from_dict(m.to_dict(), "again") == m
    path.write_text(json.dumps({**spec, "colour": 1}))
    with pytest.raises(ValueError, match="unknown field.*colour"):
        load_mapping(str(path))
    with pytest.raises(ValueError, match="unknown part.*elbow"):
        KeyMapping.from_dict({"state": [{"key": "s", "parts": ["elbow"]}]})
    with pytest.raises(ValueError, match="preset"):
        load_mapping("no_such_mapping")


def test_resize_bilinear():
    img = np.random.default_rng(0).integers(0, 256, (6, 6, 3), dtype=np.uint8)
    assert resize_bilinear(img, (6, 6)) is img
    assert (resize_bilinear(np.full((5, 9, 3), 42, np.uint8), (13, 4)) == 42).all()
    up = resize_bilinear(np.array([[[0] * 3, [100] * 3]], np.uint8), (1, 4))
    np.testing.assert_array_equal(up[0, :, 0], [0, 25, 75, 100])


# ---- wire faults: a clear error within a bounded time ------------------------------------------------------------
class ScriptedPolicy:
    """A server-side policy whose next answers the test scripts (``mode``): ok, slow_once, raise, shape, nan."""

    def __init__(self) -> None:
        self.mode = "ok"
        self.sleep_s = 0.0

    def infer(self, obs: dict) -> dict:
        mode = self.mode
        if mode == "slow_once":
            self.mode = "ok"
            time.sleep(self.sleep_s)
        if mode == "raise":
            raise RuntimeError("scripted failure")
        actions = np.tile([0.5, 0.0, 0.3, 0.0, 0.0, 0.0, 0.08], (10, 1))
        if mode == "shape":
            actions = actions[:, :3]
        if mode == "nan":
            actions[4, 2] = np.nan
        return {"actions": actions, "request": obs.get("request")}


@pytest.fixture()
def scripted():
    policy = ScriptedPolicy()
    handle = PolicyServer(policy, port=0).start()
    yield policy, handle
    handle.stop()


STATE_ONLY = KeyMapping("state_only", state=(StateKey("observation/state", ("ee_pos_m", "gripper_m")),))


def test_server_down_at_connect_is_one_line_within_the_retry_budget():
    url = f"ws://127.0.0.1:{free_port()}"
    t0 = time.perf_counter()
    with pytest.raises(ServerUnreachable) as err:
        RemoteSource(url, mapping=STATE_ONLY, action_space=ActionSpace(), config=FAST)
    assert time.perf_counter() - t0 < FAST.connect_tries * FAST.connect_timeout_s + FAST.retry_wait_s + 0.5
    msg = str(err.value)
    # a ConnectionError: the command lines print it as their one line
    assert url in msg and "2 tries" in msg and "\n" not in msg and isinstance(err.value, ConnectionError)


def test_a_server_that_accepts_but_never_answers_the_handshake_is_bounded():
    silent = socket.socket()
    silent.bind(("127.0.0.1", 0))
    silent.listen()  # TCP connects, nothing ever answers the websocket handshake
    url = f"ws://127.0.0.1:{silent.getsockname()[1]}"
    t0 = time.perf_counter()
    try:
        with pytest.raises(ServerUnreachable, match="after 1 try"):
            PolicyClient(url, ClientConfig(connect_timeout_s=0.3, connect_tries=1))
    finally:
        silent.close()
    assert time.perf_counter() - t0 < 1.0


def test_a_slow_reply_times_out_and_never_answers_a_later_request(scripted):
    policy, handle = scripted
    client = PolicyClient(handle.url, FAST)
    policy.sleep_s, policy.mode = 0.8, "slow_once"
    t0 = time.perf_counter()
    with pytest.raises(RequestTimeout, match="did not answer within 0.3 s"):
        client.infer({"request": 1}, timeout_s=0.3)
    assert time.perf_counter() - t0 < 0.3 + FAST.close_timeout_s + 0.3
    assert not client.connected
    assert client.infer({"request": 2}, timeout_s=3.0)["request"] == 2  # its own answer, not the late one
    assert client.infer({"request": 3})["request"] == 3
    assert [c.error is None for c in client.calls] == [False, True, True] and client.connects == 2
    client.close()


def test_an_error_frame_raises_its_exception_line_and_the_next_call_reconnects(scripted):
    policy, handle = scripted
    client = PolicyClient(handle.url, FAST)
    policy.mode = "raise"
    with pytest.raises(ServerError, match="RuntimeError: scripted failure") as err:
        client.infer({"request": 1})
    assert "Traceback" in err.value.text and "\n" not in str(err.value)
    policy.mode = "ok"
    assert client.infer({"request": 2})["request"] == 2
    client.close()


def test_wrong_shapes_and_nan_raise_value_errors_naming_them(scripted):
    policy, handle = scripted
    src = RemoteSource(handle.url, mapping=STATE_ONLY, action_space=ActionSpace(), config=FAST)
    try:
        assert src.metadata == {} and not src.needs_image and src.declared_capabilities == frozenset()
        policy.mode = "shape"
        with pytest.raises(ValueError, match=r"shape \(10, 3\).*\(H >= 1, 7\)"):
            src.plan(observation())
        policy.mode = "nan"
        with pytest.raises(ValueError, match="NaN or inf.*waypoint 4"):
            src.plan(observation())
        policy.mode = "ok"
        chunk = src.plan(observation())
        assert chunk.horizon == 10 and chunk.info["server_infer_ms"] > 0 and chunk.info["policy_infer_ms"] is None
    finally:
        src.close()


def test_server_stopped_mid_episode_fails_fast_then_reconnects(expert):
    policy = SourcePolicy(expert)
    handle = PolicyServer(policy, port=0).start()
    src = RemoteSource(handle.url, config=FAST)
    port = handle.port
    try:
        src.plan(observation())
        handle.stop()
        with pytest.raises((ConnectionLost, ServerUnreachable)):
            src.plan(observation())
        for _ in range(3):
            t0 = time.perf_counter()
            with pytest.raises(ServerUnreachable, match="Connection refused"):
                src.plan(observation())
            assert time.perf_counter() - t0 < 0.5
        handle = PolicyServer(policy, port=port).start()  # back on the same port
        np.testing.assert_array_equal(src.plan(observation()).waypoints, expert.plan(observation()).waypoints)
    finally:
        src.close()
        handle.stop()


def test_a_restarted_server_serving_another_source_is_refused(expert):
    handle = PolicyServer(SourcePolicy(expert), port=0).start()
    src = RemoteSource(handle.url, config=FAST)
    port = handle.port
    handle.stop()
    other = make_expert(lead="none", horizon=8)
    handle = PolicyServer(SourcePolicy(other), port=port).start()
    try:
        with pytest.raises((ConnectionLost, ServerUnreachable)):
            src.plan(observation())  # the old connection is gone
        src.plan(observation())  # same metadata: the same declared source (horizon is not declared)
        handle.stop()
        handle = PolicyServer(SourcePolicy(make_expert(dt_s=0.05)), port=port).start()
        with pytest.raises((ConnectionLost, ServerUnreachable)):
            src.plan(observation())
        with pytest.raises(SourceError, match="other metadata"):
            src.plan(observation())
    finally:
        src.close()
        handle.stop()


def test_foreign_server_needs_a_mapping_and_an_action_space(scripted):
    _, handle = scripted
    with pytest.raises(SourceError, match="does not declare its convention.*also need --obs-mapping"):
        RemoteSource(handle.url, action_space=ActionSpace(), config=FAST)
    with pytest.raises(SourceError, match="does not declare its convention.*--obs-mapping also needs --action-space --gripper --chunk-dt-s"):
        RemoteSource(handle.url, mapping=STATE_ONLY, config=FAST)


def test_the_server_keeps_serving_other_connections_during_a_slow_call(scripted):
    policy, handle = scripted
    slow = PolicyClient(handle.url, FAST)
    policy.sleep_s, policy.mode = 0.6, "slow_once"
    done = []
    thread = threading.Thread(target=lambda: done.append(slow.infer({"request": "slow"})))
    thread.start()
    time.sleep(0.1)
    t0 = time.perf_counter()
    with urllib.request.urlopen(handle.healthz_url, timeout=5) as r:
        assert r.status == 200
    assert time.perf_counter() - t0 < 0.3  # the event loop is not blocked by the policy
    thread.join(5)
    assert done[0]["request"] == "slow"
    slow.close()


# ---- the serve CLI -----------------------------------------------------------------------------------------------
def test_serve_cli_one_line_errors(capsys):
    from scenarios.serve import main

    busy = socket.socket()
    busy.bind(("127.0.0.1", 0))
    busy.listen()
    cases = [(["--source", "expert", "--checkpoint", "x.pt"], "--checkpoint applies to --source policy only"),
             (["--checkpoint", "/nonexistent.pt"], "does not exist"),
             (["--source", "os.path:no_such_factory"], "no_such_factory"),
             (["--source", "policy", "--horizon", "4"], "--horizon applies to --source expert only"),
             (["--port", "70000"], "--port must be >= 0 and <= 65535"),
             (["--source", "expert", "--port", str(busy.getsockname()[1])], "address already in use")]
    try:
        for argv, match in cases:
            with pytest.raises(SystemExit) as exc:
                main(argv)
            err = capsys.readouterr().err
            assert exc.value.code == 2 and match in err and err.count("\n") == 1, (argv, err)
    finally:
        busy.close()


def test_serve_cli_serves_until_terminated():
    import signal

    root = str(__import__("pathlib").Path(__file__).parents[1])
    proc = subprocess.Popen([sys.executable, "-m", "scenarios.serve", "--source", "expert", "--expert-lead", "none",
                             "--port", "0"], cwd=root, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        banner = proc.stdout.readline()
        assert banner.startswith("serving scripted expert (lead none") and "ws://127.0.0.1:" in banner, banner
        url = banner.split(" at ")[1].split()[0]
        src = RemoteSource(url, config=FAST)
        obs = observation()
        np.testing.assert_array_equal(src.plan(obs).waypoints, make_expert(lead="none").plan(obs).waypoints)
        src.close()
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=30)
        assert proc.returncode == 0 and "stopped" in out, err
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()


def test_the_openpi_package_is_a_protocol_package_another_project_could_vendor(tmp_path):
    """Its files copied out under another name import and serve without anything else of this project."""
    import shutil

    src = __import__("pathlib").Path(__file__).parents[1] / "mmact_ctrl" / "sources" / "openpi"
    shutil.copytree(src, tmp_path / "vendored_openpi", ignore=shutil.ignore_patterns("__pycache__"))
    code = ("import sys, numpy as np, vendored_openpi as p, vendored_openpi.bench; "
            "h = p.PolicyServer(type('P', (), {'infer': lambda self, o: {'actions': np.zeros((2, 7))}})(), port=0).start(); "
            "c = p.PolicyClient(h.url); assert c.infer({'x': np.ones(3)})['actions'].shape == (2, 7); c.close(); h.stop(); "
            "bad = [m for m in sys.modules if m.split('.')[0] in ('mmact_ctrl', 'scenarios', 'controllers', 'policy', 'mujoco')]; "
            "assert not bad, bad")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=str(tmp_path))


# ---- end to end: an episode through a server ---------------------------------------------------------------------
def test_episodes_through_a_server_run_as_in_process():
    from controllers.robot_model import PandaModel
    from mmact_ctrl.config import StackConfig
    from mmact_ctrl.controller import HybridController
    from mmact_ctrl.loop import run_episode
    from scenarios.world.factory import make_world

    world = make_world("linear", 0.2, n_objects=1)
    model = PandaModel()
    expert = make_expert(lead="velocity", world=world)
    policy = ScriptedFailures(SourcePolicy(expert))
    handle = PolicyServer(policy, port=0).start()
    src = RemoteSource(handle.url, config=FAST)
    try:
        cfg = StackConfig(mode="open_loop", duration_s=1.5, replan_hz=4.0, latency_ms=100.0)
        local = run_episode(world, expert, HybridController(cfg, model=model), seed=3)
        remote = run_episode(world, src, HybridController(cfg, model=model), seed=3)
        assert sum(remote.rejections.values()) == 0 and len(remote.chunk_active_s) == len(local.chunk_active_s) >= 5
        np.testing.assert_array_equal(remote.tau_cmd_nm, local.tau_cmd_nm)  # the same chunks: the same episode
        hybrid = run_episode(world, src, HybridController(StackConfig(mode="hybrid", duration_s=1.5), model=model), seed=3)
        assert sum(hybrid.rejections.values()) == 0 and hybrid.chunk_active_s and hybrid.abort is None
        policy.fail_calls = {2, 3}  # the server errors on two queries: counted rejections, the episode goes on
        policy.calls = 0
        faulty = run_episode(world, src, HybridController(cfg, model=model), seed=3)
        assert faulty.rejections["source_raised"] == 2 and faulty.abort is None
        assert all("scripted server failure" in e[2] for e in faulty.events if e[1] == "source_raised")
    finally:
        src.close()
        handle.stop()
        world.close()


class ScriptedFailures:
    """Serves ``inner`` (an openpi policy) but raises on the call numbers in ``fail_calls`` (counted from 0)."""

    def __init__(self, inner) -> None:
        self.inner = inner
        self.metadata = inner.metadata
        self.fail_calls: set[int] = set()
        self.calls = 0

    def infer(self, obs: dict) -> dict:
        n, self.calls = self.calls, self.calls + 1
        if n in self.fail_calls:
            raise RuntimeError("scripted server failure")
        return self.inner.infer(obs)
