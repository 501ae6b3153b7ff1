"""The pick task's scripted expert: approach (with its lead), descend, close and lift, as waypoints with the gripper
channel, through the same action tokenizer as every other chunk.

It reads what one observation shows (the TCP, the gripper's opening, where the cube is and, with ``lead
velocity``, where it was 0.1 s earlier) and plans the rest of the grasp from there; nothing is remembered between
chunks, so whatever happened (a missed grasp, a drop) is planned from anew:

- **holding** (the gripper has closed on the cube, which is between the fingers, or still in the pads' grip off
  the TCP across them, ``HELD_XY_M``): lift it ``LIFT_TO_M`` above the carrier and hold it there, gripper closed;
- **closing** (the gripper is closing, the cube between the fingers): stay with the cube (its predicted course),
  keep closing, then lift;
- **missed** (the gripper is closed but the cube is not between the fingers): open and rise to the approach height;
- **open**: a minimum-jerk approach to ``APPROACH_ABOVE_M`` above where the cube will be, a descent to the grasp
  height, the gripper closed once there (over ``CLOSE_S``), then the lift; each waypoint aims where the cube will be
  at its own time (the lead; ``lead none`` aims where the cube is now).

With the carrier's box known (``workspace_low_m`` / ``workspace_high_m``, read from the world as reach's expert
does), the predicted course is reflected at its walls, as the carrier's is, and the descent is timed around a
predicted bounce: the gripper does not close within ``BOUNCE_CLEAR_S`` after (or during the closing before) the cube
turns at a wall; the hand hovers along the course up to ``MAX_WAIT_S`` first, and if no start clears the bounce it
keeps hovering and the next chunk plans again. Every execution mode is given the same chunks.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mmact_ctrl.chunk import ActionChunk, Observation
from policy.action_tokenizer import ActionTokenizer
from scenarios.world.expert import (GRIPPER_OPEN_M, LEADS, ExpertBase, expert_tokenizer, min_jerk,
                                    two_frame_velocity_m_s)
from scenarios.world.motions import reflect_into_box
from scenarios.world.tasks.pick_scene import CUBE_HALF_M, CUBE_REST_Z_M

#: the approach passes this far above the cube before the descent, m
APPROACH_ABOVE_M = 0.07
#: the lift: the cube's centre this far above its resting height, m
LIFT_TO_M = 0.12
#: a cube within these of the TCP is between the fingers (horizontal, vertical), m
BETWEEN_XY_M, BETWEEN_Z_M = 0.02, 0.02
#: the gripper is closing below this opening, closed on a cube below this one, m
CLOSING_BELOW_M, CLOSED_ON_CUBE_M = 0.075, 2 * CUBE_HALF_M + 0.006
#: fingers closed on a cube measure at least this opening (less: closed on nothing), m; a cube they hold stays in
#: the pads' grip this far off the TCP horizontally, m (the pads centre it along the fingers' axis, and across it the
#: pads press its faces up to half its width plus theirs): a cube held 2-3 cm across the axis, lifted 12 cm, was taken
#: for a missed grasp, and the gripper reopened and dropped it
ON_CUBE_ABOVE_M, HELD_XY_M = 2 * CUBE_HALF_M - 0.01, 0.03
#: the descent starts from above the cube: the TCP within this of its course horizontally, and at most this above
#: the approach height, m
ABOVE_XY_M, ABOVE_Z_M = 0.015, 0.02
#: how long the descent, the closing and the wait before the lift take, s
DESCEND_S, CLOSE_S, SETTLE_S = 0.5, 0.3, 0.1
#: the grasp: the TCP (between the fingertip pads) this far above the cube's centre, m
GRASP_ABOVE_CENTRE_M = 0.006
#: a two-frame speed above this is a jump, not a motion (as the reach expert's), m/s
MAX_LEAD_SPEED_M_S = 0.8
#: the closing starts at least this long after a predicted wall bounce of the cube, s, and the descent waits above
#: the course at most this long (in steps of the chunk's spacing) for a start that clears it, s
BOUNCE_CLEAR_S, MAX_WAIT_S = 0.4, 0.5
#: the grid the predicted course is searched for bounces on, s
BOUNCE_GRID_S = 0.01


@dataclass(frozen=True)
class PickExpertConfig:
    """Attributes: horizon (waypoints), dt_s (their spacing, s), approach_speed_m_s (average TCP speed of the approach),
    min_approach_s (s), lead (``none`` or ``velocity``), workspace_low_m / workspace_high_m (the box the carrier
    moves the cube in: the predicted course reflects at its walls; None: unbounded)."""

    horizon: int = 16
    dt_s: float = 0.1
    approach_speed_m_s: float = 0.3
    min_approach_s: float = 0.5
    lead: str = "velocity"
    workspace_low_m: tuple[float, float, float] | None = None
    workspace_high_m: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        if (self.workspace_low_m is None) != (self.workspace_high_m is None):
            raise ValueError("PickExpertConfig: workspace_low_m and workspace_high_m are given together")
        if self.lead not in LEADS:
            raise ValueError(f"PickExpertConfig.lead must be one of {LEADS}, got {self.lead!r}")
        if self.horizon < 1 or not self.dt_s > 0:
            raise ValueError(f"PickExpertConfig: horizon >= 1 and dt_s > 0, got {self.horizon}, {self.dt_s}")


def cube_velocity_m_s(config: PickExpertConfig, obs: Observation) -> np.ndarray:
    """The cube's horizontal velocity from two frames (zero without the lead, an earlier frame, or at a jump)."""
    return two_frame_velocity_m_s(obs, config.lead, MAX_LEAD_SPEED_M_S, horizontal=True)


