"""Which observation keys carry the images, the state and the prompt: named mappings from our ``Observation`` to
the observation dict a policy server reads.

Presets (:data:`PRESETS`, :func:`load_mapping`):

``mmact``   our own keys, carrying everything an ``Observation`` holds, so that our server rebuilds the exact
            ``Observation`` (:meth:`MmactMapping.decode`) and a served source of ours behaves bit-identically:
            ``mmact/t0_s``, ``mmact/q_rad``, ``mmact/dq_rad_s``, ``mmact/ee_pos_m``, ``mmact/ee_rotvec_rad``,
            ``mmact/gripper_m``, ``mmact/target_pos_m``, ``mmact/target_prev_pos_m`` (absent when None),
            ``mmact/frame_gap_s``, ``mmact/image/<camera>`` and ``mmact/prev_image/<camera>`` (H, W, 3) uint8 per
            camera as rendered (absent when None), ``prompt`` (the instruction);
``libero``, ``droid``  the observation keys of those conventions (``mmact_ctrl.sources.presets``: each preset's file
            says what its keys hold and where that was read).

A user mapping is a JSON file (:func:`load_mapping` with its path) with this schema (every field but ``images`` /
``state`` optional; unknown fields are refused)::

    {
      "name": "my_policy",                 # default: the file name without .json
      "images": [                          # one entry per image key
        {"key": "observation/image",       # the key in the observation dict
         "camera": "front",                # a scene camera (front, top, side), or null: a black frame
         "size_px": 224,                   # the side of a square frame, or [height, width]
         "previous": false,                # true: the frame prev_frame_gap_s before the observation
         "rotate_deg": 0}                  # 0: as rendered (ours are upright); 180: turned upside down
      ],
      "state": [                           # one entry per state key: a float vector of the named parts
        {"key": "observation/state",
         "parts": ["ee_pos_m", "ee_axis_angle_rad", "gripper_fingers_m"],
         "dtype": "float32"}               # default float64
      ],
      "prompt_key": "prompt",              # null: no prompt is sent
      "prompt": null,                      # a fixed text instead of the scene's instruction
      "prev_frame_gap_s": 0.0              # > 0 when an image has "previous": true, s
    }

State parts (:data:`STATE_PARTS`, with their sizes): ``t0_s`` (1, s), ``q_rad`` (7), ``dq_rad_s`` (7), ``ee_pos_m``
(3, world frame), ``ee_rotvec_rad`` (3, ours: relative to the nominal grasp), ``ee_axis_angle_rad`` (3, the TCP
orientation as a world-frame axis-angle, continuous: the quaternion in the nominal grasp's hemisphere, angle in
[0, 2 pi] as robosuite's ``quat2axisangle``, :func:`controllers.rotations.axis_angle_in_hemisphere`), ``gripper_m``
(1, opening), ``gripper_fingers_m`` (2, +w/2 and -w/2), ``gripper_open_1`` (1, 1 = open), ``gripper_close_1`` (1,
1 = closed), ``target_pos_m`` (3), ``target_prev_pos_m`` (3, the current position before there is an earlier frame),
``frame_gap_s`` (1).

**Privileged parts** (:data:`PRIVILEGED_PARTS`: the true target, which a simulator knows and no real robot does):
a key mapping sends them only as ``mmact/<part>`` keys listed in ``KeyMapping.privileged``, which the client fills
only for a server of ours that asks for them in its metadata (``mmact_ctrl.sources.presets.resolve``), or when the
user put them in a mapping file or chose the ``mmact`` mapping; the connect block names them.

A mapping declares the scene cameras it needs (``camera_names``: the world must render these, in that order) and the
size to render them at (``image_size_px``). A camera the scene does not have (:data:`SCENE_CAMERAS`) fills its key
with a black frame, and ``missing_cameras`` says which. A frame rendered at another size is resized (bilinear).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from controllers.rotations import axis_angle_in_hemisphere, reference_quat, rot_from_rotvec
from mmact_ctrl.chunk import Observation

#: the cameras of the simulated scene (``scenarios.world.panda_scene.AVAILABLE_CAMERAS``; a test holds them equal)
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


def _views(observation: Observation, camera_names: tuple[str, ...], previous: bool, name: str) -> np.ndarray | None:
    """The (V, H, W, 3) frames of ``camera_names`` in ``observation`` (the earlier ones with ``previous``; the
    current ones stand in before there is an earlier frame)."""
    img = observation.prev_image if previous and observation.prev_image is not None else observation.image
    if img is None:
        raise ValueError(f"observation mapping {name!r} needs the camera frames of {list(camera_names)}, but "
                         "Observation.image is None")
    img = np.asarray(img)
    if img.ndim != 4 or len(img) != len(camera_names) or img.shape[-1] != 3:
        raise ValueError(f"observation mapping {name!r} expects frames (V={len(camera_names)}, H, W, 3) of cameras "
                         f"{list(camera_names)}, got shape {img.shape}")
    return img


@dataclass(frozen=True)
class KeyMapping:
    """A mapping of named keys (the ``libero`` and ``droid`` presets, a user's JSON file).

    Attributes:
        name: how reports name it.
        images: the image keys.
        state: the state keys.
        prompt_key: the key of the prompt (None: no prompt).
        prompt: a fixed prompt instead of ``Observation.instruction`` (None: the instruction).
        prev_frame_gap_s: how long before the observation the ``previous`` frames are taken, s.
        scene_cameras: the cameras the scene has (others are black frames).
        privileged: :data:`PRIVILEGED_PARTS` also sent, each as ``mmact/<part>`` (float64): only for a server of
            ours that asked for them (see the module).
    """

    name: str
    images: tuple[ImageKey, ...] = ()
    state: tuple[StateKey, ...] = ()
    prompt_key: str | None = PROMPT_KEY
    prompt: str | None = None
    prev_frame_gap_s: float = 0.0
    scene_cameras: tuple[str, ...] = SCENE_CAMERAS
    privileged: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "images", tuple(self.images))
        object.__setattr__(self, "state", tuple(self.state))
        object.__setattr__(self, "scene_cameras", tuple(self.scene_cameras))
        object.__setattr__(self, "privileged", tuple(self.privileged))
        bad = [p for p in self.privileged if p not in PRIVILEGED_PARTS]
        if bad:
            raise ValueError(f"observation mapping {self.name!r}: privileged part(s) {bad} are not of {PRIVILEGED_PARTS}")
        keys = [k.key for k in self.images] + [k.key for k in self.state] + ([self.prompt_key] if self.prompt_key else [])
        dup = sorted({k for k in keys if keys.count(k) > 1})
        if dup:
            raise ValueError(f"observation mapping {self.name!r}: key(s) {dup} given more than once")
        gap = self.prev_frame_gap_s
        if not (isinstance(gap, (int, float)) and math.isfinite(gap) and gap >= 0):
            raise ValueError(f"observation mapping {self.name!r}: prev_frame_gap_s must be a number of seconds >= 0, "
                             f"got {gap!r}")
        if any(k.previous for k in self.images) and not gap > 0:
            raise ValueError(f"observation mapping {self.name!r}: an image key asks for the previous frame, so "
                             "prev_frame_gap_s must be > 0")
        if self.prompt is not None and not isinstance(self.prompt, str):
            raise ValueError(f"observation mapping {self.name!r}: prompt must be a string or null, got {self.prompt!r}")

    @property
    def camera_names(self) -> tuple[str, ...]:
        """The scene cameras the world must render, in order (each once)."""
        return tuple(dict.fromkeys(k.camera for k in self.images if k.camera in self.scene_cameras))

    @property
    def missing_cameras(self) -> tuple[str, ...]:
        """Cameras named by an image key that the scene does not have: those keys are black frames."""
        return tuple(dict.fromkeys(k.camera for k in self.images if k.camera is not None
                                   and k.camera not in self.scene_cameras))

    @property
    def needs_image(self) -> bool:
        return bool(self.camera_names)

    @property
    def privileged_keys(self) -> tuple[str, ...]:
        """Every key that carries what no real robot knows: state keys with a privileged part, and the
        ``mmact/<part>`` keys of :attr:`privileged`."""
        keys = [k.key for k in self.state if any(p in PRIVILEGED_PARTS for p in k.parts)]
        return tuple(keys + [f"mmact/{p}" for p in self.privileged])

    @property
    def image_size_px(self) -> int | None:
        """The side to render the scene cameras at: the largest side any of their keys asks for (None: none)."""
        sides = [max(k.size_hw) for k in self.images if k.camera in self.scene_cameras]
        return max(sides) if sides else None

    def describe(self) -> str:
        parts = [f"{k.key} <- {k.camera if k.camera in self.scene_cameras else 'black'} "
                 f"{k.size_hw[0]}x{k.size_hw[1]}{' (previous)' if k.previous else ''}"
                 f"{' rotated 180' if k.rotate_deg == 180 and k.camera in self.scene_cameras else ''}"
                 for k in self.images]
        parts += [f"{k.key} <- {'+'.join(k.parts)} ({k.size}, {k.dtype})" for k in self.state]
        parts += [f"mmact/{p} <- {p} (privileged)" for p in self.privileged]
        if self.prompt_key:
            parts.append(f"{self.prompt_key} <- {'fixed text' if self.prompt is not None else 'instruction'}")
        note = (f"; the scene has no camera {', '.join(map(repr, self.missing_cameras))}: black frame(s)"
                if self.missing_cameras else "")
        return f"{self.name}: " + ", ".join(parts) + note

    def encode(self, observation: Observation, rot_nominal: np.ndarray | None = None) -> dict:
        """The observation dict of ``observation`` (``rot_nominal``: the nominal grasp orientation (3, 3), needed by
        ``ee_axis_angle_rad``)."""
        out: dict = {}
        cams = self.camera_names
        for k in self.images:
            if k.camera in self.scene_cameras:
                views = _views(observation, cams, k.previous, self.name)
                frame = resize_bilinear(views[cams.index(k.camera)], k.size_hw)
                out[k.key] = np.ascontiguousarray(frame[::-1, ::-1] if k.rotate_deg == 180 else frame)
            else:
                out[k.key] = np.zeros((*k.size_hw, 3), dtype=np.uint8)
        for k in self.state:
            if "ee_axis_angle_rad" in k.parts and rot_nominal is None:
                raise ValueError(f"observation mapping {self.name!r}: state part ee_axis_angle_rad needs the nominal "
                                 "grasp orientation")
            vec = np.concatenate([state_part(observation, p, rot_nominal) for p in k.parts])
            out[k.key] = vec.astype(k.dtype)
        for p in self.privileged:
            value = state_part(observation, p, rot_nominal)
            out[f"mmact/{p}"] = float(value[0]) if p in _SCALARS else value
        if self.prompt_key:
            out[self.prompt_key] = self.prompt if self.prompt is not None else str(observation.instruction)
        return out

    def to_dict(self) -> dict:
        """The JSON form (the user mapping file's schema)."""
        return {"name": self.name,
                "images": [{"key": k.key, "camera": k.camera, "size_px": list(k.size_hw), "previous": k.previous,
                            "rotate_deg": k.rotate_deg} for k in self.images],
                "state": [{"key": k.key, "parts": list(k.parts), "dtype": k.dtype} for k in self.state],
                "prompt_key": self.prompt_key, "prompt": self.prompt, "prev_frame_gap_s": float(self.prev_frame_gap_s)}

    @classmethod
    def from_dict(cls, d: dict, name: str = "mapping", scene_cameras: tuple[str, ...] = SCENE_CAMERAS) -> "KeyMapping":
        """A mapping from its JSON form (raises ``ValueError`` naming an unknown or bad field)."""
        if not isinstance(d, dict):
            raise ValueError(f"observation mapping {name!r} must be a JSON object, got {type(d).__name__}")
        allowed = {"name", "images", "state", "prompt_key", "prompt", "prev_frame_gap_s"}
        unknown = sorted(set(d) - allowed)
        if unknown:
            raise ValueError(f"observation mapping {name!r}: unknown field(s) {unknown}; expected some of {sorted(allowed)}")
        name = d.get("name", name)
        images, state = [], []
        for i, e in enumerate(d.get("images") or []):
            _fields(e, {"key", "camera", "size_px", "previous", "rotate_deg"}, f"{name!r} images[{i}]")
            images.append(ImageKey(e.get("key"), e.get("camera"), _size_hw(e.get("size_px", 224), f"{name!r} images[{i}]"),
                                   bool(e.get("previous", False)), e.get("rotate_deg", 0)))
        for i, e in enumerate(d.get("state") or []):
            _fields(e, {"key", "parts", "dtype"}, f"{name!r} state[{i}]")
            parts = e.get("parts")
            if not isinstance(parts, list):
                raise ValueError(f"observation mapping {name!r} state[{i}]: parts must be a list of names, got {parts!r}")
            state.append(StateKey(e.get("key"), tuple(parts), e.get("dtype", "float64")))
        return cls(name=str(name), images=tuple(images), state=tuple(state), prompt_key=d.get("prompt_key", PROMPT_KEY),
                   prompt=d.get("prompt"), prev_frame_gap_s=float(d.get("prev_frame_gap_s", 0.0)),
                   scene_cameras=tuple(scene_cameras))


def _fields(entry, allowed: set[str], where: str) -> None:
    if not isinstance(entry, dict):
        raise ValueError(f"observation mapping {where} must be an object, got {entry!r}")
    unknown = sorted(set(entry) - allowed)
    if unknown:
        raise ValueError(f"observation mapping {where}: unknown field(s) {unknown}; expected some of {sorted(allowed)}")


def _key(prefix: str, camera: str) -> str:
    return f"mmact/{prefix}/{camera}"


#: the mmact preset's scalar and vector keys -> Observation fields
MMACT_FIELDS: dict[str, str] = {
    "mmact/t0_s": "t0_s", "mmact/q_rad": "q_rad", "mmact/dq_rad_s": "dq_rad_s", "mmact/ee_pos_m": "ee_pos_m",
    "mmact/ee_rotvec_rad": "ee_rotvec_rad", "mmact/gripper_m": "gripper_m", "mmact/target_pos_m": "target_pos_m",
    "mmact/target_prev_pos_m": "target_prev_pos_m", "mmact/frame_gap_s": "frame_gap_s",
}
_SCALARS = ("t0_s", "gripper_m", "frame_gap_s")
_OPTIONAL = ("target_prev_pos_m", "frame_gap_s")


@dataclass(frozen=True)
class MmactMapping:
    """Our own keys: everything an ``Observation`` holds, exactly (float64 vectors, frames as rendered).

    Attributes:
        camera_names: the cameras whose frames travel (``mmact/image/<camera>``), the order of ``Observation.image``.
        image_size_px: the side to render them at (None: the world's default).
        prev_frame_gap_s: > 0: the earlier frames travel too (``mmact/prev_image/<camera>``), s.
        needs_image: whether frames travel at all.
    """

    camera_names: tuple[str, ...] = ("front",)
    image_size_px: int | None = None
    prev_frame_gap_s: float = 0.0
    needs_image: bool = True
    name: str = field(default="mmact", init=False)
    missing_cameras: tuple[str, ...] = field(default=(), init=False)
    #: the mmact keys carry the true target: every privileged part
    privileged: tuple[str, ...] = field(default=PRIVILEGED_PARTS, init=False)

    @property
    def privileged_keys(self) -> tuple[str, ...]:
        """The keys that carry what no real robot knows (the true target now and a frame earlier)."""
        return tuple(f"mmact/{p}" for p in self.privileged)

    def __post_init__(self) -> None:
        object.__setattr__(self, "camera_names", tuple(self.camera_names))
        if self.needs_image and not self.camera_names:
            raise ValueError("observation mapping 'mmact': a source that needs images must name its cameras")

    def describe(self) -> str:
        frames = (f"frames of {', '.join(self.camera_names)}{' + earlier frames' if self.prev_frame_gap_s > 0 else ''}"
                  if self.needs_image else "no frames")
        return f"mmact: every Observation field under mmact/..., {frames}, prompt <- instruction"

    def encode(self, observation: Observation, rot_nominal: np.ndarray | None = None) -> dict:
        """Every field of ``observation`` (``rot_nominal`` is not needed: accepted for a common signature)."""
        o = observation
        out: dict = {PROMPT_KEY: str(o.instruction)}
        for key, attr in MMACT_FIELDS.items():
            value = getattr(o, attr)
            if value is None:
                continue
            out[key] = float(value) if attr in _SCALARS else np.ascontiguousarray(value, dtype=np.float64)
        if self.needs_image and o.image is not None:
            views = _views(o, self.camera_names, False, self.name)
            for cam, view in zip(self.camera_names, views):
                out[_key("image", cam)] = np.ascontiguousarray(view)
            if o.prev_image is not None:
                prev = np.asarray(o.prev_image)
                if prev.shape != views.shape:
                    raise ValueError(f"observation mapping 'mmact': prev_image has shape {prev.shape}, image {views.shape}")
                for cam, view in zip(self.camera_names, prev):
                    out[_key("prev_image", cam)] = np.ascontiguousarray(view)
        return out

    def decode(self, obs: dict) -> Observation:
        """The ``Observation`` an :meth:`encode` dict came from (raises ``ValueError`` naming a missing or bad key)."""
        if not isinstance(obs, dict):
            raise ValueError(f"an observation must be a dict, got {type(obs).__name__}")
        kw: dict = {}
        for key, attr in MMACT_FIELDS.items():
            if key not in obs:
                if attr in _OPTIONAL:  # None / 0 in the Observation: not sent
                    continue
                raise ValueError(f"observation lacks {key!r} (keys: {sorted(obs)[:12]}): is the client using the "
                                 "mmact mapping?")
            value = obs[key]
            if attr in _SCALARS:
                kw[attr] = float(value)
            else:
                arr = np.array(value, dtype=np.float64)  # a copy: the frame's buffer is read-only
                want = 7 if attr in ("q_rad", "dq_rad_s") else 3
                if arr.shape != (want,):
                    raise ValueError(f"observation key {key!r} must have shape ({want},), got {arr.shape}")
                kw[attr] = arr
        kw["instruction"] = str(obs.get(PROMPT_KEY, ""))
        if self.needs_image:
            kw["image"] = self._frames(obs, "image", required=True)
            if self.prev_frame_gap_s > 0:
                kw["prev_image"] = self._frames(obs, "prev_image", required=False)
        return Observation(**kw)

    def _frames(self, obs: dict, prefix: str, required: bool) -> np.ndarray | None:
        keys = [_key(prefix, cam) for cam in self.camera_names]
        have = [k in obs for k in keys]
        if not any(have) and not required:
            return None
        if not all(have):
            missing = [k for k, h in zip(keys, have) if not h]
            raise ValueError(f"observation lacks {missing} (the source reads cameras {list(self.camera_names)})")
        views = [np.asarray(obs[k]) for k in keys]
        for k, v in zip(keys, views):
            if v.dtype != np.uint8 or v.ndim != 3 or v.shape[-1] != 3:
                raise ValueError(f"observation key {k!r} must be (H, W, 3) uint8, got {v.shape} {v.dtype}")
        if len({v.shape for v in views}) > 1:
            raise ValueError(f"observation frames {keys} differ in shape: {[v.shape for v in views]}")
        return np.stack(views)


ObsMapping = KeyMapping | MmactMapping

#: the named mappings: each preset's (``mmact_ctrl.sources.presets``)
PRESETS: tuple[str, ...] = ("mmact", "libero", "droid")


def load_mapping(spec: "str | Path | ObsMapping", scene_cameras: tuple[str, ...] = SCENE_CAMERAS) -> ObsMapping:
    """A preset by name (:data:`PRESETS`), a user mapping by JSON file path, or ``spec`` itself when it is already
    a mapping (raises ``ValueError`` naming the bad name, path or field)."""
    if isinstance(spec, (KeyMapping, MmactMapping)):
        return replace(spec, scene_cameras=tuple(scene_cameras)) if isinstance(spec, KeyMapping) else spec
    text = str(spec)
    if text == "mmact":
        return MmactMapping()
    if text in PRESETS:
        from mmact_ctrl.sources.presets import PRESETS as CONVENTIONS

        return replace(CONVENTIONS[text].mapping, scene_cameras=tuple(scene_cameras))
    path = Path(text)
    if not path.is_file():
        raise ValueError(f"unknown observation mapping {text!r}: give a preset ({', '.join(PRESETS)}) or the path of a "
                         "JSON mapping file")
    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"observation mapping file {text!r} is not readable JSON: {exc}") from None
    return KeyMapping.from_dict(data, name=path.stem, scene_cameras=tuple(scene_cameras))
