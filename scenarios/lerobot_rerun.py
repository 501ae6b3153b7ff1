"""A Rerun recording of one episode of a LeRobot dataset, as LeRobot's own dataset viewer shows one: each camera's
frames as decoded from the mp4 (at ``from_timestamp + timestamp``), every dimension of ``observation.state`` and
``action`` as a time series, the true target as a 3-D point when the dataset has it; on the ``frame_index`` and
``timestamp`` timelines. View it with ``rerun PATH.rrd`` (rerun-sdk: ``pip install -e ".[viz]"``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mmact_ctrl.datasets.reader import LeRobotDataset
from mmact_ctrl.datasets.video import read_frames
from mmact_ctrl.recording import _rerun


def write_episode_recording(ds: LeRobotDataset, episode: int, path: str | Path) -> Path:
    """Write episode ``episode`` of ``ds`` to the Rerun file ``path``."""
    rr = _rerun()
    row = ds.episode(episode)
    table = ds.frames_table(episode)
    ts = np.asarray(table.column("timestamp").to_numpy(), dtype=float)
    frame_index = np.asarray(table.column("frame_index").to_numpy())
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    rec = rr.RecordingStream("mmact_ctrl_dataset")
    rec.save(str(path))
    base = f"episode_{episode}"
    indexes = [rr.TimeColumn("frame_index", sequence=frame_index), rr.TimeColumn("timestamp", duration=ts)]
    for feature in ("observation.state", "action"):
        values = ds.values(episode, feature)
        names = ds.features[feature].get("names") or [str(i) for i in range(values.shape[1])]
        for d, name in enumerate(names):
            rec.send_columns(f"{base}/{feature}/{name}", indexes=indexes,
                             columns=rr.Scalars.columns(scalars=values[:, d]))
    if "target_pos_m" in ds.features:
        target = ds.values(episode, "target_pos_m")
        for i in range(len(ts)):
            rec.set_time("frame_index", sequence=int(frame_index[i]))
            rec.set_time("timestamp", duration=float(ts[i]))
            rec.log(f"{base}/world/target", rr.Points3D([target[i]], radii=0.02, colors=[(230, 50, 50)]))
    for key in ds.camera_keys:
        times, frames = read_frames(ds.video_path(row, key))
        for i, t in enumerate(row[f"videos/{key}/from_timestamp"] + ts):
            j = int(np.argmin(np.abs(times - t)))
            rec.set_time("frame_index", sequence=int(frame_index[i]))
            rec.set_time("timestamp", duration=float(ts[i]))
            rec.log(f"{base}/{key}", rr.Image(frames[j]))
    rec.flush()
    rec.disconnect()
    return path
