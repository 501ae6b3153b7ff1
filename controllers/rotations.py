"""Orientation helpers: the action's rotation vector is relative to a nominal grasp orientation.

Convention: ``R = exp(rotvec) @ R_nominal`` (a world-frame perturbation of the nominal).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin


def rotvec_from_rot(rot: np.ndarray, rot_nominal: np.ndarray) -> np.ndarray:
    """Rotation vector (rad, world frame) of ``rot`` relative to ``rot_nominal``."""
    return np.asarray(pin.log3(rot @ rot_nominal.T))


def rot_from_rotvec(rotvec_rad: np.ndarray, rot_nominal: np.ndarray) -> np.ndarray:
    """Inverse of :func:`rotvec_from_rot`."""
    return np.asarray(pin.exp3(np.asarray(rotvec_rad, dtype=np.float64))) @ rot_nominal


def orientation_error(rot_des: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """World-frame rotation vector taking ``rot`` to ``rot_des`` (rad)."""
    return np.asarray(pin.log3(rot_des @ rot.T))
