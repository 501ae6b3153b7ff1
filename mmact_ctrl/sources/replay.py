"""``--source lerobot:DIR[:episode]``: a LeRobot dataset's recorded actions replayed through the stack as chunks, so
that a user can check that a dataset (ours, or anyone's of the same robot conventions) means what it says.

Each episode of the run replays one episode of the dataset: the one named (``DIR:3``), or the dataset's episodes in
order (``DIR``: the run's first episode replays the dataset's first, and so on, wrapping around). A query at
``t0`` answers the recorded actions from the frame at ``t0`` to the episode's end, ``1 / fps`` apart: frame ``m``'s
action is meant for ``(m + 1) / fps`` (``mmact_ctrl.datasets.frame_actions``), which is where a chunk's waypoint
``i`` asked at ``m / fps`` falls. So the executed reference is the recorded one whatever the replan rate and the
latency.

The action's meaning comes from ``info.json``'s names: ours (``scenarios.collect --format lerobot``) are
``tcp_pose`` (``x_m, y_m, z_m, rx_rad, ry_rad, rz_rad, gripper_m``) and ``joint_pos`` (``panda_joint1_rad ..
panda_joint7_rad, gripper_m``); a dataset whose action names are neither is refused in one line: replaying actions
of unknown meaning would be the silent garbage a convention misread is.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mmact_ctrl.chunk import Observation
from mmact_ctrl.datasets.conventions import action_space_of
from mmact_ctrl.datasets.reader import LeRobotDataset
from mmact_ctrl.sources.contract import SourceError

PREFIX = "lerobot:"


def is_replay_spec(spec: str) -> bool:
    return spec.startswith(PREFIX)


def parse_replay_spec(spec: str) -> tuple[Path, int | None]:
    """``lerobot:DIR[:episode]`` -> (DIR, the episode or None) (one line if it is not that)."""
    body = spec[len(PREFIX):]
    if not body:
        raise SourceError(f"--source {spec!r}: lerobot:DIR[:episode] needs the dataset's directory")
    head, sep, tail = body.rpartition(":")
    if sep and tail.isdigit():
        return Path(head), int(tail)
    return Path(body), None


class LeRobotReplay:
    """The chunk source that replays a dataset's actions (see the module). ``action_space`` says what they are, so
    :func:`~mmact_ctrl.sources.loader.wrap_source` adapts them (a joint space through forward kinematics)."""

    needs_image = False

    def __init__(self, root: str | Path, episode: int | None = None) -> None:
        try:
            self.dataset = ds = LeRobotDataset.open(root)
        except (FileNotFoundError, ValueError, RuntimeError) as exc:
            raise SourceError(f"--source lerobot:{root}: {exc}") from None
        try:
            self.action_space = action_space_of(ds.info, f"--source lerobot:{root}")
        except ValueError as exc:
            raise SourceError(str(exc)) from None
        self.fps = ds.fps
        available = [int(r["episode_index"]) for r in ds.episodes]
        if episode is not None and episode not in available:
            raise SourceError(f"--source lerobot:{root}:{episode}: no such episode (it has {len(available)}: "
                              f"0 .. {available[-1]})")
        self.order = [episode] if episode is not None else available
        self.name = f"lerobot:{root}" + ("" if episode is None else f":{episode}")
        self._next = 0
        self._actions: np.ndarray | None = None
        self.episode_index: int | None = None

    def reset(self) -> None:
        """The run's next episode replays the next recorded one."""
        self._load(self.order[self._next % len(self.order)])
        self._next += 1

    def _load(self, index: int) -> None:
        self.episode_index = index
        self._actions = self.dataset.values(index, "action").astype(np.float64)

    def plan(self, observation: Observation) -> np.ndarray:
        """The recorded actions from the frame at ``observation.t0_s`` on (at least the last one)."""
        if self._actions is None:  # asked before any episode (a connect check): the first one
            self._load(self.order[0])
        m = int(round(observation.t0_s * self.fps))
        a = self._actions
        return a[min(m, len(a) - 1):].copy()
