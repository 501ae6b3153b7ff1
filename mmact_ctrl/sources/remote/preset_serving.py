"""A chunk source of ours that speaks a foreign convention over openpi's protocol (``scenarios.serve --preset``).

:class:`ConventionPolicy` reads an observation dict in a convention's keys (``libero``, ``droid``, a JSON preset)
back into an ``Observation`` (:func:`decode_keys`: the pose from the state's position and axis-angle, or from its
joints through forward kinematics; the gripper from its convention; the frames of the scene cameras; the prompt),
asks the source for a chunk and answers it as that convention's actions
(:class:`~mmact_ctrl.sources.action_encoder.ActionEncoder`: successive normalised steps for LIBERO, normalised
joint velocities for DROID). Its metadata declares only its ``action_horizon`` and, under ``"mmact"``, the
privileged parts it reads (our scripted expert reads the true target, which no real robot has); the convention
itself it leaves to the client, as a foreign server does: the client must say ``--preset``.

This is how a convention is tested end to end: the scripted expert natively and the same expert through a
convention over the wire must run the same episodes; a client that misreads one piece of it must not.
"""

from __future__ import annotations

import time

import numpy as np

from controllers.robot_model import PandaModel
from controllers.rotations import rot_from_axis_angle, rotvec_from_rot
from mmact_ctrl.chunk import ActionChunk, Observation
from mmact_ctrl.sources.action_encoder import ActionEncoder
from mmact_ctrl.sources.action_space import GRIPPER_MAX_M
from mmact_ctrl.sources.contract import source_name
from mmact_ctrl.sources.remote.mapping import PRIVILEGED_PARTS, STATE_PARTS, KeyMapping
from mmact_ctrl.sources.remote.serving import METADATA_VERSION


def _parts(mapping: KeyMapping, obs: dict) -> dict[str, np.ndarray]:
    """Every state part the mapping's keys carry, by name (float64)."""
    out: dict[str, np.ndarray] = {}
    for k in mapping.state:
        if k.key not in obs:
            raise KeyError(f"observation lacks {k.key!r} (keys: {sorted(obs)[:12]})")
        vec = np.asarray(obs[k.key], dtype=np.float64).reshape(-1)
        if len(vec) != k.size:
            raise ValueError(f"observation key {k.key!r} must hold {k.size} values ({'+'.join(k.parts)}), got {len(vec)}")
        at = 0
        for part in k.parts:
            out[part] = vec[at:at + STATE_PARTS[part]]
            at += STATE_PARTS[part]
    return out


def _gripper_m(parts: dict[str, np.ndarray]) -> float:
    if "gripper_m" in parts:
        return float(parts["gripper_m"][0])
    if "gripper_fingers_m" in parts:
        return float(parts["gripper_fingers_m"][0] - parts["gripper_fingers_m"][1])
    if "gripper_open_1" in parts:
        return GRIPPER_MAX_M * float(parts["gripper_open_1"][0])
    if "gripper_close_1" in parts:
        return GRIPPER_MAX_M * (1.0 - float(parts["gripper_close_1"][0]))
    return GRIPPER_MAX_M


