"""The round trip of a written dataset: every frame read back with PyAV at ``from_timestamp + timestamp`` is the
frame that was rendered (PSNR over the codec's loss), every timestamp is ``frame_index / fps``, every index range is
contiguous. The rendered frames come from the caller (``scenarios.collect --format lerobot --verify`` keeps them
while it writes).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from mmact_ctrl.datasets.reader import LeRobotDataset
from mmact_ctrl.datasets.video import psnr_db, read_frames

#: LeRobot's decoder tolerance between a query time and the frame it finds, s
TOLERANCE_S = 1e-4


@dataclass(frozen=True)
class RoundTrip:
    """What the round trip found.

    Attributes:
        frames: camera frames compared.
        psnr_min_db, psnr_median_db: over those frames.
        timestamp_error_max_s: the largest distance between a frame's query time and the decoded frame's time.
        frames_missing: query times with no decoded frame within ``TOLERANCE_S``.
        timestamps_exact: every ``timestamp`` equals ``float32(frame_index / fps)``.
        index_contiguous: ``index`` is 0 .. N-1 in order, and each episode's rows are its
            ``[dataset_from_index, dataset_to_index)``, the episodes one after another.
    """

    frames: int
    psnr_min_db: float
    psnr_median_db: float
    timestamp_error_max_s: float
    frames_missing: int
    timestamps_exact: bool
    index_contiguous: bool

    def ok(self, psnr_floor_db: float = 35.0) -> bool:
        return (self.frames_missing == 0 and self.timestamps_exact and self.index_contiguous
                and self.psnr_min_db >= psnr_floor_db and self.timestamp_error_max_s <= TOLERANCE_S)


def check_indices(ds: LeRobotDataset) -> tuple[bool, bool]:
    """(timestamps exact, indices contiguous) over every data row of ``ds``."""
    exact, contiguous, expected_start = True, True, 0
    for row in ds.episodes:
        table = ds.frames_table(int(row["episode_index"]))
        idx = np.asarray(table.column("index").to_numpy())
        fi = np.asarray(table.column("frame_index").to_numpy())
        ts = np.asarray(table.column("timestamp").to_numpy())
        n = int(row["length"])
        contiguous &= (row["dataset_from_index"] == expected_start and row["dataset_to_index"] == expected_start + n
                       and len(idx) == n and np.array_equal(idx, np.arange(expected_start, expected_start + n))
                       and np.array_equal(fi, np.arange(n)))
        exact &= bool(np.array_equal(ts.astype(np.float32), (np.arange(n) / ds.fps).astype(np.float32)))
        expected_start += n
    return bool(exact), bool(contiguous)


def round_trip(ds: LeRobotDataset, rendered: Callable[[int, str], np.ndarray]) -> RoundTrip:
    """Compare every camera frame of ``ds`` with ``rendered(episode_index, camera_key) -> (N, H, W, 3)``."""
    psnrs, worst_dt, missing = [], 0.0, 0
    decoded: dict = {}
    for row in ds.episodes:
        ep = int(row["episode_index"])
        ts = np.asarray(ds.frames_table(ep).column("timestamp").to_numpy(), dtype=np.float64)
        for key in ds.camera_keys:
            path = ds.video_path(row, key)
            if path not in decoded:
                decoded = {path: read_frames(path)}  # one file at a time: the episodes of a file are in order
            times, frames = decoded[path]
            original = rendered(ep, key)
            for t, image in zip(row[f"videos/{key}/from_timestamp"] + ts, original):
                j = int(np.argmin(np.abs(times - t)))
                dt = abs(float(times[j]) - t)
                worst_dt = max(worst_dt, dt)
                if dt > TOLERANCE_S:
                    missing += 1
                    continue
                psnrs.append(psnr_db(frames[j], image))
    exact, contiguous = check_indices(ds)
    finite = np.array([p for p in psnrs if np.isfinite(p)] or [float("inf")])
    return RoundTrip(frames=len(psnrs), psnr_min_db=float(min(psnrs)) if psnrs else float("nan"),
                     psnr_median_db=float(np.median(finite)), timestamp_error_max_s=worst_dt, frames_missing=missing,
                     timestamps_exact=exact, index_contiguous=contiguous)
