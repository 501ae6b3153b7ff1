"""The action of each dataset frame: the command active at that frame, read from the chunks an episode executed.

A dataset frame ``m`` is taken at ``t_m = m / fps``. Its action is what the robot was being driven toward then: the
chunk active at ``t_m`` (the last one activated at or before it) evaluated at the next frame's time
``t_(m+1)``, the pose the command asks the robot to reach by the next frame (LeRobot's convention: ``action[m]`` is
the target that ``observation.state[m+1]`` answers). Between a chunk's waypoints the position and the gripper are
interpolated linearly and the orientation by slerp; before its first waypoint the first is held, after its last the
last (as :class:`~mmact_ctrl.reference.ChunkReference` holds them). Before any chunk is active the robot holds its
start pose, and that is the action.

At ``fps = 1 / chunk dt`` (10 Hz for our 0.1 s waypoints) every action is a waypoint as the source sent it; at 20 or
30 fps the waypoints are interpolated.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

#: a time within this of a waypoint's or an activation's time is that time, s
TIME_EPS_S = 1e-9


@dataclass(frozen=True)
class ChunkActivation:
    """A chunk as it was executed.

    Attributes:
        t_active_s: when it became active, s.
        times_s: its waypoints' times (H,), s.
        waypoints: ``(H, 7)`` ``[x, y, z (m), rx, ry, rz (rad, rotation vector relative to the nominal grasp),
            gripper (m)]``.
    """

    t_active_s: float
    times_s: np.ndarray
    waypoints: np.ndarray


def slerp_rotvec(a_rad: np.ndarray, b_rad: np.ndarray, s: float) -> np.ndarray:
    """The rotation a fraction ``s`` of the way from ``a`` to ``b`` along the shortest arc, as a world-frame rotation
    vector (both rotation vectors relative to the same nominal orientation: ``R = exp(r) R_nominal``)."""
    ra, rb = pin.exp3(np.asarray(a_rad, dtype=float)), pin.exp3(np.asarray(b_rad, dtype=float))
    return np.asarray(pin.log3(pin.exp3(s * pin.log3(rb @ ra.T)) @ ra))


def chunk_value_at(chunk: ChunkActivation, t_s: float) -> np.ndarray:
    """The chunk's command (7,) at ``t_s``: linear in position and gripper, slerp in orientation between the
    bracketing waypoints; the first waypoint held before its time, the last after its time."""
    times, w = chunk.times_s, chunk.waypoints
    if t_s <= times[0] + TIME_EPS_S:
        return w[0].copy()
    if t_s >= times[-1] - TIME_EPS_S:
        return w[-1].copy()
    i = int(np.searchsorted(times, t_s, side="right")) - 1
    if abs(t_s - times[i]) <= TIME_EPS_S:
        return w[i].copy()
    s = float((t_s - times[i]) / (times[i + 1] - times[i]))
    out = (1.0 - s) * w[i] + s * w[i + 1]
    out[3:6] = slerp_rotvec(w[i, 3:6], w[i + 1, 3:6], s)
    return out


def frame_actions(activations: list[ChunkActivation], hold_action: np.ndarray, n_frames: int,
                  fps: int) -> np.ndarray:
    """``(n_frames, 7)`` float64: frame ``m``'s action, the chunk active at ``m / fps`` at ``(m + 1) / fps``
    (``hold_action`` (7,), the start pose, before any chunk is active)."""
    out = np.empty((n_frames, 7))
    starts = np.array([a.t_active_s for a in activations])
    for m in range(n_frames):
        t_m = m / fps
        j = int(np.searchsorted(starts, t_m + TIME_EPS_S, side="right")) - 1
        out[m] = hold_action if j < 0 else chunk_value_at(activations[j], (m + 1) / fps)
    return out
