"""The damped null-space projector of the TCP Jacobian (the posture term's parameter)."""

from __future__ import annotations

import numpy as np


def null_projector(jacobian_6x7: np.ndarray, damping: float) -> np.ndarray:
    """``I - J^T (J J^T + damping^2 I)^-1 J`` (7x7, symmetric): the projector onto the joint motions that do not move
    the TCP (the self-motion of a 7-DoF arm), damped so that it is continuous across singularities (directions with
    singular values well below ``damping``, m or rad, count as null space)."""
    j = np.asarray(jacobian_6x7, dtype=float)
    jjt = j @ j.T + (damping * damping) * np.eye(j.shape[0])
    return np.eye(j.shape[1]) - j.T @ np.linalg.solve(jjt, j)
