"""Sources that speak other action spaces than ours: joint positions (DROID-style) and TCP deltas (LIBERO-style).

    python -m scenarios.moving_target --source examples.action_spaces:make_joint_source --target static --mode hybrid
    python -m scenarios.moving_target --source examples.action_spaces:make_delta_source --target static --mode hybrid

Each declares its ``action_space`` and returns an ``(H, D)`` array from ``plan``; the stack's adapter
(``mmact_ctrl.sources.action_space``) turns it into our task-space chunk (joint positions through the Pinocchio
model's forward kinematics), so every mode and every safety check applies unchanged. Both wrap the leading
example source (``examples.byo_source``) and convert its plan: joints by inverse kinematics from the observed
joints, deltas by subtracting the observed TCP pose.
"""

from __future__ import annotations

import numpy as np

from controllers.ik import solve_ik
from controllers.robot_model import PandaModel
from controllers.rotations import rot_from_rotvec
from examples.byo_source import LeadingSource
from mmact_ctrl.chunk import Observation
from mmact_ctrl.sources.action_space import ActionSpace, gripper_values


class JointPositionSource:
    """Answers absolute joint positions (7) + a gripper value in ``gripper`` convention per waypoint."""

    needs_image = False

    def __init__(self, horizon: int = 16, dt_s: float = 0.1, gripper: str = "close_1") -> None:
        self.inner = LeadingSource(horizon, dt_s)
        self.action_space = ActionSpace("joint_pos", gripper=gripper, dt_s=dt_s)
        self.model = PandaModel()
        _, self.rot_nominal = self.model.fk(self.model.home_q_rad)
        self.name = "example-joint-positions"

    def plan(self, observation: Observation) -> np.ndarray:
        chunk = self.inner.plan(observation)
        q = np.asarray(observation.q_rad, dtype=float)
        out = np.empty((chunk.horizon, 7 + (self.action_space.gripper != "none")))
        for i, w in enumerate(chunk.waypoints):
            q, _ = solve_ik(self.model, w[:3], rot_from_rotvec(w[3:6], self.rot_nominal), q)  # warm start: previous
            out[i, :7] = q
        out[:, 7:] = gripper_values(chunk.waypoints[:, 6], self.action_space.gripper).reshape(len(out), -1)
        return out


class TcpDeltaSource:
    """Answers TCP displacements and rotations relative to the pose at the observation, + a gripper value."""

    needs_image = False

    def __init__(self, horizon: int = 16, dt_s: float = 0.1, gripper: str = "sign", delta_from: str = "observation") -> None:
        self.inner = LeadingSource(horizon, dt_s)
        self.action_space = ActionSpace("tcp_delta", gripper=gripper, dt_s=dt_s, delta_from=delta_from)
        self.name = "example-tcp-deltas"

    def plan(self, observation: Observation) -> np.ndarray:
        w = self.inner.plan(observation).waypoints
        pose = np.concatenate([w[:, :3], w[:, 3:6]], axis=1)
        ref = np.concatenate([np.asarray(observation.ee_pos_m), np.asarray(observation.ee_rotvec_rad)])
        delta = pose - ref  # positions exactly; rotations: the chunk holds the nominal grasp, so the difference is small
        if self.action_space.delta_from == "previous":
            delta = np.diff(np.vstack([ref, pose]), axis=0)
        g = gripper_values(w[:, 6], self.action_space.gripper).reshape(len(w), -1)
        return np.concatenate([delta, g], axis=1)


def make_joint_source(horizon: int = 16, dt_s: float = 0.1, gripper: str = "close_1") -> JointPositionSource:
    return JointPositionSource(horizon, dt_s, gripper)


def make_delta_source(horizon: int = 16, dt_s: float = 0.1, gripper: str = "sign",
                      delta_from: str = "observation") -> TcpDeltaSource:
    return TcpDeltaSource(horizon, dt_s, gripper, delta_from)
