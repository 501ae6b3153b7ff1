"""The inverse of an action space's adapter: our task-space waypoints written as another convention's actions.

:class:`ActionEncoder` turns a chunk's waypoints ``(H, 7)`` (TCP position m, rotation vector relative to the nominal
grasp rad, gripper opening m; ``mmact_ctrl.chunk``) answered to an ``Observation`` into the ``(H, D)`` actions of an
:class:`~mmact_ctrl.sources.action_space.ActionSpace`, such that that space's
:class:`~mmact_ctrl.sources.action_space.ActionAdapter` gives the waypoints back (to float precision; joint spaces
through inverse kinematics, ``controllers.ik``, to its tolerance). It lets a source of ours speak a foreign
convention (``mmact_ctrl.sources.remote.preset_serving``), which is how a convention is tested end to end: the same
expert, natively and through the convention, must give the same episodes.

Values that fall outside the space's ``clip`` range after unscaling are clipped (as a policy trained on that range
could not have answered them) and counted.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controllers.ik import IKConfig, solve_ik
from controllers.robot_model import PandaModel
from controllers.rotations import axis_angle_in_hemisphere, reference_quat, rot_from_rotvec, rotvec_from_rot
from mmact_ctrl.chunk import Observation
from mmact_ctrl.sources.action_space import ActionSpace, gripper_values

#: the IK the joint spaces are encoded with: tight enough that the adapter's forward kinematics gives the waypoint
#: back within a micrometre
ENCODE_IK = IKConfig(iterations=200, tol_m=1e-9, damping=1e-8, step_max_rad=0.2)


@dataclass(frozen=True)
class EncodedActions:
    """Actions of one space for one chunk.

    Attributes:
        actions: ``(H, D)`` float64.
        n_clipped: values that fell outside the space's clip range (clipped).
        ik_error_max: the largest pose error the inverse kinematics left (joint spaces; m + rad), else 0.
    """

    actions: np.ndarray
    n_clipped: int = 0
    ik_error_max: float = 0.0


class ActionEncoder:
    """Writes task-space waypoints as actions of ``space``.

    Args:
        space: the target action space.
        model: the robot model (None: the Panda's; its own buffers).
    """

    def __init__(self, space: ActionSpace, model: PandaModel | None = None) -> None:
        self.space = space
        self.model = model if model is not None else PandaModel()
        self._rot_nominal = self.model.fk(self.model.home_q_rad)[1]
        self._quat_nominal = reference_quat(self._rot_nominal)

    def _rots(self, waypoints: np.ndarray) -> list[np.ndarray]:
        return [rot_from_rotvec(w[3:6], self._rot_nominal) for w in waypoints]

    def _arm(self, w: np.ndarray, observation: Observation) -> tuple[np.ndarray, float]:
        """The arm columns ``(H, arm_dims)`` in m / rad (before scaling) and the largest IK error."""
        sp = self.space
        if sp.kind == "tcp_pose":
            if sp.rotation == "nominal":
                return w[:, :6].copy(), 0.0
            out = w[:, :6].copy()
            out[:, 3:] = [axis_angle_in_hemisphere(r, self._quat_nominal) for r in self._rots(w)]
            return out, 0.0
        if sp.kind == "tcp_delta":
            return self._tcp_deltas(w, observation), 0.0
        q_prev = np.asarray(observation.q_rad, dtype=np.float64)
        qs, err_max = np.empty((len(w), 7)), 0.0
        for i, rot in enumerate(self._rots(w)):
            qs[i], err = solve_ik(self.model, w[i, :3], rot, qs[i - 1] if i else q_prev, ENCODE_IK)
            err_max = max(err_max, err)
        if sp.kind == "joint_pos":
            return qs, err_max
        base = np.vstack([q_prev, qs[:-1]]) if sp.delta_from == "previous" else q_prev
        return qs - base, err_max

    def _tcp_deltas(self, w: np.ndarray, observation: Observation) -> np.ndarray:
        pos0 = np.asarray(observation.ee_pos_m, dtype=np.float64)
        rot0 = rot_from_rotvec(np.asarray(observation.ee_rotvec_rad, dtype=np.float64), self._rot_nominal)
        rots = self._rots(w)
        out = np.empty((len(w), 6))
        if self.space.delta_from == "previous":
            out[:, :3] = np.diff(np.vstack([pos0, w[:, :3]]), axis=0)
            prev = [rot0] + rots[:-1]
        else:
            out[:, :3] = w[:, :3] - pos0
            prev = [rot0] * len(rots)
        for i, (r, p) in enumerate(zip(rots, prev)):
            out[i, 3:] = rotvec_from_rot(r, p)  # the world-frame step that takes p to r: r = exp(step) p
        return out

    def encode(self, waypoints, observation: Observation) -> EncodedActions:
        """The actions of ``waypoints`` ``(H, 7)`` answered to ``observation``."""
        w = np.asarray(waypoints, dtype=np.float64)
        if w.ndim != 2 or w.shape[1] != 7 or len(w) < 1:
            raise ValueError(f"waypoints must have shape (H >= 1, 7), got {w.shape}")
        sp = self.space
        arm, err = self._arm(w, observation)
        arm = arm / sp.scale_vector
        grip = gripper_values(w[:, 6], sp.gripper).reshape(len(w), -1)
        a = np.hstack([arm, grip])
        n_clipped = 0
        if sp.clip is not None:
            outside = (a < sp.clip[0]) | (a > sp.clip[1])
            n_clipped = int(outside.sum())
            a = np.clip(a, sp.clip[0], sp.clip[1])
        return EncodedActions(actions=a, n_clipped=n_clipped, ik_error_max=float(err))
