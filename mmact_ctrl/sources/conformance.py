"""What looks wrong in a policy's reply for the convention it is said to speak.

A misread convention rarely raises: a chunk of the right shape with the wrong meaning runs, and the robot goes
somewhere else. :func:`reply_problems` reads one reply the way an engineer would before trusting it, and says in
one line each what does not fit the declared convention:

- values outside the convention's clip range (a normalised policy answers in [-1, 1]; metres or radians there are
  clipped away);
- a gripper value outside its convention's range;
- deltas that look like absolute poses (rows of ``tcp_delta`` within a few centimetres of the observed TCP
  position, rows of ``joint_delta`` within a few hundredths of a radian of the observed joints);
- absolute poses that look like deltas (``tcp_pose`` rows near the origin, ``joint_pos`` rows near zero, while the
  robot is elsewhere);
- motion the arm cannot make: a first waypoint far from the TCP, a TCP speed between waypoints beyond the Panda's
  1.7 m/s (the wrong scale or spacing), waypoints out of reach;
- a chunk length other than the convention's (a note: every waypoint is timed by its spacing, so it still runs).

Used by the conformance probe (``python -m scenarios.probe``) and by the connect check before the first episode.
"""

from __future__ import annotations

import numpy as np

from mmact_ctrl.chunk import Observation
from mmact_ctrl.sources.action_space import GRIPPER_MAX_M, ActionSpace

#: the Panda's TCP speed limit (Franka's control parameters), m/s
TCP_SPEED_MAX_M_S = 1.7
#: farther than this from the robot base no Panda TCP reaches, m
REACH_MAX_M = 0.95
#: a first waypoint farther than this from the observed TCP is a jump, not a step, m
FIRST_STEP_MAX_M = 0.25
#: each gripper convention's range (low, high) of valid values
GRIPPER_RANGES: dict[str, tuple[float, float]] = {"width_m": (0.0, GRIPPER_MAX_M), "open_1": (0.0, 1.0),
                                                  "close_1": (0.0, 1.0), "sign": (-1.0, 1.0)}
#: how each gripper convention reads
GRIPPER_MEANING: dict[str, str] = {"width_m": "opening in m (0.08 open, 0 closed)", "open_1": "1 open, 0 closed",
                                   "close_1": "1 closed, 0 open", "sign": "-1 open, +1 closed", "none": "no value (open)"}
_TOL = 1e-6


def _range_problems(a: np.ndarray, space: ActionSpace) -> list[str]:
    out = []
    if space.clip is not None:
        lo, hi = space.clip
        outside = (a < lo - _TOL) | (a > hi + _TOL)
        if outside.any():
            worst = float(np.abs(a[outside]).max())
            out.append(f"{int(outside.sum())} of {a.size} action values lie outside [{lo:g}, {hi:g}] (up to {worst:.3g}) "
                       "and are clipped: is the reply normalised as the convention says?")
    if space.gripper in GRIPPER_RANGES:
        lo, hi = GRIPPER_RANGES[space.gripper]
        g = a[:, -1]
        if (g < lo - 1e-3 * max(1.0, hi)).any() or (g > hi + 1e-3 * max(1.0, hi)).any():
            out.append(f"gripper values {float(g.min()):.3g} .. {float(g.max()):.3g} lie outside the {space.gripper} "
                       f"convention's [{lo:g}, {hi:g}] ({GRIPPER_MEANING[space.gripper]}): another gripper convention?")
    return out


