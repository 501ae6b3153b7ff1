"""Our own observation keys: everything an ``Observation`` holds, exactly (float64 vectors, frames as rendered); only
a server of ours reads them (they carry the true target)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mmact_ctrl.chunk import Observation
from mmact_ctrl.sources.remote.key_mapping import _views
from mmact_ctrl.sources.remote.keys import PRIVILEGED_PARTS, PROMPT_KEY


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