def predicted_course_m(config: PickExpertConfig, cube_m: np.ndarray, vel_m_s: np.ndarray,
                       times_s: np.ndarray) -> np.ndarray:
    """Where the cube will be at ``times_s`` (after the observation): constant velocity, reflected at the walls of
    the carrier's box when it is known (N, 3), m."""
    course = cube_m + np.asarray(times_s, dtype=float)[:, None] * vel_m_s
    if config.workspace_low_m is None or not np.any(vel_m_s):
        return course
    low, high = np.asarray(config.workspace_low_m, dtype=float), np.asarray(config.workspace_high_m, dtype=float)
    course[:, :2] = reflect_into_box(course[:, :2], low[:2], high[:2])
    return course


def bounce_times_s(config: PickExpertConfig, cube_m: np.ndarray, vel_m_s: np.ndarray, until_s: float) -> np.ndarray:
    """The times (after the observation, up to ``until_s``) at which the predicted course turns at a wall, s."""
    if config.workspace_low_m is None or not np.any(vel_m_s):
        return np.zeros(0)
    grid = np.arange(0.0, until_s + BOUNCE_GRID_S, BOUNCE_GRID_S)
    step = np.diff(predicted_course_m(config, cube_m, vel_m_s, grid)[:, :2], axis=0)
    turned = np.any(step[1:] * step[:-1] < 0.0, axis=1)
    return grid[1:-1][turned]


def descent_wait_s(config: PickExpertConfig, bounces_s: np.ndarray) -> float | None:
    """How long the descent waits above the course so that no predicted bounce falls in ``BOUNCE_CLEAR_S`` before
    the closing starts or during it: the shortest wait (a multiple of the chunk's spacing up to ``MAX_WAIT_S``), or
    None when none clears."""
    for wait in np.arange(0.0, MAX_WAIT_S + 1e-9, config.dt_s):
        close = wait + DESCEND_S
        if not np.any((bounces_s > close - BOUNCE_CLEAR_S) & (bounces_s < close + CLOSE_S)):
            return float(wait)
    return None


