"""The one-screen summary of a LeRobot dataset (ours or anyone's), and a Rerun recording of one of its episodes, as
LeRobot's own dataset viewer shows one: ``python -m scenarios.collect --format lerobot --show DIR [--rerun PATH.rrd
--episode N]``."""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import numpy as np

from mmact_ctrl.datasets.reader import LeRobotDataset

MMACT_META = "meta/mmact.json"


def show(root: str | Path, rerun: str | None = None, episode: int = 0) -> str:
    """The summary (and, with ``rerun``, the recording of ``episode`` written there)."""
    ds = LeRobotDataset.open(root)
    info = ds.info
    lines = [f"LeRobot dataset {ds.root}  ({info['codebase_version']}, robot {info.get('robot_type')})",
             f"  episodes {info['total_episodes']}, frames {info['total_frames']}, fps {info['fps']} "
             f"({info['total_frames'] / max(info['fps'], 1):.1f} s), tasks {info['total_tasks']}",
             "  features:"]
    for name, f in info["features"].items():
        names = f.get("names")
        what = (f"{f['info'].get('video.codec')} {f['info'].get('video.pix_fmt')}" if f["dtype"] == "video"
                else ", ".join(names) if isinstance(names, list) and len(names) <= 8 else "")
        lines.append(f"    {name:<32} {f['dtype']:<8} {str(list(f['shape'])):<14} {what}")
    counts = Counter(t for row in ds.episodes for t in row["tasks"])
    lines.append("  tasks:")
    for task, n in counts.most_common(6):
        lines.append(f"    {n:>4} x {task}")
    if len(counts) > 6:
        lines.append(f"    ... and {len(counts) - 6} more")
    meta_path = ds.root / MMACT_META
    if meta_path.is_file():
        meta = json.loads(meta_path.read_text())
        eps = meta.get("episodes", [])
        if eps:
            ok = sum(e["success"] for e in eps)
            err = np.median([e["final_error_m"] for e in eps]) * 1e3
            lines.append(f"  success {ok}/{len(eps)} ({ok / len(eps):.0%}), median final error {err:.1f} mm "
                         f"(meta/mmact.json; made by: {meta.get('command', '?')})")
    else:
        lines.append("  success: not recorded (no meta/mmact.json: not one of our exports)")
    if rerun:
        from scenarios.lerobot_rerun import write_episode_recording

        path = write_episode_recording(ds, episode, rerun)
        lines.append(f"  wrote the Rerun recording of episode {episode} to {path} (view it with: rerun {path})")
    return "\n".join(lines)
