"""Read a LeRobotDataset v3.0 back (ours or anyone's) with pyarrow: the schema, the episodes, a feature's values of
one episode, the tasks. IO only."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mmact_ctrl.datasets import layout as L
from mmact_ctrl.datasets.writer import _pa


@dataclass(frozen=True)
class LeRobotDataset:
    """A dataset on disk.

    Attributes:
        root: its directory.
        info: ``meta/info.json``.
        episodes: the episodes parquet's rows (dicts), by episode index.
        tasks: task index -> task string.
    """

    root: Path
    info: dict
    episodes: tuple[dict, ...]
    tasks: dict[int, str]

    @classmethod
    def open(cls, root: str | Path) -> LeRobotDataset:
        """The dataset at ``root`` (one line naming what is missing or not v3.0)."""
        pa, pq = _pa()
        root = Path(root)
        info_path = root / L.INFO_PATH
        if not info_path.is_file():
            raise FileNotFoundError(f"{str(root)!r} is not a LeRobot dataset: no {L.INFO_PATH}")
        info = json.loads(info_path.read_text())
        version = info.get("codebase_version")
        if version != L.CODEBASE_VERSION:
            raise ValueError(f"{str(root)!r}: codebase_version {version!r}, this reader reads {L.CODEBASE_VERSION!r}")
        files = sorted((root / "meta" / "episodes").glob("chunk-*/file-*.parquet"))
        if not files:
            raise FileNotFoundError(f"{str(root)!r}: no episodes parquet under meta/episodes/")
        rows = [r for f in files for r in pq.read_table(f).to_pylist()]
        rows.sort(key=lambda r: r["episode_index"])
        tasks_table = pq.read_table(root / L.TASKS_PATH)
        names = tasks_table.column_names
        text_col = "task" if "task" in names else "__index_level_0__"
        tasks = dict(zip(tasks_table.column("task_index").to_pylist(), tasks_table.column(text_col).to_pylist()))
        return cls(root=root, info=info, episodes=tuple(rows), tasks=tasks)

    @property
    def fps(self) -> int:
        return int(self.info["fps"])

    @property
    def features(self) -> dict:
        return self.info["features"]

    @property
    def camera_keys(self) -> tuple[str, ...]:
        return tuple(k for k, f in self.features.items() if f.get("dtype") == "video")

    def episode(self, index: int) -> dict:
        """The episodes parquet's row of episode ``index`` (one line if there is none)."""
        for row in self.episodes:
            if row["episode_index"] == index:
                return row
        raise ValueError(f"{str(self.root)!r} has no episode {index} (episodes 0 .. {len(self.episodes) - 1})")

    def data_path(self, row: dict) -> Path:
        return self.root / self.info["data_path"].format(chunk_index=row["data/chunk_index"],
                                                        file_index=row["data/file_index"])

    def video_path(self, row: dict, key: str) -> Path:
        return self.root / self.info["video_path"].format(video_key=key, chunk_index=row[f"videos/{key}/chunk_index"],
                                                         file_index=row[f"videos/{key}/file_index"])

    def frames_table(self, index: int):
        """The data parquet's rows of episode ``index`` (a pyarrow table in frame order)."""
        pa, pq = _pa()
        import pyarrow.compute as pc

        row = self.episode(index)
        table = pq.read_table(self.data_path(row))
        table = table.filter(pc.equal(table["episode_index"], index))
        return table.sort_by("frame_index")

    def values(self, index: int, feature: str) -> np.ndarray:
        """Episode ``index``'s ``feature`` as ``(N, D)`` (``(N,)`` for a scalar column)."""
        table = self.frames_table(index)
        if feature not in table.column_names:
            raise ValueError(f"{str(self.root)!r} has no feature {feature!r} (it has {', '.join(table.column_names)})")
        pa, _ = _pa()
        col = table.column(feature).combine_chunks()
        if pa.types.is_fixed_size_list(col.type) or pa.types.is_list(col.type) or pa.types.is_large_list(col.type):
            rows = col.to_pylist()  # a list column of anyone's writer: equal lengths, or one line
            lengths = {len(r) for r in rows}
            if len(lengths) > 1:
                raise ValueError(f"{str(self.root)!r}: feature {feature!r} has rows of lengths {sorted(lengths)}")
            return np.asarray(rows, dtype=np.float64).reshape(len(rows), -1)
        return np.asarray(col.to_numpy(zero_copy_only=False))
