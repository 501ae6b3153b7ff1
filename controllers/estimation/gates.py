"""The gates a measurement passes before it may touch the estimate: non-finite (NaN, inf, a wrong shape or type; the
estimator gates a non-finite time stamp the same way), frozen (bit for bit the previous measurement: a real sensor's
noise never repeats, a stalled driver re-sends its last value), and outlier (an innovation far outside the
estimate's belief: a squared Mahalanobis distance above ``reset_gate``). What is gated is counted by the estimator,
never fused; consecutive outliers that agree with each other are a jump (:mod:`controllers.estimation.jumps`)."""

from __future__ import annotations

import numpy as np


def screen(z_m, last_z_m: np.ndarray | None, frozen_gate: bool) -> tuple[np.ndarray | None, str | None]:
    """``(z, None)``: the measurement as a new (3,) float64 array, m, if it passes the non-finite and frozen gates;
    else ``(None, "nonfinite" | "frozen")``. The frozen gate (``frozen_gate``) compares with ``last_z_m``, the
    previous measurement that passed, in arrival order (a stalled driver re-sends)."""
    try:
        z = np.asarray(z_m, dtype=np.float64)
    except (TypeError, ValueError):
        return None, "nonfinite"
    if z.shape != (3,) or not np.all(np.isfinite(z)):
        return None, "nonfinite"
    if frozen_gate and last_z_m is not None and np.array_equal(z, last_z_m):
        return None, "frozen"
    return z.copy(), None


def innovation_d2(z_m: np.ndarray, x_pred: np.ndarray, P_pred: np.ndarray, R: np.ndarray) -> float:
    """Squared Mahalanobis distance (dimensionless) of the measured position ``z_m`` (3,) m from the predicted
    state's position (mean ``x_pred``, covariance ``P_pred``), with the measurement noise covariance ``R`` (3, 3)
    m^2: the outlier gate compares it with ``reset_gate``."""
    y = z_m - x_pred[:3]
    S = P_pred[:3, :3] + R
    return float(y @ np.linalg.solve(S, y))