def _meaning_problems(a: np.ndarray, space: ActionSpace, observation: Observation) -> list[str]:
    """Deltas that look absolute, absolute poses that look like deltas (in the reply's own units, scaled)."""
    arm = a[:, :space.arm_dims] * space.scale_vector
    ee = np.asarray(observation.ee_pos_m, dtype=float)
    q = np.asarray(observation.q_rad, dtype=float)
    raw = a[:, :space.arm_dims]
    kind = space.kind
    if kind == "tcp_delta" and np.linalg.norm(ee) > 0.1:
        near = [(np.linalg.norm(v[:, :3] - ee, axis=1) < 0.03).all() for v in (arm, raw)]
        if any(near):
            return [f"every tcp_delta row is within 3 cm of the observed TCP position"
                    f"{'' if near[0] else ' before scaling'}: absolute positions sent as deltas?"]
    if kind == "joint_delta" and np.abs(q).max() > 0.3:
        near = [(np.abs(v - q).max(axis=1) < 0.05).all() for v in (arm, raw)]
        if any(near):
            return [f"every joint_delta row is within 0.05 rad of the observed joints"
                    f"{'' if near[0] else ' before scaling'}: absolute joints sent as deltas?"]
    if kind == "tcp_pose" and np.linalg.norm(ee) > 0.2 and (np.linalg.norm(arm[:, :3], axis=1) < 0.05).all():
        return [f"every tcp_pose position is within 5 cm of the robot base while the TCP is {np.linalg.norm(ee):.2f} m "
                "away: deltas sent as absolute poses?"]
    if kind == "joint_pos" and np.abs(q).max() > 0.5 and (np.abs(arm).max(axis=1) < 0.1).all():
        return ["every joint_pos row is within 0.1 rad of zero while the joints are not: deltas sent as positions?"]
    if kind in ("tcp_delta", "joint_delta") and space.delta_from == "observation" and len(arm) >= 4:
        size = np.linalg.norm(arm[:, :3] if kind == "tcp_delta" else arm, axis=1)
        if size.max() > 1e-3 and size[-1] < 0.5 * size.max() and size.sum() > 2.5 * size.max():
            return [f"the rows grow and shrink again (largest {size.max():.3g}, last {size[-1]:.3g}) as successive steps "
                    "do, where deltas from the observation would grow: --delta-from previous?"]
    return []


def _motion_problems(waypoints: np.ndarray, dt_s: float, observation: Observation) -> list[str]:
    out = []
    ee = np.asarray(observation.ee_pos_m, dtype=float)
    pos = np.vstack([ee, waypoints[:, :3]])
    steps = np.linalg.norm(np.diff(pos, axis=0), axis=1)
    if steps[0] > FIRST_STEP_MAX_M:
        out.append(f"the first waypoint is {steps[0]:.3f} m from the TCP: another frame or other units?")
    speed = float(steps.max()) / float(dt_s)
    if speed > TCP_SPEED_MAX_M_S:
        out.append(f"steps of up to {float(steps.max()):.3f} m every {dt_s:g} s imply {speed:.2f} m/s at the TCP, beyond the "
                   f"Panda's {TCP_SPEED_MAX_M_S:g} m/s: the wrong scale, or the wrong spacing?")
    reach = float(np.linalg.norm(waypoints[:, :3], axis=1).max())
    if reach > REACH_MAX_M:
        out.append(f"waypoints reach {reach:.2f} m from the robot base, beyond the Panda's {REACH_MAX_M:g} m")
    return out


def reply_problems(actions, space: ActionSpace, observation: Observation, waypoints: np.ndarray | None,
                   horizon: int | None = None) -> list[str]:
    """What looks wrong in ``actions`` (the raw ``(H, D)`` reply) for ``space`` answered to ``observation``;
    ``waypoints``: the same chunk in our task space (None when it could not be converted); ``horizon``: the chunk
    length the convention's models emit. Empty: nothing looks wrong."""
    a = np.asarray(actions, dtype=np.float64)
    if a.ndim == 3 and a.shape[0] == 1:
        a = a[0]
    if a.ndim != 2 or a.shape[1] != space.dims:
        return [f"actions of shape {a.shape} do not fit {space.describe()}: expected (H, {space.dims})"]
    if not np.all(np.isfinite(a)):
        return [f"actions contain NaN or inf ({int((~np.isfinite(a)).sum())} values)"]
    out = _range_problems(a, space) + _meaning_problems(a, space, observation)
    if waypoints is not None:
        out += _motion_problems(np.asarray(waypoints, dtype=float), float(space.dt_s), observation)
    if horizon is not None and len(a) != horizon:
        out.append(f"(note) {len(a)} waypoints a chunk where the convention's models emit {horizon}: each is timed by "
                   "the spacing, so it runs; check that the spacing is right")
    return out
