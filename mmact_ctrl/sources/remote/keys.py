"""The constants of the observation keys, and the pieces a key mapping is made of: image keys (which camera, what
size, which way up; bilinear resizing) and state keys (which parts of an ``Observation``, as what dtype)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controllers.rotations import axis_angle_in_hemisphere, reference_quat, rot_from_rotvec
from mmact_ctrl.chunk import Observation

SCENE_CAMERAS: tuple[str, ...] = ("front", "top", "side", "box_front", "box_side")
#: the gripper's full opening, m
GRIPPER_MAX_M = 0.08
#: the state parts a mapping can put in a state key, and their sizes
STATE_PARTS: dict[str, int] = {
    "t0_s": 1, "q_rad": 7, "dq_rad_s": 7, "ee_pos_m": 3, "ee_rotvec_rad": 3, "ee_axis_angle_rad": 3,
    "gripper_m": 1, "gripper_fingers_m": 2, "gripper_open_1": 1, "gripper_close_1": 1, "target_pos_m": 3,
    "target_prev_pos_m": 3, "frame_gap_s": 1,
}
#: what a simulator knows and a real robot does not: sent only where asked for (see the module)
PRIVILEGED_PARTS: tuple[str, ...] = ("target_pos_m", "target_prev_pos_m", "frame_gap_s")
#: the prompt key of every preset (openpi's)
PROMPT_KEY = "prompt"
#: our extension: the known prefix (n, 7) of an inpainting request (task-space waypoints)
KNOWN_ACTIONS_KEY = "mmact/known_actions"
#: our extension in a reply: the action tokens (H, 7) int the waypoints came from, and the clipped-action count
TOKENS_KEY = "mmact/tokens"
N_CLIPPED_KEY = "mmact/n_clipped"


def resize_bilinear(image: np.ndarray, size_hw: tuple[int, int]) -> np.ndarray:
    """``image`` (H, W, 3) uint8 resized to ``size_hw`` (height, width) px, bilinear with pixel centres aligned
    (no antialiasing); the same array when it already has that size."""
    img = np.asarray(image)
    h, w = img.shape[:2]
    out_h, out_w = int(size_hw[0]), int(size_hw[1])
    if (h, w) == (out_h, out_w):
        return img

    def axis(n_in: int, n_out: int):
        pos = np.clip((np.arange(n_out) + 0.5) * (n_in / n_out) - 0.5, 0.0, n_in - 1)
        lo = np.floor(pos).astype(np.intp)
        return lo, np.minimum(lo + 1, n_in - 1), (pos - lo).astype(np.float32)

    y0, y1, wy = axis(h, out_h)
    x0, x1, wx = axis(w, out_w)
    f = img.astype(np.float32)
    wx = wx[None, :, None]
    top = f[y0][:, x0] * (1 - wx) + f[y0][:, x1] * wx
    bottom = f[y1][:, x0] * (1 - wx) + f[y1][:, x1] * wx
    out = top * (1 - wy[:, None, None]) + bottom * wy[:, None, None]
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


def _size_hw(value, where: str) -> tuple[int, int]:
    sides = [value, value] if isinstance(value, (int, np.integer)) and not isinstance(value, bool) else value
    if (not isinstance(sides, (list, tuple)) or len(sides) != 2
            or not all(isinstance(s, (int, np.integer)) and not isinstance(s, bool) and s >= 1 for s in sides)):
        raise ValueError(f"{where}: size_px must be an integer >= 1 or [height, width], got {value!r}")
    return int(sides[0]), int(sides[1])


@dataclass(frozen=True)
class ImageKey:
    """One image key: which scene camera fills it, at what size.

    Attributes:
        key: the key in the observation dict.
        camera: the scene camera, or None for a black frame.
        size_hw: (height, width) px of the frame sent.
        previous: the frame ``prev_frame_gap_s`` before the observation instead of the current one.
        rotate_deg: 0 (the frame as rendered: ours come out upright) or 180 (turned upside down, as robosuite's
            raw renders are).
    """

    key: str
    camera: str | None
    size_hw: tuple[int, int] = (224, 224)
    previous: bool = False
    rotate_deg: int = 0

    def __post_init__(self) -> None:
        if not isinstance(self.key, str) or not self.key:
            raise ValueError(f"image key must be a non-empty string, got {self.key!r}")
        if self.camera is not None and (not isinstance(self.camera, str) or not self.camera):
            raise ValueError(f"image key {self.key!r}: camera must be a camera name or null, got {self.camera!r}")
        object.__setattr__(self, "size_hw", _size_hw(tuple(self.size_hw) if isinstance(self.size_hw, list)
                                                     else self.size_hw, f"image key {self.key!r}"))
        if self.rotate_deg not in (0, 180) or isinstance(self.rotate_deg, bool):
            raise ValueError(f"image key {self.key!r}: rotate_deg must be 0 or 180, got {self.rotate_deg!r}")


@dataclass(frozen=True)
class StateKey:
    """One state key: the float vector of ``parts`` (names of :data:`STATE_PARTS`) as ``dtype``."""

    key: str
    parts: tuple[str, ...]
    dtype: str = "float64"

    def __post_init__(self) -> None:
        if not isinstance(self.key, str) or not self.key:
            raise ValueError(f"state key must be a non-empty string, got {self.key!r}")
        object.__setattr__(self, "parts", tuple(self.parts))
        if not self.parts:
            raise ValueError(f"state key {self.key!r} needs at least one part of {sorted(STATE_PARTS)}")
        unknown = [p for p in self.parts if p not in STATE_PARTS]
        if unknown:
            raise ValueError(f"state key {self.key!r}: unknown part(s) {unknown}; choose from {sorted(STATE_PARTS)}")
        if self.dtype not in ("float16", "float32", "float64"):
            raise ValueError(f"state key {self.key!r}: dtype must be float16, float32 or float64, got {self.dtype!r}")

    @property
    def size(self) -> int:
        return sum(STATE_PARTS[p] for p in self.parts)


def state_part(observation: Observation, part: str, rot_nominal: np.ndarray) -> np.ndarray:
    """The value of one state part of ``observation`` (float64 vector, see :data:`STATE_PARTS`)."""
    o = observation
    g = float(o.gripper_m)
    if part == "t0_s":
        return np.array([o.t0_s], dtype=np.float64)
    if part == "ee_axis_angle_rad":
        rot = rot_from_rotvec(np.asarray(o.ee_rotvec_rad, dtype=np.float64), rot_nominal)
        return axis_angle_in_hemisphere(rot, reference_quat(rot_nominal))
    if part == "gripper_m":
        return np.array([g])
    if part == "gripper_fingers_m":
        return np.array([0.5 * g, -0.5 * g])
    if part == "gripper_open_1":
        return np.array([g / GRIPPER_MAX_M])
    if part == "gripper_close_1":
        return np.array([1.0 - g / GRIPPER_MAX_M])
    if part == "frame_gap_s":
        return np.array([float(o.frame_gap_s)])
    if part == "target_prev_pos_m":
        prev = o.target_prev_pos_m if o.target_prev_pos_m is not None else o.target_pos_m
        return np.asarray(prev, dtype=np.float64).reshape(3)
    if part in STATE_PARTS:
        return np.asarray(getattr(o, part), dtype=np.float64).reshape(STATE_PARTS[part])
    raise ValueError(f"unknown state part {part!r}; choose from {sorted(STATE_PARTS)}")
