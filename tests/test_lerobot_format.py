"""The LeRobot v3.0 writer without the simulator: the layout against the specification (keys, columns, dtypes,
indices), the stats against numpy on the same data, the video round trip and its timestamps, the frame actions."""

import json

import numpy as np
import pytest

import pyarrow as pa  # a dependency of the dev set-up (lerobot-doctor brings it): never skipped
import pyarrow.parquet as pq  # noqa: E402

from mmact_ctrl.datasets import layout as L  # noqa: E402
from mmact_ctrl.datasets.frame_actions import ChunkActivation, chunk_value_at, frame_actions, slerp_rotvec  # noqa: E402
from mmact_ctrl.datasets.reader import LeRobotDataset  # noqa: E402
from mmact_ctrl.datasets.roundtrip import check_indices, round_trip  # noqa: E402
from mmact_ctrl.datasets.stats import sample_indices  # noqa: E402
from mmact_ctrl.datasets.video import VideoSettings  # noqa: E402
from mmact_ctrl.datasets.writer import DatasetSchema, EpisodeData, LeRobotWriter, VectorFeature  # noqa: E402

FPS = 10
SIZE = 32


def _frames(rng, n, shift):
    """Smooth frames that change from one to the next (a codec's easy case, as renders are)."""
    x = np.linspace(0, np.pi, SIZE)
    base = 127 + 60 * np.sin(x[None, :, None] + x[:, None, None] * 0.5 + 0.3 * np.arange(3) + shift)
    return np.stack([np.clip(base + 3 * k + rng.normal(0, 0.5, base.shape), 0, 255).astype(np.uint8)
                     for k in range(n)])


def _schema(cameras=("front", "side"), pix_fmt="yuv444p"):
    return DatasetSchema(fps=FPS, robot_type="franka_panda", cameras=cameras, image_size_px=SIZE,
                         video=VideoSettings(fps=FPS, pix_fmt=pix_fmt),
                         vectors=(VectorFeature("observation.state", tuple(f"q{i}" for i in range(8))),
                                  VectorFeature("action", tuple(f"a{i}" for i in range(7))),
                                  VectorFeature("target_pos_m", ("x_m", "y_m", "z_m"))))


def _write(root, lengths, seed=0, cameras=("front", "side"), pix_fmt="yuv444p"):
    rng = np.random.default_rng(seed)
    writer = LeRobotWriter(root, _schema(cameras, pix_fmt))
    episodes = []
    for i, n in enumerate(lengths):
        ep = EpisodeData(task=f"task {i % 3}", images={c: _frames(rng, n, j + i) for j, c in enumerate(cameras)},
                         vectors={"observation.state": rng.normal(size=(n, 8)).astype(np.float32),
                                  "action": rng.normal(size=(n, 7)).astype(np.float32),
                                  "target_pos_m": rng.uniform(size=(n, 3)).astype(np.float32)})
        writer.add_episode(ep)
        episodes.append(ep)
    info = writer.close()
    return info, episodes


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    root = tmp_path_factory.mktemp("ds") / "out"
    info, episodes = _write(root, [12, 7, 15, 9])
    return root, info, episodes


def test_info_json_has_every_key_of_the_specification(written):
    root, info, _ = written
    on_disk = json.loads((root / L.INFO_PATH).read_text())
    assert on_disk == info
    for key in ("codebase_version", "fps", "features", "total_episodes", "total_frames", "total_tasks", "chunks_size",
                "data_files_size_in_mb", "video_files_size_in_mb", "data_path", "video_path", "robot_type", "splits"):
        assert key in on_disk, key
    assert on_disk["codebase_version"] == "v3.0" and on_disk["fps"] == FPS and isinstance(on_disk["fps"], int)
    assert on_disk["total_episodes"] == 4 and on_disk["total_frames"] == 12 + 7 + 15 + 9 and on_disk["total_tasks"] == 3
    assert on_disk["splits"] == {"train": "0:4"}
    assert on_disk["data_path"] == "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
    assert on_disk["video_path"] == "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
    f = on_disk["features"]
    cam = f["observation.images.front"]
    assert cam["dtype"] == "video" and cam["shape"] == [SIZE, SIZE, 3] and cam["names"] == ["height", "width", "channels"]
    assert cam["info"]["video.codec"] == "h264" and cam["info"]["video.fps"] == FPS
    assert cam["info"]["video.pix_fmt"] == "yuv444p" and cam["info"]["video.height"] == SIZE
    assert f["observation.state"] == {"dtype": "float32", "shape": [8], "names": [f"q{i}" for i in range(8)]}
    assert list(f)[-5:] == ["timestamp", "frame_index", "episode_index", "index", "task_index"]
    assert f["timestamp"]["dtype"] == "float32" and f["index"]["dtype"] == "int64"
    assert not [k for k in f if "/" in k]


