"""The pick task's scripted expert: approach (with its lead), descend, close and lift, as waypoints with the gripper
channel, through the same action tokenizer as every other chunk.

It reads what one observation shows (the TCP, the gripper's opening, where the cube is and, with ``lead
velocity``, where it was 0.1 s earlier) and plans the rest of the grasp from there; nothing is remembered between
chunks, so whatever happened (a missed grasp, a drop) is planned from anew:

- **holding** (the gripper has closed on the cube, which is between the fingers): lift it ``LIFT_TO_M`` above the
  carrier and hold it there, gripper closed;
- **closing** (the gripper is closing, the cube between the fingers): stay with the cube (its predicted course),
  keep closing, then lift;
- **missed** (the gripper is closed but the cube is not between the fingers): open and rise to the approach height;
- **open**: a minimum-jerk approach to ``APPROACH_ABOVE_M`` above where the cube will be, a descent to the grasp
  height, the gripper closed once there (over ``CLOSE_S``), then the lift; each waypoint aims where the cube will be
  at its own time (the lead; ``lead none`` aims where the cube is now).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mmact_ctrl.chunk import ActionChunk, Observation
from policy.action_tokenizer import ActionTokenizer
from scenarios.world.expert import (GRIPPER_OPEN_M, LEADS, ExpertBase, expert_tokenizer, min_jerk,
                                    two_frame_velocity_m_s)
from scenarios.world.tasks.pick_scene import CUBE_HALF_M, CUBE_REST_Z_M

#: the approach passes this far above the cube before the descent, m
APPROACH_ABOVE_M = 0.07
#: the lift: the cube's centre this far above its resting height, m
LIFT_TO_M = 0.12
#: a cube within these of the TCP is between the fingers (horizontal, vertical), m
BETWEEN_XY_M, BETWEEN_Z_M = 0.02, 0.02
#: the gripper is closing below this opening, closed on a cube below this one, m
CLOSING_BELOW_M, CLOSED_ON_CUBE_M = 0.075, 2 * CUBE_HALF_M + 0.006
#: the descent starts from above the cube: the TCP within this of its course horizontally, and at most this above
#: the approach height, m
ABOVE_XY_M, ABOVE_Z_M = 0.015, 0.02
#: how long the descent, the closing and the wait before the lift take, s
DESCEND_S, CLOSE_S, SETTLE_S = 0.5, 0.3, 0.1
#: the grasp: the TCP (between the fingertip pads) this far above the cube's centre, m
GRASP_ABOVE_CENTRE_M = 0.006
#: a two-frame speed above this is a jump, not a motion (as the reach expert's), m/s
MAX_LEAD_SPEED_M_S = 0.8


@dataclass(frozen=True)
class PickExpertConfig:
    """Attributes: horizon (waypoints), dt_s (their spacing, s), approach_speed_m_s (average TCP speed of the approach),
    min_approach_s (s), lead (``none`` or ``velocity``)."""

    horizon: int = 16
    dt_s: float = 0.1
    approach_speed_m_s: float = 0.3
    min_approach_s: float = 0.5
    lead: str = "velocity"

    def __post_init__(self) -> None:
        if self.lead not in LEADS:
            raise ValueError(f"PickExpertConfig.lead must be one of {LEADS}, got {self.lead!r}")
        if self.horizon < 1 or not self.dt_s > 0:
            raise ValueError(f"PickExpertConfig: horizon >= 1 and dt_s > 0, got {self.horizon}, {self.dt_s}")


def cube_velocity_m_s(config: PickExpertConfig, obs: Observation) -> np.ndarray:
    """The cube's horizontal velocity from two frames (zero without the lead, an earlier frame, or at a jump)."""
    return two_frame_velocity_m_s(obs, config.lead, MAX_LEAD_SPEED_M_S, horizontal=True)


