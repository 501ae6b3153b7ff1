"""Inverse kinematics of the TCP pose: damped least squares on the Pinocchio model, within the joint limits.

Used where a joint-space answer is wanted for a task-space pose (a joint-position policy's labels, an example
source that speaks joints); the 1 kHz controller itself never needs it (it controls the TCP directly).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controllers.robot_description import JointLimits
from controllers.robot_model import PandaModel
from controllers.rotations import orientation_error


@dataclass(frozen=True)
class IKConfig:
    """Attributes:
    iterations: at most this many Gauss-Newton steps.
    tol_m: stop when the position error is below this (m) and the orientation error below ``tol_m`` rad per m.
    damping: Levenberg-Marquardt damping of the 6x6 normal equations.
    step_max_rad: largest joint step per iteration, rad.
    """

    iterations: int = 60
    tol_m: float = 1e-5
    damping: float = 1e-4
    step_max_rad: float = 0.2


def solve_ik(model: PandaModel, pos_m: np.ndarray, rot: np.ndarray, q_init_rad: np.ndarray,
             config: IKConfig = IKConfig(), limits: JointLimits = JointLimits()) -> tuple[np.ndarray, float]:
    """Joint positions (7,) rad that put the TCP at ``pos_m`` (3,) with rotation ``rot`` (3, 3), starting from
    ``q_init_rad``, clipped to the joint limits; and the remaining pose error (position m + orientation rad)."""
    lo, hi = np.asarray(limits.q_min_rad), np.asarray(limits.q_max_rad)
    q = np.clip(np.asarray(q_init_rad, dtype=float).copy(), lo, hi)
    err = np.inf
    for _ in range(config.iterations):
        p, r, jac = model.kinematics(q)
        e = np.concatenate([np.asarray(pos_m, dtype=float) - p, orientation_error(rot, r)])
        err = float(np.linalg.norm(e[:3]) + np.linalg.norm(e[3:]))
        if err < config.tol_m:
            break
        dq = jac.T @ np.linalg.solve(jac @ jac.T + config.damping * np.eye(6), e)
        dq *= min(1.0, config.step_max_rad / max(1e-12, float(np.abs(dq).max())))
        q = np.clip(q + dq, lo, hi)
    return q, err