def test_data_parquet_columns_dtypes_and_indices(written):
    root, info, episodes = written
    table = pq.read_table(root / "data/chunk-000/file-000.parquet")
    assert table.column_names == ["observation.state", "action", "target_pos_m", "timestamp", "frame_index",
                                  "episode_index", "index", "task_index"]  # info's order, the videos left out
    t = table.schema
    assert t.field("observation.state").type == pa.list_(pa.float32(), 8)  # HF datasets' List(length=8)
    assert t.field("timestamp").type == pa.float32()
    for col in ("frame_index", "episode_index", "index", "task_index"):
        assert t.field(col).type == pa.int64()
    assert json.loads(t.metadata[b"huggingface"])["info"]["features"]["action"]["length"] == 7
    assert table.column("index").to_pylist() == list(range(info["total_frames"]))
    ds = LeRobotDataset.open(root)
    assert check_indices(ds) == (True, True)
    ep2 = ds.values(2, "action")
    np.testing.assert_array_equal(ep2, episodes[2].vectors["action"].astype(np.float64))
    assert pq.ParquetFile(root / "data/chunk-000/file-000.parquet").num_row_groups == 4  # one per episode


def test_episodes_parquet_ranges_and_video_timestamps(written):
    root, info, episodes = written
    table = pq.read_table(root / "meta/episodes/chunk-000/file-000.parquet")
    names = table.column_names
    assert names[:7] == ["episode_index", "tasks", "length", "data/chunk_index", "data/file_index",
                         "dataset_from_index", "dataset_to_index"]
    assert names[-2:] == ["meta/episodes/chunk_index", "meta/episodes/file_index"]
    assert table.schema.field("tasks").type == pa.list_(pa.string())
    assert table.schema.field("stats/action/count").type == pa.list_(pa.int64())
    rows = table.to_pylist()
    assert [r["episode_index"] for r in rows] == [0, 1, 2, 3]
    start = 0
    for r, ep in zip(rows, episodes):
        assert (r["dataset_from_index"], r["dataset_to_index"], r["length"]) == (start, start + ep.length, ep.length)
        for key in ("observation.images.front", "observation.images.side"):
            # whole frames over fps, not a running float sum
            assert r[f"videos/{key}/from_timestamp"] == start / FPS
            assert r[f"videos/{key}/to_timestamp"] == (start + ep.length) / FPS
        assert r["tasks"] == [ep.task]
        start += ep.length


def test_tasks_parquet_is_indexed_by_the_task_string(written):
    root, _, _ = written
    table = pq.read_table(root / L.TASKS_PATH)
    assert table.column("task_index").to_pylist() == [0, 1, 2]
    assert table.column("task").to_pylist() == ["task 0", "task 1", "task 2"]
    pandas_meta = json.loads(table.schema.metadata[b"pandas"])
    assert pandas_meta["index_columns"] == ["task"]  # pandas reads it back with the task string as the index