class PickExpert(ExpertBase):
    """``ChunkSource`` of the pick task (see the module)."""

    def __init__(self, config: PickExpertConfig = PickExpertConfig(), tokenizer: ActionTokenizer | None = None) -> None:
        super().__init__(config, tokenizer)

    def plan(self, obs: Observation) -> ActionChunk:
        cfg = self.config
        times = cfg.dt_s * np.arange(1, cfg.horizon + 1)
        cube = np.asarray(obs.target_pos_m, dtype=float)
        vel = cube_velocity_m_s(cfg, obs)
        course = cube + times[:, None] * vel  # where the cube will be at each waypoint's time
        tcp = np.asarray(obs.ee_pos_m, dtype=float)
        between = (np.linalg.norm((cube - tcp)[:2]) < BETWEEN_XY_M and abs(cube[2] - tcp[2]) < BETWEEN_Z_M)
        if obs.gripper_m < CLOSING_BELOW_M and between:
            actions = self._hold_and_lift(tcp, course, times, closed=obs.gripper_m < CLOSED_ON_CUBE_M)
        elif obs.gripper_m < CLOSING_BELOW_M:
            actions = self._reopen(tcp, times)
        else:
            actions = self._approach(tcp, course, times, cube)
        return self._finish(actions, obs)

    def _hold_and_lift(self, tcp: np.ndarray, course: np.ndarray, times: np.ndarray, closed: bool) -> np.ndarray:
        """Closing (the fingers not yet closed on the cube): stay on its course, keep closing, lift after
        ``CLOSE_S + SETTLE_S``. Holding: lift from where the TCP is, straight up to ``LIFT_TO_M``, and stay."""
        a = np.zeros((len(times), 7))
        start_s = 0.0 if closed else CLOSE_S + SETTLE_S
        s = min_jerk((times - start_s) / 0.6)
        a[:, :3] = tcp if closed else course
        a[:, 2] = tcp[2] + s * (CUBE_REST_Z_M + LIFT_TO_M - tcp[2])
        if not closed:
            a[:, 2] = course[:, 2] + s * (CUBE_REST_Z_M + LIFT_TO_M - course[:, 2])
        a[:, 6] = 0.0
        return a

    def _reopen(self, tcp: np.ndarray, times: np.ndarray) -> np.ndarray:
        """A missed grasp: open and rise to the approach height where the TCP is."""
        a = np.zeros((len(times), 7))
        s = min_jerk(times / 0.4)[:, None]
        up = np.array([tcp[0], tcp[1], max(tcp[2], CUBE_REST_Z_M + APPROACH_ABOVE_M)])
        a[:, :3] = tcp + s * (up - tcp)
        a[:, 6] = GRIPPER_OPEN_M
        return a

    def _approach(self, tcp: np.ndarray, course: np.ndarray, times: np.ndarray, cube_now: np.ndarray) -> np.ndarray:
        """Open: when the TCP is above the cube (within ``ABOVE_XY_M``), down onto its course, close, lift; else a
        minimum-jerk approach to ``APPROACH_ABOVE_M`` above the course and a hover along it (the next chunk, planned
        from above, descends). Every waypoint is on the cube's course at its own time (the lead)."""
        above = course + np.array([0.0, 0.0, APPROACH_ABOVE_M])
        near = float(np.linalg.norm((cube_now - tcp)[:2])) < ABOVE_XY_M and tcp[2] < above[0, 2] + ABOVE_Z_M
        if near:
            return self._descend_close_lift(tcp, course, times)
        cfg = self.config
        dist = float(np.linalg.norm(above[-1] - tcp))
        t_app = max(cfg.min_approach_s, dist / cfg.approach_speed_m_s)
        s_app = min_jerk(times / t_app)[:, None]
        a = np.zeros((len(times), 7))
        a[:, :3] = tcp + s_app * (above - tcp)
        a[:, 6] = GRIPPER_OPEN_M
        return a

    def _descend_close_lift(self, tcp: np.ndarray, course: np.ndarray, times: np.ndarray) -> np.ndarray:
        """From above the cube: down to its centre along its course, close once there, lift after ``SETTLE_S``."""
        s_down = min_jerk(times / DESCEND_S)[:, None]
        pos = course.copy()
        pos[:, 2] = tcp[2] + s_down[:, 0] * (course[:, 2] + GRASP_ABOVE_CENTRE_M - tcp[2])
        pos[:, :2] = tcp[:2] + np.minimum(1.0, 2.0 * s_down) * (course[:, :2] - tcp[:2])
        t_close = DESCEND_S
        s_lift = min_jerk((times - t_close - CLOSE_S - SETTLE_S) / 0.6)
        pos[:, 2] += s_lift * (CUBE_REST_Z_M + LIFT_TO_M - course[:, 2])
        a = np.zeros((len(times), 7))
        a[:, :3] = pos
        a[:, 6] = np.where(times < t_close, GRIPPER_OPEN_M, 0.0)
        return a


def make_pick_expert(bins: int = 2048, horizon: int = 16, dt_s: float = 0.1, lead: str = "velocity",
                     world=None) -> PickExpert:
    """The pick expert, its chunks quantized through the shared action tokenizer (bins 0: not quantized)."""
    tokenizer = expert_tokenizer(bins)
    return PickExpert(PickExpertConfig(horizon=horizon, dt_s=dt_s, lead=lead), tokenizer)
