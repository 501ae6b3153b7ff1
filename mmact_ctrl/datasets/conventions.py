"""What a policy trained on one of our LeRobot exports reads and answers, from the dataset's own ``info.json``: the
action space (``tcp_pose`` or ``joint_pos`` + the gripper width, ``1 / fps`` apart), the cameras and their size,
the fields of ``observation.state``. The LeRobot adapter (``mmact_ctrl.sources.lerobot.LeRobotSource``) and the
replay (``mmact_ctrl.sources.replay``) are configured from it, so a trained policy comes back under the control
layer in the conventions it was trained in, never misread: names that are not ours are refused in one line.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from mmact_ctrl.datasets.layout import IMAGES_PREFIX
from mmact_ctrl.datasets.reader import LeRobotDataset
from mmact_ctrl.sources.action_space import ActionSpace

#: the names our exports give ``observation.state`` (joints + gripper opening) and each action space's ``action``
#: (``scenarios.collect_lerobot`` writes them; a replay and a trained policy read them back)
STATE_FEATURE_NAMES: tuple[str, ...] = tuple(f"panda_joint{i}_rad" for i in range(1, 8)) + ("gripper_m",)
TCP_ACTION_NAMES: tuple[str, ...] = ("x_m", "y_m", "z_m", "rx_rad", "ry_rad", "rz_rad", "gripper_m")
JOINT_ACTION_NAMES: tuple[str, ...] = STATE_FEATURE_NAMES
#: the action names of the spaces our exports write -> the action space's kind
ACTION_NAMES: dict[tuple[str, ...], str] = {TCP_ACTION_NAMES: "tcp_pose", JOINT_ACTION_NAMES: "joint_pos"}
#: ``observation.state``'s names in our exports -> the ``Observation`` fields they are
STATE_NAMES: dict[tuple[str, ...], tuple[str, ...]] = {STATE_FEATURE_NAMES: ("q_rad", "gripper_m")}


@dataclass(frozen=True)
class DatasetConventions:
    """A dataset's conventions.

    Attributes:
        fps: its frame rate (the actions' spacing is ``1 / fps``).
        action_space: what its ``action`` is.
        cameras: ``observation.images.<key>`` key -> the scene camera it was rendered from.
        image_size_px: side of its square frames.
        state_fields: the ``Observation`` fields of ``observation.state``, in order.
    """

    fps: int
    action_space: ActionSpace
    cameras: dict[str, str] = field(default_factory=dict)
    image_size_px: int = 96
    state_fields: tuple[str, ...] = ("q_rad", "gripper_m")

    def source_kwargs(self) -> dict:
        """``LeRobotSource``'s keyword arguments for a policy trained on the dataset."""
        return {"action_space": self.action_space, "cameras": dict(self.cameras), "state_fields": self.state_fields,
                "image_size_px": self.image_size_px}


def action_space_of(info: dict, where: str) -> ActionSpace:
    """The action space ``info.json``'s ``action`` names say (one line naming them when they are not ours)."""
    names = tuple(info["features"].get("action", {}).get("names") or ())
    kind = ACTION_NAMES.get(names)
    if kind is None:
        known = " or ".join(f"{k}: {list(n)}" for n, k in ACTION_NAMES.items())
        raise ValueError(f"{where}: action names {list(names)} are not a space this project knows ({known})")
    return ActionSpace(kind=kind, gripper="width_m", dt_s=1.0 / int(info["fps"]))


def dataset_conventions(root: str | Path) -> DatasetConventions:
    """The conventions of the dataset at ``root``."""
    ds = LeRobotDataset.open(root)
    info, where = ds.info, str(root)
    space = action_space_of(info, where)
    names = tuple(info["features"].get("observation.state", {}).get("names") or ())
    fields = STATE_NAMES.get(names)
    if fields is None:
        raise ValueError(f"{where}: observation.state names {list(names)} are not a state this project knows "
                         f"({[list(n) for n in STATE_NAMES]})")
    cameras = {k[len(IMAGES_PREFIX):]: k[len(IMAGES_PREFIX):] for k in ds.camera_keys}
    sizes = {int(info["features"][k]["shape"][0]) for k in ds.camera_keys}
    if len(sizes) > 1:
        raise ValueError(f"{where}: cameras of different sizes {sorted(sizes)}: the scene renders one size")
    return DatasetConventions(fps=ds.fps, action_space=space, cameras=cameras,
                              image_size_px=sizes.pop() if sizes else 96, state_fields=fields)
