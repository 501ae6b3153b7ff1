"""The external wrench on the robot, from MuJoCo's contacts: what a real Panda reports as ``O_F_ext_hat_K`` (the
force and torque its joint-torque sensors attribute to the end effector), here summed exactly over the contacts
between the robot's geoms and anything else, and referred to the TCP in the world frame."""

from __future__ import annotations

import mujoco
import numpy as np


def robot_geom_mask(model: mujoco.MjModel, robot_bodies: set[int]) -> np.ndarray:
    """Per geom: whether it belongs to one of ``robot_bodies``."""
    return np.isin(model.geom_bodyid, np.fromiter(robot_bodies, dtype=np.int64))


def external_wrench(model: mujoco.MjModel, data: mujoco.MjData, robot_geom: np.ndarray,
                    tcp_pos_m: np.ndarray) -> np.ndarray:
    """The wrench (6,) on the robot from its contacts with everything else: force N, torque about ``tcp_pos_m`` N m,
    world frame. The moment arm's cross product is written out on scalars: the same products and differences as
    ``np.cross`` (the same bits), without its per-call axis handling (it was 2/3 of a pick episode's time)."""
    out = np.zeros(6)
    f6 = np.zeros(6)
    for i in range(data.ncon):
        c = data.contact[i]
        r1, r2 = robot_geom[c.geom1], robot_geom[c.geom2]
        if r1 == r2:
            continue
        mujoco.mj_contactForce(model, data, i, f6)
        frame = c.frame.reshape(3, 3)
        force = frame.T @ f6[:3]  # on geom2 from geom1, world frame
        if r2 == 0:  # the robot is geom1: it feels the opposite
            force = -force
        out[:3] += force
        d = c.pos - tcp_pos_m
        fx, fy, fz = force
        dx, dy, dz = d
        out[3] += dy * fz - dz * fy
        out[4] += dz * fx - dx * fz
        out[5] += dx * fy - dy * fx
    return out
