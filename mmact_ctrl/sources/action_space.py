"""Action spaces: what a foreign policy's actions mean, and one small adapter per space that turns them into the
task-space ``ActionChunk`` the executors run (absolute TCP position + rotation vector relative to the nominal
grasp + gripper opening in m, ``mmact_ctrl.chunk``).

A policy declares its space with :class:`ActionSpace`; :func:`adapt_actions` converts an ``(H, D)`` array of its
actions, answered to one :class:`~mmact_ctrl.chunk.Observation`, into an ``ActionChunk``. After that every mode,
every safety check and every metric applies unchanged: nothing downstream knows where the chunk came from.

Spaces (``ActionSpace.kind``), each optionally followed by one gripper value (``ActionSpace.gripper``):

``tcp_pose``     absolute TCP position (3, m, world frame) + orientation (3, rad): a rotation vector relative to
                 the nominal grasp orientation (``rotation="nominal"``, ours) or the absolute orientation as a
                 world-frame rotation vector (``rotation="world"``, LIBERO's axis-angle state);
``tcp_delta``    TCP displacement (3, m) + rotation (3, rad, world frame, applied on the left) relative to the pose
                 at the observation (``delta_from="observation"``) or to the previous waypoint
                 (``delta_from="previous"``: the deltas accumulate, as per-step delta actions do);
``joint_pos``    absolute arm joint positions (7, rad), turned into TCP poses by the Pinocchio model's forward
                 kinematics (the same model the controller uses);
``joint_delta``  joint displacements (7, rad) relative to the joints at the observation (or accumulated,
                 ``delta_from="previous"``), then forward kinematics.

Normalised actions (``ActionSpace.clip``, ``ActionSpace.scale``): a policy trained on actions in [-1, 1] declares
``clip=(-1, 1)`` (every value, the gripper's too, is clipped to it first, as robosuite's controllers and openpi's
DROID client do) and ``scale`` (what one unit of an arm dimension is: robosuite's OSC_POSE maps 1 to 0.05 m and
0.5 rad per step, DROID's joint velocity to 0.2 rad per step); the gripper value is never scaled.

Gripper conventions (``ActionSpace.gripper``): ``width_m`` (opening in m, 0 .. 0.08, ours), ``open_1`` (1 = open,
0 = closed), ``close_1`` (1 = closed, 0 = open: DROID's ``gripper_position``), ``sign`` (-1 = open, +1 = closed:
LIBERO), ``none`` (no gripper value: the gripper stays open).

Waypoint ``i`` of a chunk is meant for ``t0 + (i + 1) * dt_s`` (``ActionChunk``), any length ``H >= 1``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from controllers.robot_model import PandaModel
from controllers.rotations import rot_from_rotvec, rotvec_from_rot
from mmact_ctrl.chunk import ActionChunk, Observation

#: the spaces an adapter exists for
KINDS: tuple[str, ...] = ("tcp_pose", "tcp_delta", "joint_pos", "joint_delta")
#: gripper conventions
GRIPPERS: tuple[str, ...] = ("width_m", "open_1", "close_1", "sign", "none")
#: the gripper's full opening, m (``controllers.robot_model.RobotModelConfig.finger_opening_m``)
GRIPPER_MAX_M = 0.08


@dataclass(frozen=True)
class ActionSpace:
    """What a source's actions are.

    Attributes:
        kind: one of :data:`KINDS`.
        gripper: one of :data:`GRIPPERS` (the last action dimension, unless ``none``).
        dt_s: spacing of the waypoints, s (waypoint ``i`` is for ``t0 + (i + 1) dt_s``).
        rotation: ``tcp_pose`` only: ``nominal`` (rotation vector relative to the nominal grasp, ours) or
            ``world`` (absolute orientation as a world-frame rotation vector).
        delta_from: ``tcp_delta`` / ``joint_delta``: ``observation`` (every waypoint relative to the observed
            pose) or ``previous`` (each relative to the one before: deltas accumulate).
        scale: what one unit of each arm dimension is (m or rad; one value for all, or one per arm dimension),
            applied after ``clip``; None: the actions are in m / rad already.
        clip: ``(low, high)``: every action value is clipped to it before anything else (None: no clipping).
    """

    kind: str = "tcp_pose"
    gripper: str = "width_m"
    dt_s: float = 0.1
    rotation: str = "nominal"
    delta_from: str = "observation"
    scale: tuple[float, ...] | None = None
    clip: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"action space kind must be one of {KINDS}, got {self.kind!r}")
        if self.gripper not in GRIPPERS:
            raise ValueError(f"gripper convention must be one of {GRIPPERS}, got {self.gripper!r}")
        if not (isinstance(self.dt_s, (int, float)) and math.isfinite(self.dt_s) and self.dt_s > 0):
            raise ValueError(f"action space dt_s must be a finite number of seconds > 0, got {self.dt_s!r}")
        if self.rotation not in ("nominal", "world"):
            raise ValueError(f"action space rotation must be 'nominal' or 'world', got {self.rotation!r}")
        if self.delta_from not in ("observation", "previous"):
            raise ValueError(f"action space delta_from must be 'observation' or 'previous', got {self.delta_from!r}")
        if self.scale is not None:
            scale = tuple(float(v) for v in np.atleast_1d(np.asarray(self.scale, dtype=np.float64)))
            if len(scale) not in (1, self.arm_dims) or not all(math.isfinite(v) and v > 0 for v in scale):
                raise ValueError(f"action space scale must be one finite number > 0 or {self.arm_dims} of them (one per "
                                 f"arm dimension of {self.kind}), got {self.scale!r}")
            object.__setattr__(self, "scale", scale)
        if self.clip is not None:
            clip = tuple(float(v) for v in np.asarray(self.clip, dtype=np.float64).reshape(-1))
            if len(clip) != 2 or not all(math.isfinite(v) for v in clip) or not clip[0] < clip[1]:
                raise ValueError(f"action space clip must be (low, high) with low < high, got {self.clip!r}")
            object.__setattr__(self, "clip", clip)

    @property
    def arm_dims(self) -> int:
        """Arm dimensions (6 for the TCP spaces, 7 for the joint spaces), before the gripper value."""
        return 6 if self.kind.startswith("tcp") else 7

    @property
    def dims(self) -> int:
        """Action dimensions D a chunk of this space has."""
        return self.arm_dims + (self.gripper != "none")

    @property
    def scale_vector(self) -> np.ndarray:
        """The scale of each arm dimension (ones without a scale)."""
        return np.broadcast_to(np.asarray(self.scale if self.scale is not None else (1.0,), dtype=np.float64),
                               (self.arm_dims,)).copy()

    @property
    def is_native(self) -> bool:
        """Whether actions are already our task-space chunk (no conversion but the checks)."""
        return (self.kind == "tcp_pose" and self.rotation == "nominal" and self.gripper == "width_m"
                and self.scale is None and self.clip is None)

    def describe(self) -> str:
        extra = {"tcp_pose": f", rotation {self.rotation}", "tcp_delta": f", from {self.delta_from}",
                 "joint_delta": f", from {self.delta_from}"}.get(self.kind, "")
        if self.clip is not None:
            extra += f", clipped to [{self.clip[0]:g}, {self.clip[1]:g}]"
        if self.scale is not None:
            extra += f", scale {'/'.join(f'{v:g}' for v in self.scale)}"
        return f"{self.kind} ({self.dims} dims, gripper {self.gripper}{extra}, dt {self.dt_s:g} s)"

    def to_dict(self) -> dict:
        return {"kind": self.kind, "gripper": self.gripper, "dt_s": float(self.dt_s), "rotation": self.rotation,
                "delta_from": self.delta_from, "scale": None if self.scale is None else list(self.scale),
                "clip": None if self.clip is None else list(self.clip)}

    @classmethod
    def from_dict(cls, d: dict) -> "ActionSpace":
        unknown = set(d) - set(cls.__dataclass_fields__)
        if unknown:
            raise ValueError(f"unknown action space field(s) {sorted(unknown)}; expected some of "
                             f"{sorted(cls.__dataclass_fields__)}")
        return cls(**{k: (float(v) if k == "dt_s" else v) for k, v in d.items()})


#: ours: what ``ActionChunk.waypoints`` hold
NATIVE = ActionSpace()


def gripper_width_m(values: np.ndarray, convention: str) -> np.ndarray:
    """Gripper openings (m, clipped to [0, 0.08]) from values in ``convention``."""
    g = np.asarray(values, dtype=np.float64)
    if convention == "width_m":
        w = g
    elif convention == "open_1":
        w = GRIPPER_MAX_M * g
    elif convention == "close_1":
        w = GRIPPER_MAX_M * (1.0 - g)
    elif convention == "sign":
        w = GRIPPER_MAX_M * 0.5 * (1.0 - g)
    elif convention == "none":
        w = np.full(g.shape, GRIPPER_MAX_M)
    else:
        raise ValueError(f"gripper convention must be one of {GRIPPERS}, got {convention!r}")
    return np.clip(w, 0.0, GRIPPER_MAX_M)


def gripper_values(width_m: np.ndarray, convention: str) -> np.ndarray:
    """The inverse of :func:`gripper_width_m`: openings (m) in ``convention`` (``none``: an empty column)."""
    w = np.asarray(width_m, dtype=np.float64)
    if convention == "width_m":
        return w
    if convention == "open_1":
        return w / GRIPPER_MAX_M
    if convention == "close_1":
        return 1.0 - w / GRIPPER_MAX_M
    if convention == "sign":
        return 1.0 - 2.0 * w / GRIPPER_MAX_M
    if convention == "none":
        return np.zeros(w.shape[:-1] + (0,)) if w.ndim > 1 else np.zeros((len(w), 0))
    raise ValueError(f"gripper convention must be one of {GRIPPERS}, got {convention!r}")


@dataclass
class ActionAdapter:
    """Turns actions of one :class:`ActionSpace` into our task-space ``ActionChunk``.

    Args:
        space: the source's action space.
        model: the robot model for forward kinematics (joint spaces) and the nominal grasp orientation (None: the
            Panda's; built once, its own data buffers: never the controller's).
    """

    space: ActionSpace
    model: PandaModel | None = None
    _rot_nominal: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if self.model is None:
            self.model = PandaModel()
        _, self._rot_nominal = self.model.fk(self.model.home_q_rad)

    def _checked(self, actions) -> np.ndarray:
        a = np.asarray(actions, dtype=np.float64)
        if a.ndim == 3 and a.shape[0] == 1:  # a batch of one, as LeRobot and many servers answer
            a = a[0]
        if a.ndim != 2 or a.shape[0] < 1 or a.shape[1] != self.space.dims:
            raise ValueError(f"actions of shape {tuple(a.shape)} do not fit the action space "
                             f"{self.space.describe()}: expected (H >= 1, {self.space.dims})")
        if not np.all(np.isfinite(a)):
            bad = int(np.argwhere(~np.isfinite(a))[0][0])
            raise ValueError(f"actions contain NaN or inf (first at waypoint {bad})")
        return a

    def physical(self, actions) -> np.ndarray:
        """``actions`` checked, clipped to ``space.clip`` and their arm dimensions multiplied by ``space.scale``: the
        values in m / rad (and the gripper value in its convention)."""
        a = self._checked(actions)
        sp = self.space
        if sp.clip is None and sp.scale is None:
            return a
        a = np.clip(a, sp.clip[0], sp.clip[1]) if sp.clip is not None else a.copy()
        if sp.scale is not None:
            a[:, :sp.arm_dims] *= sp.scale_vector
        return a

    def _rotvec_of(self, rot: np.ndarray) -> np.ndarray:
        return rotvec_from_rot(rot, self._rot_nominal)

    def _tcp_from_joints(self, q: np.ndarray) -> np.ndarray:
        out = np.empty((len(q), 6))
        for i, qi in enumerate(q):
            pos, rot, _ = self.model.kinematics(qi)
            out[i, :3] = pos
            out[i, 3:] = self._rotvec_of(rot)
        return out

    def pose(self, actions, observation: Observation) -> np.ndarray:
        """The TCP poses ``(H, 6)`` (position m, rotation vector relative to the nominal grasp) of ``actions``."""
        return self._pose(self.physical(actions), observation)

    def _pose(self, a: np.ndarray, observation: Observation) -> np.ndarray:
        sp = self.space
        if sp.kind == "tcp_pose":
            if sp.rotation == "nominal":
                return a[:, :6].copy()
            out = a[:, :6].copy()
            for i in range(len(a)):
                out[i, 3:] = self._rotvec_of(rot_from_rotvec(a[i, 3:6], np.eye(3)))
            return out
        if sp.kind == "tcp_delta":
            d = a[:, :6]
            if sp.delta_from == "previous":
                d_pos = np.cumsum(d[:, :3], axis=0)
            else:
                d_pos = d[:, :3]
            rot0 = rot_from_rotvec(np.asarray(observation.ee_rotvec_rad, dtype=float), self._rot_nominal)
            out = np.empty((len(a), 6))
            out[:, :3] = np.asarray(observation.ee_pos_m, dtype=float) + d_pos
            rot = rot0
            for i in range(len(a)):
                step = rot_from_rotvec(d[i, 3:6], np.eye(3))
                rot = step @ (rot if sp.delta_from == "previous" else rot0)
                out[i, 3:] = self._rotvec_of(rot)
            return out
        q = a[:, :7]
        if sp.kind == "joint_delta":
            q0 = np.asarray(observation.q_rad, dtype=float)
            q = q0 + (np.cumsum(q, axis=0) if sp.delta_from == "previous" else q)
        return self._tcp_from_joints(q)

    def to_chunk(self, actions, observation: Observation, tokens: np.ndarray | None = None,
                 info: dict | None = None) -> ActionChunk:
        """The task-space chunk of ``actions`` answered to ``observation`` (raises ``ValueError`` naming the shape or
        the bad value for actions that do not fit the space: the loop counts it as a rejected chunk)."""
        a = self.physical(actions)
        w = np.empty((len(a), 7))
        w[:, :6] = self._pose(a, observation)
        w[:, 6] = gripper_width_m(a[:, -1] if self.space.gripper != "none" else np.zeros(len(a)), self.space.gripper)
        meta = {"action_space": self.space.kind}
        if info:
            meta.update(info)
        return ActionChunk(waypoints=w, dt_s=float(self.space.dt_s), t0_s=observation.t0_s,
                           tokens=tokens if self.space.is_native else None, info=meta)


def adapt_actions(actions, observation: Observation, space: ActionSpace = NATIVE, model: PandaModel | None = None,
                  info: dict | None = None) -> ActionChunk:
    """One-off conversion (builds an :class:`ActionAdapter`; keep an adapter for repeated calls)."""
    return ActionAdapter(space, model).to_chunk(actions, observation, info=info)
