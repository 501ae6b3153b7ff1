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


def _quat_xyzw(rot: np.ndarray) -> np.ndarray:
    """Unit quaternion (x, y, z, w) of ``rot``, sign as Eigen gives it."""
    return np.asarray(pin.Quaternion(np.asarray(rot, dtype=np.float64)).coeffs(), dtype=np.float64)


def reference_quat(rot_ref: np.ndarray) -> np.ndarray:
    """The quaternion (x, y, z, w) of ``rot_ref`` that fixes a hemisphere: the sign with its largest component
    positive (for the nominal grasp, a half turn about x: (1, 0, 0, 0))."""
    q = _quat_xyzw(rot_ref)
    return q if q[int(np.argmax(np.abs(q)))] >= 0 else -q


def axis_angle_in_hemisphere(rot: np.ndarray, quat_ref_xyzw: np.ndarray) -> np.ndarray:
    """World-frame axis-angle (3,) rad of ``rot``, continuous near the reference orientation.

    The quaternion of ``rot`` is taken in the hemisphere of ``quat_ref_xyzw`` (``q . q_ref >= 0``) and turned into an
    axis-angle as robosuite's ``quat2axisangle`` does (angle ``2 acos(w)`` in [0, 2 pi], not folded into [0, pi]): the
    result is continuous for every orientation less than a half turn from the reference. A plain matrix logarithm
    (:func:`rotvec_from_rot` with the identity) folds the angle into [0, pi] and flips the axis where the angle crosses
    pi: around a hand pointing down (a half turn about x) it jumps by 2 pi between two calls where nothing moved."""
    q = _quat_xyzw(rot)
    if float(q @ np.asarray(quat_ref_xyzw, dtype=np.float64)) < 0.0:
        q = -q
    w = min(1.0, max(-1.0, float(q[3])))
    s = float(np.sqrt(max(0.0, 1.0 - w * w)))
    if s < 1e-12:  # no rotation (w = 1) or a full turn (w = -1): no axis
        return np.zeros(3)
    return q[:3] * (2.0 * float(np.arccos(w)) / s)


def rot_from_axis_angle(axis_angle_rad: np.ndarray) -> np.ndarray:
    """Rotation matrix of a world-frame axis-angle of any angle (the inverse of :func:`axis_angle_in_hemisphere`)."""
    return np.asarray(pin.exp3(np.asarray(axis_angle_rad, dtype=np.float64)))
