"""The horizontal coordinated-turn (CT) motion model: a target that moves at constant speed while its horizontal
velocity turns at a constant rate ``omega`` (rad/s, about the world z axis; positive counter-clockwise seen from
above), and at constant vertical velocity. A circle at constant speed is exactly this motion, a straight line is
``omega = 0``.

State layout (10,), shared with the CV / CA modes of :mod:`controllers.target_estimator`'s ``imm-ct`` IMM:
``[pos (3) m, vel (3) m/s, acc (3) m/s^2, omega rad/s]``. In the CT model the acceleration is not free: it is the
centripetal acceleration ``omega z x v`` of the velocity (so a CT state mixed with a CA one means the same thing in
every slot), and the propagation ignores the acceleration it is given.

Pure numpy (it runs on a real arm).
"""

from __future__ import annotations

import numpy as np

DIM = 10  #: [pos(3), vel(3), acc(3), omega]
_SMALL_WT = 1e-4  # |omega h| below this: the series of sin / cos (no 0 / 0)


def _turn_coeffs(omega: float, h: float) -> tuple[float, float, float, float, float, float]:
    """``s = sin(wh) / w``, ``k = (1 - cos(wh)) / w``, ``cos(wh)``, ``sin(wh)`` and the derivatives ``ds/dw``,
    ``dk/dw`` (limits for w -> 0: h, 0, 1, 0, 0, h^2 / 2)."""
    wt = omega * h
    c, sn = np.cos(wt), np.sin(wt)
    if abs(wt) < _SMALL_WT:
        s = h * (1.0 - wt * wt / 6.0)
        k = h * (0.5 * wt - wt**3 / 24.0)
        ds = -omega * h**3 / 3.0
        dk = h * h * (0.5 - wt * wt / 8.0)
        return s, k, c, sn, ds, dk
    s, k = sn / omega, (1.0 - c) / omega
    ds = (h * c - s) / omega
    dk = (h * sn - k) / omega
    return s, k, c, sn, ds, dk


def ct_propagate(x: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """The state (10,) ``h`` s later under the CT model, and the Jacobian (10, 10) of that map (the EKF's F).

    Horizontal: ``v(t) = R(omega t) v``, ``p(t) = p + S(t) v`` with ``S`` the integral of the rotation; vertical:
    constant velocity; ``acc = omega z x v(t)``; ``omega`` constant."""
    p, v, w = x[:3], x[3:6], float(x[9])
    s, k, c, sn, ds, dk = _turn_coeffs(w, h)
    vx, vy = float(v[0]), float(v[1])
    nvx, nvy = c * vx - sn * vy, sn * vx + c * vy
    out = np.empty(DIM)
    out[0] = p[0] + s * vx - k * vy
    out[1] = p[1] + k * vx + s * vy
    out[2] = p[2] + h * v[2]
    out[3], out[4], out[5] = nvx, nvy, v[2]
    out[6], out[7], out[8] = -w * nvy, w * nvx, 0.0
    out[9] = w
    F = np.zeros((DIM, DIM))
    F[0, 0] = F[1, 1] = F[2, 2] = 1.0
    F[0, 3], F[0, 4], F[0, 9] = s, -k, ds * vx - dk * vy
    F[1, 3], F[1, 4], F[1, 9] = k, s, dk * vx + ds * vy
    F[2, 5] = h
    # d(cos wh)/dw = -h sin wh, d(sin wh)/dw = h cos wh
    dnvx_dw, dnvy_dw = -h * (sn * vx + c * vy), h * (c * vx - sn * vy)
    F[3, 3], F[3, 4], F[3, 9] = c, -sn, dnvx_dw
    F[4, 3], F[4, 4], F[4, 9] = sn, c, dnvy_dw
    F[5, 5] = 1.0
    # acc = (-w nvy, w nvx, 0)
    F[6, 3], F[6, 4], F[6, 9] = -w * sn, -w * c, -nvy - w * dnvy_dw
    F[7, 3], F[7, 4], F[7, 9] = w * c, -w * sn, nvx + w * dnvx_dw
    F[9, 9] = 1.0
    return out, F


def ct_extrapolate(x: np.ndarray, taus: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions and velocities (N, 3) ``taus`` (N,) s ahead of a CT state (10,): along the circle of turn rate
    ``x[9]`` (vectorized :func:`ct_propagate` without the Jacobian)."""
    taus = np.asarray(taus, dtype=float)
    p, v, w = x[:3], x[3:6], float(x[9])
    wt = w * taus
    c, sn = np.cos(wt), np.sin(wt)
    if abs(w) * float(np.max(np.abs(taus), initial=0.0)) < _SMALL_WT:
        s = taus * (1.0 - wt * wt / 6.0)
        k = taus * (0.5 * wt - wt**3 / 24.0)
    else:
        s, k = sn / w, (1.0 - c) / w
    vx, vy, vz = float(v[0]), float(v[1]), float(v[2])
    pos = np.empty((taus.size, 3))
    pos[:, 0] = p[0] + s * vx - k * vy
    pos[:, 1] = p[1] + k * vx + s * vy
    pos[:, 2] = p[2] + taus * vz
    vel = np.empty((taus.size, 3))
    vel[:, 0] = c * vx - sn * vy
    vel[:, 1] = sn * vx + c * vy
    vel[:, 2] = vz
    return pos, vel


def ct_process_noise(h: float, accel_var: float, turn_var: float) -> np.ndarray:
    """Process noise (10, 10) over ``h``: a white (piecewise-constant) acceleration of variance ``accel_var``
    (m/s^2)^2 per axis on position and velocity (``G = [h^2/2, h]``) and a white turn-rate acceleration of variance
    ``turn_var`` (rad/s^2)^2 on omega (``G = h``); the centripetal acceleration slot gets the velocity noise turned
    by omega through the Jacobian at the next step, none of its own."""
    Q = np.zeros((DIM, DIM))
    q = np.array([[0.25 * h**4, 0.5 * h**3], [0.5 * h**3, h**2]]) * accel_var
    for i in range(3):
        Q[i, i], Q[i, i + 3], Q[i + 3, i], Q[i + 3, i + 3] = q[0, 0], q[0, 1], q[1, 0], q[1, 1]
    Q[9, 9] = h * h * turn_var
    return Q
