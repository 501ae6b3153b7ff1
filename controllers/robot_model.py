"""Pinocchio model of the Panda arm: the dynamic and kinematic terms the QP and MPC need.

The two finger joints are locked (``pin.buildReducedModel``) at a fixed opening: their
mass is lumped into the hand, which is what the 7x7 arm block of the full mass matrix is.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from controllers.robot_description import ARM_JOINTS, FINGER_JOINTS, HOME_Q_RAD, TCP_FRAME, panda_urdf_path


@dataclass(frozen=True)
class RobotModelConfig:
    """Attributes:
    armature_kgm2: rotor inertia added to each arm joint (must equal the simulator's), kg*m^2.
    finger_opening_m: total gripper opening at which the fingers are locked, m.
    frame: the controlled frame (tool centre point).
    """

    armature_kgm2: tuple[float, ...] = (0.1,) * 7
    finger_opening_m: float = 0.08
    frame: str = TCP_FRAME

    def __post_init__(self) -> None:
        if len(self.armature_kgm2) != 7 or min(self.armature_kgm2) < 0:
            raise ValueError(f"armature_kgm2 must be 7 non-negative values, got {self.armature_kgm2}")
        if not 0.0 <= self.finger_opening_m <= 0.08:
            raise ValueError(f"finger_opening_m must be in [0, 0.08], got {self.finger_opening_m}")


@dataclass
class RobotTerms:
    """Terms at one joint state (arrays are owned by the model and overwritten on the next call).

    M: mass matrix incl. armature (7,7); h: bias torques incl. joint damping (7,) N*m;
    J: TCP Jacobian, LOCAL_WORLD_ALIGNED, rows [linear; angular] (6,7);
    dJv: TCP classical acceleration at zero joint acceleration (6,); pos_m: TCP position (3,);
    rot: TCP rotation (3,3); vel: TCP twist [linear m/s; angular rad/s] (6,).
    """

    M: np.ndarray
    h: np.ndarray
    J: np.ndarray
    dJv: np.ndarray
    pos_m: np.ndarray
    rot: np.ndarray
    vel: np.ndarray


class PandaModel:
    """Pinocchio Panda arm (7 DoF) built from the example-robot-data URDF."""

    def __init__(self, config: RobotModelConfig = RobotModelConfig()) -> None:
        self.config = config
        full = pin.buildModelFromUrdf(str(panda_urdf_path()))
        q_lock = pin.neutral(full)
        for name in FINGER_JOINTS:
            jid = full.getJointId(name)
            q_lock[full.joints[jid].idx_q] = config.finger_opening_m / 2.0
        locked = [full.getJointId(n) for n in FINGER_JOINTS]
        self.model = pin.buildReducedModel(full, locked, q_lock)
        names = tuple(self.model.names[i] for i in range(1, self.model.njoints))
        if names != ARM_JOINTS:  # pragma: no cover - description changed
            raise RuntimeError(f"unexpected joints in the Panda model: {names}")
        self.model.armature = np.asarray(config.armature_kgm2, dtype=np.float64)
        self.data = self.model.createData()
        self._kin_data = self.model.createData()  # for kinematics at other states: never overwrites ``terms``
        self.frame_id = self.model.getFrameId(config.frame)
        if self.frame_id >= self.model.nframes:
            raise ValueError(f"frame {config.frame!r} not in the Panda model")
        self.nv = self.model.nv
        self._damping = np.asarray(self.model.damping, dtype=np.float64).copy()
        self._lower = np.tril_indices(self.nv, -1)
        # pinocchio >= 3 fills the whole mass matrix in computeAllTerms; older versions only the upper triangle.
        q_test = pin.randomConfiguration(self.model)
        pin.computeAllTerms(self.model, self.data, q_test, np.ones(self.nv))
        self._symmetrize = not np.allclose(self.data.M, self.data.M.T, rtol=0.0, atol=1e-12)

    @property
    def home_q_rad(self) -> np.ndarray:
        return np.asarray(HOME_Q_RAD, dtype=np.float64)

    def terms(self, q_rad: np.ndarray, dq_rad_s: np.ndarray) -> RobotTerms:
        """All terms at ``(q, dq)``: one ``computeAllTerms`` pass (~7 us)."""
        m, d, fid = self.model, self.data, self.frame_id
        pin.computeAllTerms(m, d, q_rad, dq_rad_s)
        oMf = pin.updateFramePlacement(m, d, fid)
        M = d.M.copy()
        if self._symmetrize:
            M[self._lower] = M.T[self._lower]
        frame = pin.LOCAL_WORLD_ALIGNED
        # positional: RobotTerms(M, h, J, dJv, pos_m, rot, vel), a third of a microsecond under keywords every tick
        return RobotTerms(M, d.nle + self._damping * dq_rad_s, pin.getFrameJacobian(m, d, fid, frame),
                          pin.getFrameClassicalAcceleration(m, d, fid, frame).vector, oMf.translation, oMf.rotation,
                          pin.getFrameVelocity(m, d, fid, frame).vector)

    def kinematics(self, q_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """TCP position (3,) m, rotation (3,3) and Jacobian (6,7) LOCAL_WORLD_ALIGNED at ``q`` (copies), computed
        on a second data buffer so the arrays of the last :meth:`terms` stay valid."""
        m, d, fid = self.model, self._kin_data, self.frame_id
        pin.computeJointJacobians(m, d, q_rad)
        oMf = pin.updateFramePlacement(m, d, fid)
        J = pin.getFrameJacobian(m, d, fid, pin.LOCAL_WORLD_ALIGNED)
        return oMf.translation.copy(), oMf.rotation.copy(), np.array(J)

    def fk(self, q_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """TCP (position m, rotation) at ``q``."""
        pin.framesForwardKinematics(self.model, self.data, q_rad)
        oMf = self.data.oMf[self.frame_id]
        return oMf.translation.copy(), oMf.rotation.copy()

    def gravity(self, q_rad: np.ndarray) -> np.ndarray:
        """Gravity torques at ``q``, N*m."""
        return pin.computeGeneralizedGravity(self.model, self.data, q_rad).copy()
