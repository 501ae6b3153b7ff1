"""The chunk contract shared by every chunk source (learned policy, scripted expert)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np


@dataclass(frozen=True)
class Observation:
    """What a chunk source sees at observation time ``t0_s``.

    Attributes:
        t0_s: simulation time of the observation, seconds.
        q_rad: arm joint positions (7,), rad.
        dq_rad_s: arm joint velocities (7,), rad/s.
        ee_pos_m: end-effector (TCP site) position (3,), world frame, m.
        ee_rotvec_rad: end-effector orientation as a rotation vector relative to the nominal grasp orientation (3,).
        gripper_m: gripper opening, m.
        target_pos_m: where the instructed target is in this frame (3,), m; what one camera frame shows.
        image: camera frame(s) ``(V, H, W, 3)`` uint8, or None when the source does not need pixels.
        instruction: the language instruction, or "" when there is none.
        target_prev_pos_m: where the target was in the frame ``frame_gap_s`` earlier (3,), m (a second frame, from
            which a source may estimate the target's velocity; at the start of an episode, the first frame).
        frame_gap_s: time between that earlier frame and this one, s (0 when there is no earlier frame yet).
        prev_image: camera frame(s) ``(V, H, W, 3)`` uint8 rendered ``prev_frame_gap_s`` before ``t0_s``, for a
            source that declares ``prev_frame_gap_s > 0`` (a policy that sees motion); None when the source does
            not ask for it, or there was no earlier frame (the first query of an episode).
    """

    t0_s: float
    q_rad: np.ndarray
    dq_rad_s: np.ndarray
    ee_pos_m: np.ndarray
    ee_rotvec_rad: np.ndarray
    gripper_m: float
    target_pos_m: np.ndarray
    image: np.ndarray | None = None
    instruction: str = ""
    target_prev_pos_m: np.ndarray | None = None
    frame_gap_s: float = 0.0
    prev_image: np.ndarray | None = None


@dataclass(frozen=True)
class ActionChunk:
    """H float waypoints of 7 dims, ``dt_s`` apart, computed from the observation at ``t0_s``.

    Waypoint ``i`` is meant for time ``t0_s + (i + 1) * dt_s``. ``waypoints`` are the
    dequantized actions (``[x, y, z, rx, ry, rz, gripper]``, see ``policy.action_tokenizer``);
    ``tokens`` are the action tokens they came from (None when quantization is off).
    """

    waypoints: np.ndarray
    dt_s: float
    t0_s: float
    tokens: np.ndarray | None = None
    n_clipped: int = 0
    info: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        w = np.asarray(self.waypoints, dtype=np.float64)
        if w.ndim != 2 or w.shape[1] != 7 or w.shape[0] < 1:
            raise ValueError(f"ActionChunk.waypoints must have shape (H>=1, 7), got {w.shape}")
        if not np.all(np.isfinite(w)):
            raise ValueError("ActionChunk.waypoints contain NaN or inf")
        if not (self.dt_s > 0):
            raise ValueError(f"ActionChunk.dt_s must be > 0, got {self.dt_s}")
        object.__setattr__(self, "waypoints", w)
        object.__setattr__(self, "_times_s", self.t0_s + self.dt_s * np.arange(1, w.shape[0] + 1))

    @property
    def horizon(self) -> int:
        return int(self.waypoints.shape[0])

    @property
    def times_s(self) -> np.ndarray:
        """Absolute time of each waypoint, s (computed once)."""
        return self._times_s  # type: ignore[attr-defined]

    @property
    def end_s(self) -> float:
        return float(self.t0_s + self.dt_s * self.horizon)


@runtime_checkable
class ChunkSource(Protocol):
    """Anything that turns an observation into an action chunk (policy, expert)."""

    #: whether ``plan`` needs ``Observation.image`` (rendering costs ~10 ms per view).
    needs_image: bool

    def plan(self, observation: Observation) -> ActionChunk:
        """Compute one action chunk from one observation."""
        ...