def test_stats_equal_numpy_on_the_same_data(written):
    root, _, episodes = written
    stats = json.loads((root / L.STATS_PATH).read_text())
    for feature in ("observation.state", "action", "target_pos_m"):
        x = np.concatenate([ep.vectors[feature] for ep in episodes]).astype(np.float64)
        s = stats[feature]
        np.testing.assert_allclose(s["min"], x.min(0), rtol=0, atol=1e-12)
        np.testing.assert_allclose(s["max"], x.max(0), rtol=0, atol=1e-12)
        np.testing.assert_allclose(s["mean"], x.mean(0), rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(s["std"], x.std(0), rtol=1e-9)
        assert s["count"] == [len(x)]
        for key, q in (("q01", 0.01), ("q10", 0.10), ("q50", 0.50), ("q90", 0.90), ("q99", 0.99)):
            np.testing.assert_allclose(s[key], np.quantile(x, q, axis=0), rtol=1e-12, atol=1e-12)
    # a camera: per channel, pixels in [0, 1], shape (3, 1, 1), over the frames sampled from each episode
    px = np.concatenate([ep.images["side"][sample_indices(ep.length)].reshape(-1, 3) for ep in episodes]) / 255.0
    s = stats["observation.images.side"]
    assert np.asarray(s["mean"]).shape == (3, 1, 1)
    np.testing.assert_allclose(np.asarray(s["mean"]).ravel(), px.mean(0), rtol=1e-9)
    np.testing.assert_allclose(np.asarray(s["std"]).ravel(), px.std(0), rtol=1e-9)
    np.testing.assert_allclose(np.asarray(s["min"]).ravel(), px.min(0))
    np.testing.assert_allclose(np.asarray(s["max"]).ravel(), px.max(0))
    assert 0.0 <= np.min(s["min"]) and np.max(s["max"]) <= 1.0
    for feature in ("timestamp", "frame_index", "episode_index", "index", "task_index"):
        assert set(stats[feature]) == set(L.STAT_NAMES)


def test_every_frame_reads_back_at_its_timestamp(written):
    root, _, episodes = written
    rt = round_trip(LeRobotDataset.open(root), lambda ep, key: episodes[ep].images[key.split(".")[-1]])
    assert rt.frames == 2 * sum(ep.length for ep in episodes) and rt.frames_missing == 0
    assert rt.timestamp_error_max_s < 1e-6 and rt.psnr_min_db >= 35.0 and rt.ok()


def test_yuv420p_is_written_and_read_back_too(tmp_path):
    info, episodes = _write(tmp_path / "420", [6, 5], cameras=("front",), pix_fmt="yuv420p")
    assert info["features"]["observation.images.front"]["info"]["video.pix_fmt"] == "yuv420p"
    rt = round_trip(LeRobotDataset.open(tmp_path / "420"), lambda ep, key: episodes[ep].images["front"])
    assert rt.frames == 11 and rt.frames_missing == 0 and rt.psnr_min_db > 30.0


def test_a_changed_frame_fails_the_round_trip(written):
    root, _, episodes = written
    ds = LeRobotDataset.open(root)

    def wrong(ep, key):  # episode 1 compared with episode 2's frames: not what was written
        return episodes[2 if ep == 1 else ep].images[key.split(".")[-1]][: episodes[ep].length]

    assert not round_trip(ds, wrong).ok()


def test_timestamps_do_not_drift_over_many_episodes(tmp_path):
    """LeRobot issue #3177: a running float sum of durations drifts past 1e-4 s after ~30 episodes in one file."""
    lengths = [int(n) for n in np.random.default_rng(3).integers(3, 8, size=40)]
    info, episodes = _write(tmp_path / "many", lengths, cameras=("front",))
    ds = LeRobotDataset.open(tmp_path / "many")
    last = ds.episodes[-1]
    assert last["videos/observation.images.front/from_timestamp"] == sum(lengths[:-1]) / FPS
    rt = round_trip(ds, lambda ep, key: episodes[ep].images["front"])
    assert rt.frames_missing == 0 and rt.timestamp_error_max_s < 1e-6


def test_a_non_empty_out_is_refused(tmp_path):
    (tmp_path / "x").write_text("mine")
    with pytest.raises(ValueError, match="exists and is not empty"):
        LeRobotWriter(tmp_path, _schema())


def test_a_feature_name_with_a_slash_is_refused():
    with pytest.raises(ValueError, match="contain no '/'"):
        VectorFeature("observation/state", ("a",))


def test_frame_actions_at_the_waypoints_rate_are_the_waypoints():
    w = np.zeros((4, 7))
    w[:, 0] = [0.1, 0.2, 0.3, 0.4]
    w[:, 6] = 0.08
    chunk = ChunkActivation(t_active_s=0.2, times_s=np.array([0.1, 0.2, 0.3, 0.4]), waypoints=w)
    hold = np.full(7, -1.0)
    a = frame_actions([chunk], hold, n_frames=6, fps=10)
    np.testing.assert_array_equal(a[0], hold)  # nothing active before 0.2 s: the start pose is held
    np.testing.assert_array_equal(a[1], hold)
    np.testing.assert_allclose(a[2:5, 0], [0.3, 0.4, 0.4])  # frame m: the value for (m + 1) / fps; the last held
    a20 = frame_actions([chunk], hold, n_frames=8, fps=20)
    np.testing.assert_allclose(a20[4:7, 0], [0.25, 0.3, 0.35])  # interpolated between waypoints


def test_slerp_takes_the_shortest_arc_at_constant_rate():
    a = np.array([0.0, 0.0, 0.2])
    b = np.array([0.0, 0.0, 0.8])
    np.testing.assert_allclose(slerp_rotvec(a, b, 0.5), [0, 0, 0.5], atol=1e-12)
    # about two axes: the midpoint is equally far (in angle) from both ends
    a, b = np.array([0.6, 0.0, 0.0]), np.array([0.0, 0.6, 0.0])
    import pinocchio as pin

    m = slerp_rotvec(a, b, 0.5)
    d = lambda x, y: np.linalg.norm(pin.log3(pin.exp3(x) @ pin.exp3(y).T))  # noqa: E731
    assert d(a, m) == pytest.approx(d(m, b), rel=1e-9) and d(a, m) == pytest.approx(d(a, b) / 2, rel=1e-9)
    chunk = ChunkActivation(0.0, np.array([0.1, 0.2]), np.array([[0, 0, 0, *a, 0.0], [0, 0, 0, *b, 0.0]]))
    np.testing.assert_allclose(chunk_value_at(chunk, 0.15)[3:6], m, atol=1e-12)