def _pose(parts: dict[str, np.ndarray], model: PandaModel, rot_nominal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(TCP position m, rotation vector relative to the nominal grasp) from the parts: the state's own pose, else
    forward kinematics of its joints."""
    if "ee_pos_m" in parts and ("ee_axis_angle_rad" in parts or "ee_rotvec_rad" in parts):
        rotvec = (parts["ee_rotvec_rad"] if "ee_rotvec_rad" in parts
                  else rotvec_from_rot(rot_from_axis_angle(parts["ee_axis_angle_rad"]), rot_nominal))
        return parts["ee_pos_m"].copy(), np.asarray(rotvec, dtype=np.float64)
    if "q_rad" in parts:
        pos, rot = model.fk(parts["q_rad"])
        return pos, rotvec_from_rot(rot, rot_nominal)
    raise ValueError("the convention's state carries neither the TCP pose (ee_pos_m + an orientation) nor the joints")


def decode_keys(mapping: KeyMapping, obs: dict, model: PandaModel, rot_nominal: np.ndarray,
                privileged: tuple[str, ...] = ()) -> Observation:
    """The ``Observation`` a key mapping's dict describes (what it does not carry: zeros, or None); ``privileged``:
    the parts that must arrive as ``mmact/<part>`` (a ``ValueError`` names the missing one)."""
    parts = _parts(mapping, obs)
    pos, rotvec = _pose(parts, model, rot_nominal)
    for p in privileged:
        key = f"mmact/{p}"
        if key not in obs:
            raise KeyError(f"observation lacks {key!r}: this server reads the true target (privileged), which the "
                           "client sends only when the server's metadata asks for it")
        parts[p] = np.asarray(obs[key], dtype=np.float64).reshape(-1)
    cams = mapping.camera_names
    keys = [k for k in mapping.images if k.camera in cams and not k.previous and k.key in obs]
    frames = [np.asarray(obs[k.key])[::-1, ::-1] if k.rotate_deg == 180 else np.asarray(obs[k.key]) for k in keys]
    image = np.stack(frames) if frames and len({f.shape for f in frames}) == 1 else None
    target = parts.get("target_pos_m", np.full(3, np.nan))
    gap = float(parts["frame_gap_s"][0]) if "frame_gap_s" in parts else 0.0
    return Observation(t0_s=float(parts["t0_s"][0]) if "t0_s" in parts else 0.0,
                       q_rad=parts.get("q_rad", np.zeros(7)).copy(), dq_rad_s=parts.get("dq_rad_s", np.zeros(7)).copy(),
                       ee_pos_m=pos, ee_rotvec_rad=rotvec, gripper_m=_gripper_m(parts), target_pos_m=target.copy(),
                       image=image, instruction=str(obs.get(mapping.prompt_key, "")) if mapping.prompt_key else "",
                       target_prev_pos_m=parts["target_prev_pos_m"].copy() if gap > 0 else None, frame_gap_s=gap)


class ConventionPolicy:
    """``source`` (a chunk source of ours) as an openpi policy speaking ``convention``.

    Args:
        source: the chunk source (its ``plan`` returns our task-space ``ActionChunk``).
        convention: the convention to speak (a :class:`~mmact_ctrl.sources.presets.Convention` with a key mapping).
        privileged: the privileged parts the source reads (declared in the metadata; the client sends them).
        infer_delay_ms: added to every call (to stand in for a slower model), ms.
        frame_check: optional ``check(obs_dict, observation)`` that raises when the frames are not what a policy of
            this convention was trained on (``scenarios.world.frame_check``).
        model: the robot model (None: the Panda's).
    """

    def __init__(self, source, convention, privileged: tuple[str, ...] = (), infer_delay_ms: float = 0.0,
                 frame_check=None, model: PandaModel | None = None) -> None:
        if not isinstance(convention.mapping, KeyMapping):
            raise ValueError(f"convention {convention.name!r} reads our own mmact keys: serve it without --preset")
        bad = [p for p in privileged if p not in PRIVILEGED_PARTS]
        if bad:
            raise ValueError(f"privileged parts {bad} are not of {PRIVILEGED_PARTS}")
        self.source, self.convention, self.privileged = source, convention, tuple(privileged)
        self.model = model if model is not None else PandaModel()
        self.encoder = ActionEncoder(convention.action, self.model)
        self._rot_nominal = self.model.fk(self.model.home_q_rad)[1]
        self.infer_delay_s = float(infer_delay_ms) / 1e3
        self.frame_check = frame_check
        horizon = getattr(getattr(source, "config", None), "horizon", None)
        self.metadata = {**({"action_horizon": int(horizon)} if horizon else {}),
                         "mmact": {"version": METADATA_VERSION, "source": source_name(source),
                                   "privileged": list(self.privileged)}}

    @property
    def name(self) -> str:
        return source_name(self.source)

    def infer(self, obs: dict) -> dict:
        """One chunk as the convention's actions (raises, naming the key or value, for an observation that does not
        fit the convention: the server sends that text to the client)."""
        t0 = time.perf_counter()
        observation = decode_keys(self.convention.mapping, obs, self.model, self._rot_nominal, self.privileged)
        if self.frame_check is not None:
            self.frame_check(obs, observation)
        chunk = self.source.plan(observation)
        if not isinstance(chunk, ActionChunk):
            raise TypeError(f"source {self.name!r} returned {type(chunk).__name__}, not an ActionChunk")
        if abs(float(chunk.dt_s) - float(self.convention.action.dt_s)) > 1e-9:
            raise ValueError(f"source {self.name!r} plans {chunk.dt_s:g} s apart, the convention {self.convention.name!r} "
                             f"{self.convention.action.dt_s:g} s")
        encoded = self.encoder.encode(chunk.waypoints, observation)
        wait = self.infer_delay_s - (time.perf_counter() - t0)
        if wait > 0:
            time.sleep(wait)
        return {"actions": encoded.actions.astype(np.float32),
                "policy_timing": {"infer_ms": (time.perf_counter() - t0) * 1e3}}
