"""Write a LeRobotDataset v3.0 (``mmact_ctrl.datasets.layout``) episode by episode: the frames' columns in parquet
(pyarrow), each camera's frames in mp4 (PyAV), the metadata as LeRobot writes it. IO only: no MuJoCo, no stack.

    writer = LeRobotWriter(root, schema)
    for ep in episodes:
        writer.add_episode(ep)     # EpisodeData: task, camera frames, vector features
    writer.close()                 # info.json, stats.json, tasks.parquet, the episodes parquet, the data parquet
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mmact_ctrl.datasets import layout as L
from mmact_ctrl.datasets.stats import aggregate, image_stats, to_json, vector_stats
from mmact_ctrl.datasets.video import VideoSettings, VideoWriter, stream_info


def _pa():
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise RuntimeError("--format lerobot needs pyarrow: pip install -e '.[dataset]'") from None
    return pa, pq


@dataclass(frozen=True)
class VectorFeature:
    """A per-frame vector feature.

    Attributes:
        name: its key (``observation.state``, ``action``, or an extra that starts with neither).
        names: one name per dimension (units in the names).
        dtype: numpy dtype name of the stored values.
    """

    name: str
    names: tuple[str, ...]
    dtype: str = "float32"

    def __post_init__(self) -> None:
        L.check_feature_name(self.name)
        if not self.names:
            raise ValueError(f"feature {self.name!r} needs at least one dimension name")

    @property
    def dim(self) -> int:
        return len(self.names)

    def info(self) -> dict:
        return {"dtype": self.dtype, "shape": [self.dim], "names": list(self.names)}


@dataclass(frozen=True)
class DatasetSchema:
    """What every frame of the dataset holds.

    Attributes:
        fps: frames per second (an integer, as LeRobot's ``info.json`` has it).
        robot_type: the robot's name in ``info.json``.
        cameras: the camera names; each is the feature ``observation.images.<name>``.
        image_size_px: side of the square frames, px.
        vectors: the vector features (``observation.state`` and ``action`` first).
        video: how the frames are encoded.
    """

    fps: int
    robot_type: str
    cameras: tuple[str, ...]
    image_size_px: int
    vectors: tuple[VectorFeature, ...]
    video: VideoSettings | None = None

    def __post_init__(self) -> None:
        if not (isinstance(self.fps, int) and self.fps > 0):
            raise ValueError(f"fps must be a positive integer, got {self.fps!r}")
        keys = [v.name for v in self.vectors]
        for required in ("observation.state", "action"):
            if required not in keys:
                raise ValueError(f"a LeRobot dataset needs the feature {required!r}")
        for cam in self.cameras:
            L.check_feature_name(L.IMAGES_PREFIX + cam)
        if self.video is None:
            object.__setattr__(self, "video", VideoSettings(fps=self.fps))

    @property
    def camera_keys(self) -> tuple[str, ...]:
        return tuple(L.IMAGES_PREFIX + c for c in self.cameras)

    def features(self) -> dict:
        """``info.json``'s ``features`` without the cameras' ``info`` blocks (those are read from the files)."""
        out: dict = {}
        for key in self.camera_keys:
            out[key] = {"dtype": "video", "shape": [self.image_size_px, self.image_size_px, 3],
                        "names": ["height", "width", "channels"]}
        for v in self.vectors:
            out[v.name] = v.info()
        out.update({k: dict(v) for k, v in L.DEFAULT_FEATURES.items()})
        return out


@dataclass(frozen=True)
class EpisodeData:
    """One episode to write (``N`` frames).

    Attributes:
        task: its task (the language instruction).
        images: camera name -> ``(N, H, W, 3)`` uint8.
        vectors: feature name -> ``(N, D)``.
    """

    task: str
    images: dict[str, np.ndarray]
    vectors: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def length(self) -> int:
        return int(len(next(iter(self.vectors.values()))))


class LeRobotWriter:
    """Writes ``schema``'s episodes under ``root`` (which must not exist or be empty)."""

    def __init__(self, root: str | Path, schema: DatasetSchema) -> None:
        self.root = Path(root)
        if self.root.exists() and (not self.root.is_dir() or any(self.root.iterdir())):
            raise ValueError(f"--out {str(self.root)!r} exists and is not empty: a dataset is written into a new or "
                             "empty directory")
        _pa()
        self.schema = schema
        self.tasks: dict[str, int] = {}
        self.values: dict[str, list[np.ndarray]] = {v.name: [] for v in schema.vectors}  # for the exact stats
        self.episodes: list[dict] = []
        self.episode_stats: list[dict[str, dict]] = []
        self._videos: dict[str, VideoWriter] = {}
        self._video_files: dict[str, int] = {c: 0 for c in schema.cameras}
        self._data_file = 0
        self._data_writer = None  # pyarrow.parquet.ParquetWriter of the current data file
        self._frames = 0
        self._closed = False

    # ---- episodes ----------------------------------------------------------------------------------------------
    def add_episode(self, ep: EpisodeData) -> int:
        """Write one episode's frames; returns its index."""
        s = self.schema
        n = ep.length
        if n < 1:
            raise ValueError("an episode needs at least one frame")
        for v in s.vectors:
            arr = np.asarray(ep.vectors.get(v.name))
            if arr.ndim != 2 or arr.shape != (n, v.dim):
                raise ValueError(f"episode feature {v.name!r}: shape {arr.shape}, the schema says ({n}, {v.dim})")
        for cam in s.cameras:
            frames = ep.images.get(cam)
            if frames is None or frames.shape != (n, s.image_size_px, s.image_size_px, 3) or frames.dtype != np.uint8:
                got = None if frames is None else (frames.shape, str(frames.dtype))
                raise ValueError(f"episode camera {cam!r}: {got}, the schema says ({n}, {s.image_size_px}, "
                                 f"{s.image_size_px}, 3) uint8")
        index = len(self.episodes)
        task_index = self.tasks.setdefault(ep.task, len(self.tasks))
        start = self._frames
        defaults = {"timestamp": (np.arange(n) / s.fps).astype(np.float32), "frame_index": np.arange(n),
                    "episode_index": np.full(n, index), "index": np.arange(start, start + n),
                    "task_index": np.full(n, task_index)}
        vectors = {v.name: np.asarray(ep.vectors[v.name], dtype=v.dtype) for v in s.vectors}
        chunk, file = self._write_data(vectors, defaults)
        row = {"episode_index": index, "tasks": [ep.task], "length": n, "data/chunk_index": chunk,
               "data/file_index": file, "dataset_from_index": start, "dataset_to_index": start + n}
        stats: dict[str, dict] = {}
        for cam, key in zip(s.cameras, s.camera_keys):
            row.update(self._write_video(cam, key, ep.images[cam]))
            stats[key] = image_stats(ep.images[cam])
        for name, arr in vectors.items():
            self.values[name].append(arr)
            stats[name] = vector_stats(arr)
        for name, arr in defaults.items():
            stats[name] = vector_stats(arr)
        self.episode_stats.append(stats)
        for feat, st in stats.items():
            for name, value in st.items():
                row[f"stats/{feat}/{name}"] = np.asarray(value).tolist()
        row["meta/episodes/chunk_index"], row["meta/episodes/file_index"] = 0, 0
        self.episodes.append(row)
        self._frames += n
        return index

    def _write_data(self, vectors: dict[str, np.ndarray], defaults: dict[str, np.ndarray]) -> tuple[int, int]:
        """Append an episode's rows to the current data file as one row group (a new file once the current one
        is over ``DATA_FILES_SIZE_IN_MB``); returns its (chunk_index, file_index)."""
        pa, pq = _pa()
        if self._data_writer is not None and self._data_path().stat().st_size >= L.DATA_FILES_SIZE_IN_MB * 2 ** 20:
            self._data_writer.close()
            self._data_writer, self._data_file = None, self._data_file + 1
        cols = {}
        for v in self.schema.vectors:
            flat = pa.array(vectors[v.name].reshape(-1))
            cols[v.name] = pa.FixedSizeListArray.from_arrays(flat, v.dim)
        cols["timestamp"] = pa.array(defaults["timestamp"], pa.float32())
        for key in ("frame_index", "episode_index", "index", "task_index"):
            cols[key] = pa.array(defaults[key], pa.int64())
        table = pa.table(cols).replace_schema_metadata({b"huggingface": json.dumps(self._hf_features()).encode()})
        if self._data_writer is None:
            path = self._data_path()
            path.parent.mkdir(parents=True, exist_ok=True)
            self._data_writer = pq.ParquetWriter(path, table.schema, compression="snappy", use_dictionary=True)
        self._data_writer.write_table(table)
        return L.chunk_and_file(self._data_file)

    def _data_path(self) -> Path:
        chunk, file = L.chunk_and_file(self._data_file)
        return self.root / L.DATA_PATH.format(chunk_index=chunk, file_index=file)

    def _hf_features(self) -> dict:
        """The ``huggingface`` schema metadata HF ``datasets`` 4 writes (LeRobot loads with info.json's features
        whether or not it is there; other readers of the parquet use it)."""
        feats: dict = {}
        for v in self.schema.vectors:
            feats[v.name] = {"feature": {"dtype": v.dtype, "_type": "Value"}, "length": v.dim, "_type": "List"}
        for key, f in L.DEFAULT_FEATURES.items():
            feats[key] = {"dtype": f["dtype"], "_type": "Value"}
        return {"info": {"features": feats}}

    def _write_video(self, cam: str, key: str, frames: np.ndarray) -> dict:
        """Append an episode's frames to the camera's current file (a new file once it is over the size limit)."""
        s = self.schema
        w = self._videos.get(cam)
        if w is not None and w.path.stat().st_size > L.VIDEO_FILES_SIZE_IN_MB * 1024 * 1024:
            w.close()
            self._video_files[cam] += 1
            w = None
        chunk, file = L.chunk_and_file(self._video_files[cam])
        if w is None:
            path = self.root / L.VIDEO_PATH.format(video_key=key, chunk_index=chunk, file_index=file)
            w = self._videos[cam] = VideoWriter(path, s.image_size_px, s.image_size_px, s.video)
        first = w.frames
        for frame in frames:
            w.append(frame)
        # whole frames over fps: never a running float sum (LeRobot issue #3177)
        return {f"videos/{key}/chunk_index": chunk, f"videos/{key}/file_index": file,
                f"videos/{key}/from_timestamp": first / s.fps, f"videos/{key}/to_timestamp": (first + len(frames)) / s.fps}

    # ---- the files ---------------------------------------------------------------------------------------------
    def close(self) -> dict:
        """Finish the videos and write the parquet files and the metadata; returns ``info.json``'s content."""
        if self._closed:
            raise RuntimeError("the dataset is closed already")
        self._closed = True
        if not self.episodes:
            raise ValueError("no episode was added: nothing to write")
        for w in self._videos.values():
            w.close()
        self._data_writer.close()
        self._write_tasks()
        self._write_episodes()
        # the vectors' stats from the pooled frames (exact quantiles); the cameras' pooled from the episodes' samples
        stats = {feat: aggregate([st[feat] for st in self.episode_stats]) for feat in self.episode_stats[0]}
        for name, arrays in self.values.items():
            stats[name] = vector_stats(np.concatenate(arrays))
        (self.root / L.STATS_PATH).write_text(json.dumps(to_json(stats), indent=4))
        info = self._info()
        (self.root / L.INFO_PATH).write_text(json.dumps(info, indent=4))
        return info

    def _write_tasks(self) -> None:
        pa, pq = _pa()
        tasks = sorted(self.tasks.items(), key=lambda kv: kv[1])
        table = pa.table({"task_index": pa.array([i for _, i in tasks], pa.int64()),
                          "task": pa.array([t for t, _ in tasks], pa.string())})
        # pandas' index: the task string (LeRobot reads the file with pandas and looks tasks up by the index)
        meta = {b"pandas": json.dumps({"index_columns": ["task"], "column_indexes": [], "columns": [
            {"name": "task_index", "field_name": "task_index", "pandas_type": "int64", "numpy_type": "int64",
             "metadata": None},
            {"name": "task", "field_name": "task", "pandas_type": "unicode", "numpy_type": "object",
             "metadata": None}], "creator": {"library": "pyarrow", "version": pa.__version__},
            "pandas_version": "2.2.3"}).encode()}
        path = self.root / L.TASKS_PATH
        path.parent.mkdir(parents=True, exist_ok=True)
        pq.write_table(table.replace_schema_metadata(meta), path)

    def _write_episodes(self) -> None:
        pa, pq = _pa()
        keys = list(self.episodes[0])
        table = pa.table({k: [e[k] for e in self.episodes] for k in keys})
        path = self.root / L.EPISODES_PATH.format(chunk_index=0, file_index=0)
        path.parent.mkdir(parents=True, exist_ok=True)
        pq.write_table(table, path)

    def _info(self) -> dict:
        s = self.schema
        features = s.features()
        for cam, key in zip(s.cameras, s.camera_keys):
            path = self.root / L.VIDEO_PATH.format(video_key=key, chunk_index=0, file_index=0)
            features[key]["info"] = {**stream_info(path), **s.video.info()}
        n_eps = len(self.episodes)
        # the keys in the order LeRobot's DatasetInfo.to_dict writes them
        return {"codebase_version": L.CODEBASE_VERSION, "fps": s.fps, "features": features, "total_episodes": n_eps,
                "total_frames": self._frames, "total_tasks": len(self.tasks), "chunks_size": L.CHUNKS_SIZE,
                "data_files_size_in_mb": L.DATA_FILES_SIZE_IN_MB, "video_files_size_in_mb": L.VIDEO_FILES_SIZE_IN_MB,
                "data_path": L.DATA_PATH, "video_path": L.VIDEO_PATH, "robot_type": s.robot_type,
                "splits": {"train": f"0:{n_eps}"}}
