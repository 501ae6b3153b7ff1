"""Checking and conditioning what :meth:`~controllers.mpc.TaskSpaceMPC.solve` is given."""

from __future__ import annotations

from typing import Any

import numpy as np

from controllers.mpc.config import N_JOINTS


def as_array(name: str, value: Any, shape: tuple[int, ...]) -> np.ndarray:
    """Float64 copy of ``value`` with the given shape; ValueError naming ``name`` otherwise."""
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: not convertible to a float array ({exc})") from None
    if arr.shape != shape:
        raise ValueError(f"{name}: expected shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: contains NaN or inf")
    return arr


def as_sequence(name: str, value: Any, n: int) -> np.ndarray:
    """(n, 3) reference sequence; a single (3,) point is held over the horizon."""
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: not convertible to a float array ({exc})") from None
    if arr.shape == (3,):
        arr = np.tile(arr, (n, 1))
    if arr.shape != (n, 3):
        raise ValueError(f"{name}: expected shape ({n}, 3) or (3,), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: contains NaN or inf")
    return arr


def clamp_rows(vecs: np.ndarray, max_norm: float) -> np.ndarray:
    """Scale the rows of ``vecs`` whose norm exceeds ``max_norm`` down to ``max_norm`` (same unit as ``vecs``)."""
    norms = np.linalg.norm(vecs, axis=1, keepdims=True)
    return vecs * np.minimum(1.0, max_norm / np.maximum(norms, 1e-300))


def checked_inputs(n: int, t_s: Any, q_rad: Any, dq_rad_s: Any, ee_pos_m: Any, jacobian_6x7: Any, pos_ref_m: Any,
                   rotvec_err_ref_rad: Any) -> tuple[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                                     np.ndarray, np.ndarray]:
    """The arguments of ``solve`` as float64 arrays of their shapes (units as there), references as (n, 3).

    Returns:
        ``(t_s, q0, dq0, p0, jac, pos_ref, rot_ref)``; ``rot_ref`` is zeros when ``rotvec_err_ref_rad`` is None.

    Raises:
        ValueError: an argument has a wrong shape or is not finite.
    """
    t_s = float(t_s)
    if not np.isfinite(t_s):
        raise ValueError("t_s: not finite")
    q0 = as_array("q_rad", q_rad, (N_JOINTS,))
    dq0 = as_array("dq_rad_s", dq_rad_s, (N_JOINTS,))
    p0 = as_array("ee_pos_m", ee_pos_m, (3,))
    jac = as_array("jacobian_6x7", jacobian_6x7, (6, N_JOINTS))
    pos_ref = as_sequence("pos_ref_m", pos_ref_m, n)
    rot_ref = np.zeros((n, 3)) if rotvec_err_ref_rad is None else as_sequence("rotvec_err_ref_rad", rotvec_err_ref_rad, n)
    return t_s, q0, dq0, p0, jac, pos_ref, rot_ref