class PickExpert(ExpertBase):
    """``ChunkSource`` of the pick task (see the module)."""

    def __init__(self, config: PickExpertConfig = PickExpertConfig(), tokenizer: ActionTokenizer | None = None) -> None:
        super().__init__(config, tokenizer)

    def plan(self, obs: Observation) -> ActionChunk:
        cfg = self.config
        times = cfg.dt_s * np.arange(1, cfg.horizon + 1)
        cube = np.asarray(obs.target_pos_m, dtype=float)
        vel = cube_velocity_m_s(cfg, obs)
        course = predicted_course_m(cfg, cube, vel, times)  # where the cube will be at each waypoint's time
        tcp = np.asarray(obs.ee_pos_m, dtype=float)
        xy, dz = float(np.linalg.norm((cube - tcp)[:2])), abs(cube[2] - tcp[2])
        held = ON_CUBE_ABOVE_M < obs.gripper_m < CLOSED_ON_CUBE_M and xy < HELD_XY_M
        between = (xy < BETWEEN_XY_M or held) and dz < BETWEEN_Z_M
        if obs.gripper_m < CLOSING_BELOW_M and between:
            actions = self._hold_and_lift(tcp, course, times, closed=obs.gripper_m < CLOSED_ON_CUBE_M)
        elif obs.gripper_m < CLOSING_BELOW_M:
            actions = self._reopen(tcp, times)
        else:
            actions = self._approach(tcp, course, times, cube, vel)
        return self._finish(actions, obs)

    def _hold_and_lift(self, tcp: np.ndarray, course: np.ndarray, times: np.ndarray, closed: bool) -> np.ndarray:
        """Closing (the fingers not yet closed on the cube): stay on its course, keep closing, lift after
        ``CLOSE_S + SETTLE_S``. Holding: lift from where the TCP is, straight up to ``LIFT_TO_M``, and stay."""
        a = np.zeros((len(times), 7))
        start_s = 0.0 if closed else CLOSE_S + SETTLE_S
        s = min_jerk((times - start_s) / 0.6)
        a[:, :3] = tcp if closed else course
        a[:, 2] = tcp[2] + s * (CUBE_REST_Z_M + LIFT_TO_M - tcp[2])
        if not closed:  # at the grasp height, as the descent put it (it aimed at the cube's centre, 6 mm lower;
            grasp = course[:, 2] + GRASP_ABOVE_CENTRE_M  # the reversal's 50 seeds measured the same either way)
            a[:, 2] = grasp + s * (CUBE_REST_Z_M + LIFT_TO_M - grasp)
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

    def _approach(self, tcp: np.ndarray, course: np.ndarray, times: np.ndarray, cube_now: np.ndarray,
                  vel: np.ndarray) -> np.ndarray:
        """Open: when the TCP is above the cube (within ``ABOVE_XY_M``), down onto its course (after a wait that
        clears a predicted bounce, :func:`descent_wait_s`), close, lift; else a minimum-jerk approach to
        ``APPROACH_ABOVE_M`` above the course and a hover along it (the next chunk, planned from above, descends).
        Every waypoint is on the cube's course at its own time (the lead)."""
        above = course + np.array([0.0, 0.0, APPROACH_ABOVE_M])
        near = float(np.linalg.norm((cube_now - tcp)[:2])) < ABOVE_XY_M and tcp[2] < above[0, 2] + ABOVE_Z_M
        wait = None
        if near:
            wait = descent_wait_s(self.config, bounce_times_s(self.config, cube_now, vel, times[-1]))
        if wait is not None:
            return self._descend_close_lift(tcp, course, times, wait)
        cfg = self.config
        dist = float(np.linalg.norm(above[-1] - tcp))
        t_app = max(cfg.min_approach_s, dist / cfg.approach_speed_m_s)
        s_app = min_jerk(times / t_app)[:, None]
        a = np.zeros((len(times), 7))
        a[:, :3] = tcp + s_app * (above - tcp)
        a[:, 6] = GRIPPER_OPEN_M
        return a

    def _descend_close_lift(self, tcp: np.ndarray, course: np.ndarray, times: np.ndarray,
                            wait_s: float = 0.0) -> np.ndarray:
        """From above the cube: onto its course, down to its centre after ``wait_s``, close once there, lift after
        ``SETTLE_S``."""
        s_onto = min_jerk(times / DESCEND_S)[:, None]
        s_down = min_jerk((times - wait_s) / DESCEND_S)
        pos = course.copy()
        pos[:, 2] = tcp[2] + s_down * (course[:, 2] + GRASP_ABOVE_CENTRE_M - tcp[2])
        pos[:, :2] = tcp[:2] + np.minimum(1.0, 2.0 * s_onto) * (course[:, :2] - tcp[:2])
        t_close = wait_s + DESCEND_S
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
    box = {}
    if world is not None:  # the carrier's box, as reach's expert reads the target workspace
        box = dict(workspace_low_m=tuple(world.target.workspace_low_m), workspace_high_m=tuple(world.target.workspace_high_m))
    return PickExpert(PickExpertConfig(horizon=horizon, dt_s=dt_s, lead=lead, **box), tokenizer)
