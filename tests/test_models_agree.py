"""MuJoCo (scenarios.world.panda_scene) and Pinocchio load the same URDF: their dynamics must agree.

At 20 random arm configurations within the joint limits (fingers locked at the open gripper,
0.04 m each, in both models) we compare the 7x7 arm block of the joint-space mass matrix (with the
scene's armature on both sides), the gravity torques, and the pose of MuJoCo's ``tcp`` site vs
Pinocchio's ``panda_hand_tcp`` frame.

Tolerance: |mujoco - pinocchio| <= 1e-6 * |pinocchio| + 1e-9 elementwise (``rtol=1e-6``,
``atol=1e-9`` in kg*m^2, N*m, m and rotation-matrix units). Measured agreement is ~1e-15.
"""

from __future__ import annotations

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from controllers.robot_description import ARM_JOINTS, FINGER_JOINTS, TCP_FRAME, JointLimits, panda_urdf_path
from scenarios.world.panda_scene import (
    GRIPPER_MAX_M,
    SceneConfig,
    arm_dof_adr,
    arm_qpos_adr,
    build_panda_model,
    finger_qpos_adr,
    tcp_site_id,
)

RTOL, ATOL = 1e-6, 1e-9
N_CONFIGS = 20


@pytest.fixture(scope="module")
def models():
    scene = SceneConfig(armature_kgm2=(0.1, 0.1, 0.1, 0.1, 0.05, 0.05, 0.05))
    mj_model = build_panda_model(scene)
    full = pin.buildModelFromUrdf(str(panda_urdf_path()))
    q_full = pin.neutral(full)
    lock_ids = []
    for name in FINGER_JOINTS:
        jid = full.getJointId(name)
        lock_ids.append(jid)
        q_full[full.joints[jid].idx_q] = GRIPPER_MAX_M / 2.0
    reduced = pin.buildReducedModel(full, lock_ids, q_full)
    assert tuple(reduced.names[1:]) == ARM_JOINTS
    reduced.armature = np.asarray(scene.armature_kgm2, dtype=float)
    return mj_model, reduced


def _random_configs(seed: int = 0) -> np.ndarray:
    lim = JointLimits().arrays()
    rng = np.random.default_rng(seed)
    return rng.uniform(lim["q_min_rad"], lim["q_max_rad"], size=(N_CONFIGS, len(ARM_JOINTS)))


def test_mass_gravity_and_tcp_agree(models):
    mj_model, pin_model = models
    pin_data = pin_model.createData()
    mj_data = mujoco.MjData(mj_model)
    qadr, dadr = arm_qpos_adr(mj_model), arm_dof_adr(mj_model)
    tcp = tcp_site_id(mj_model)
    frame_id = pin_model.getFrameId(TCP_FRAME)
    full_m = np.zeros((mj_model.nv, mj_model.nv))
    for q in _random_configs():
        mj_data.qpos[:] = 0.0
        mj_data.qpos[qadr] = q
        mj_data.qpos[finger_qpos_adr(mj_model)] = GRIPPER_MAX_M / 2.0
        mj_data.qvel[:] = 0.0
        mujoco.mj_forward(mj_model, mj_data)

        mujoco.mj_fullM(mj_model, mj_data, full_m)
        m_mj = full_m[np.ix_(dadr, dadr)]
        m_pin = pin.crba(pin_model, pin_data, q)
        m_pin = np.triu(m_pin) + np.triu(m_pin, 1).T
        np.testing.assert_allclose(m_mj, m_pin, rtol=RTOL, atol=ATOL, err_msg=f"mass matrix at q={q}")

        g_pin = pin.computeGeneralizedGravity(pin_model, pin_data, q)
        np.testing.assert_allclose(mj_data.qfrc_bias[dadr], g_pin, rtol=RTOL, atol=ATOL, err_msg=f"gravity at q={q}")

        pin.framesForwardKinematics(pin_model, pin_data, q)
        placement = pin_data.oMf[frame_id]
        np.testing.assert_allclose(mj_data.site_xpos[tcp], placement.translation, rtol=RTOL, atol=ATOL,
                                   err_msg=f"TCP position at q={q}")
        np.testing.assert_allclose(mj_data.site_xmat[tcp].reshape(3, 3), placement.rotation, rtol=RTOL, atol=ATOL,
                                   err_msg=f"TCP orientation at q={q}")


def test_armature_is_in_both_mass_matrices(models):
    """The armature must really be on the diagonal (else the test above could pass vacuously)."""
    mj_model, pin_model = models
    np.testing.assert_allclose(mj_model.dof_armature[arm_dof_adr(mj_model)], pin_model.armature)
    q = _random_configs(1)[0]
    data = pin_model.createData()
    with_arm = pin.crba(pin_model, data, q).copy()
    bare = pin_model.copy()
    bare.armature = np.zeros(7)
    without = pin.crba(bare, bare.createData(), q)
    np.testing.assert_allclose(np.diag(with_arm - without), pin_model.armature, atol=1e-12)
