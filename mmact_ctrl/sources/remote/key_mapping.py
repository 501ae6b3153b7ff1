"""A mapping of named keys (the ``libero`` and ``droid`` presets' observation keys, a user's JSON file): which scene
camera fills which image key, which parts of the state go in which state key, where the prompt goes."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mmact_ctrl.chunk import Observation
from mmact_ctrl.sources.remote.keys import (PRIVILEGED_PARTS, PROMPT_KEY, SCENE_CAMERAS, ImageKey, StateKey,
                                            _size_hw, resize_bilinear, state_part)

#: scalar state parts (sent as a float under ``mmact/<part>``)
_SCALARS = ("t0_s", "gripper_m", "frame_gap_s")


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
