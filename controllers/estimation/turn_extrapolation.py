"""Extrapolating a constant-acceleration state along a turn: :func:`turn_extrapolate` (the CA model's and the IMMs'
CA-mode prediction)."""

from __future__ import annotations

import numpy as np


def turn_extrapolate(x: np.ndarray, taus: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions (m) and velocities (m/s) (N, 3) ``taus`` (N,) s ahead of a [pos, vel, acc] state, as a
    *coordinated turn*: the acceleration's part across the velocity turns the velocity at
    ``omega = |a_perp| / |v|`` about ``v x a_perp`` (a circle), the part along it speeds the target up or down (a
    parabola; weighted by how much of the acceleration is along the velocity, see the comment in the body). For a
    target on a circle the polynomial ``p + v t + a t^2 / 2`` leaves the circle along a parabola (40 mm off after
    200 ms at 0.4 m/s on an 8 cm circle); this stays on it. Below 2 cm/s, or when the turn rate would exceed
    20 rad/s, the polynomial."""
    p, v, a = x[:3], x[3:6], x[6:9]
    taus = np.asarray(taus, dtype=float)
    speed = float(np.linalg.norm(v))
    if speed < 0.02:
        return (p + np.multiply.outer(taus, v) + np.multiply.outer(0.5 * taus**2, a),
                v + np.multiply.outer(taus, a))
    v_hat = v / speed
    a_along = float(a @ v_hat)
    a_perp = a - a_along * v_hat
    # On a turn, the CA filter's acceleration lags the true (rotating) one by a phase phi (0.45 rad on the 0.4 m/s,
    # 8 cm circle at 100 Hz): its along-track part, |a| sin(phi), is mostly that lag, not a speed change, and as a
    # parabola it left the circle by 60 mm in 0.4 s (the MPC's preview). It is trusted as far as the acceleration
    # is along the velocity: scaled by cos^2 of their angle (a speeding-up line keeps it, a circle drops ~80 %).
    a_sq = float(a @ a)
    a_par = (a_along * (a_along * a_along / a_sq) if a_sq > 0.0 else 0.0) * v_hat
    omega = float(np.linalg.norm(a_perp)) / speed
    if omega < 1e-6 or omega > 20.0:
        return (p + np.multiply.outer(taus, v) + np.multiply.outer(0.5 * taus**2, a),
                v + np.multiply.outer(taus, a))
    wt = omega * taus
    sin_w, cos_w = np.sin(wt), np.cos(wt)
    pos = (p + np.multiply.outer(sin_w / omega, v) + np.multiply.outer((1.0 - cos_w) / omega**2, a_perp)
           + np.multiply.outer(0.5 * taus**2, a_par))
    vel = np.multiply.outer(cos_w, v) + np.multiply.outer(sin_w / omega, a_perp) + np.multiply.outer(taus, a_par)
    return pos, vel
