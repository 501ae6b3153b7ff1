"""The insert task's scripted expert: over the hole (with its lead), down to the mouth, and in, as waypoints with the
gripper closed on the peg, through the same action tokenizer as every other chunk.

It reads one observation (the TCP, where the hole's mouth is and, with ``lead velocity``, where it was 0.1 s earlier)
and plans from there, nothing remembered: above the mouth (the peg's bottom ``ABOVE_M`` over it) it descends
``INSERT_SPEED_M_S`` into the hole to ``PUSH_M`` below the seat; elsewhere it first moves there. The peg's bottom is
taken to be ``PEG_BELOW_TCP_M`` under the TCP, where the task's reset puts it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mmact_ctrl.chunk import ActionChunk, Observation
from policy.action_tokenizer import ActionTokenizer
from scenarios.world.expert import LEADS, ExpertBase, expert_tokenizer, min_jerk, two_frame_velocity_m_s
from scenarios.world.tasks.insert_scene import HOLE_DEPTH_M, PEG_BELOW_TCP_M

#: the approach ends with the peg's bottom this far over the mouth, m: far enough that the insertion's start has
#: settled before the peg meets the chamfer (a chunk planned 200 ms ago starts 8 mm down its descent, and the hybrid
#: layer's reference catches up over ~0.2 s; from 15 mm the peg met the chamfer still at ~0.1 m/s, one episode in 60
#: over 30 N on seeds 6030-6089, none from 25 mm, where seating takes 0.25 s longer)
ABOVE_M = 0.025
#: the TCP within this of its spot over the mouth (horizontally) starts the insertion, m
OVER_XY_M = 0.003
#: the insertion's speed, m/s, and how far past the hole's bottom it aims (a light push on the seat), m
INSERT_SPEED_M_S = 0.04
PUSH_M = 0.0015
#: a two-frame speed above this is a jump, not a motion, m/s
MAX_LEAD_SPEED_M_S = 0.3


@dataclass(frozen=True)
class InsertExpertConfig:
    """Attributes: horizon (waypoints), dt_s (their spacing, s), approach_speed_m_s (average TCP speed of the move
    over the hole), min_approach_s (s), lead (``none`` or ``velocity``)."""

    horizon: int = 16
    dt_s: float = 0.1
    approach_speed_m_s: float = 0.3
    min_approach_s: float = 0.5
    lead: str = "velocity"

    def __post_init__(self) -> None:
        if self.lead not in LEADS:
            raise ValueError(f"InsertExpertConfig.lead must be one of {LEADS}, got {self.lead!r}")
        if self.horizon < 1 or not self.dt_s > 0:
            raise ValueError(f"InsertExpertConfig: horizon >= 1 and dt_s > 0, got {self.horizon}, {self.dt_s}")


class InsertExpert(ExpertBase):
    """``ChunkSource`` of the insert task (see the module)."""

    def __init__(self, config: InsertExpertConfig = InsertExpertConfig(), tokenizer: ActionTokenizer | None = None) -> None:
        super().__init__(config, tokenizer)

    def plan(self, obs: Observation) -> ActionChunk:
        cfg = self.config
        times = cfg.dt_s * np.arange(1, cfg.horizon + 1)
        mouth = np.asarray(obs.target_pos_m, dtype=float)
        course = mouth + times[:, None] * self._velocity(obs)  # where the mouth will be at each waypoint's time
        tcp = np.asarray(obs.ee_pos_m, dtype=float)
        over = course + np.array([0.0, 0.0, PEG_BELOW_TCP_M + ABOVE_M])  # the TCP's spot over the mouth
        entered = tcp[2] < mouth[2] + PEG_BELOW_TCP_M + ABOVE_M + 0.005
        if entered and np.hypot(*(tcp - mouth)[:2]) < OVER_XY_M + 0.002 * (tcp[2] < over[0, 2] - 0.002):
            pos = self._insert(tcp, course, times)
        else:
            pos = self._approach(tcp, over, times)
        a = np.zeros((len(times), 7))
        a[:, :3] = pos
        return self._finish(a, obs)

    def _velocity(self, obs: Observation) -> np.ndarray:
        """The mouth's horizontal velocity from two frames (``two_frame_velocity_m_s``)."""
        return two_frame_velocity_m_s(obs, self.config.lead, MAX_LEAD_SPEED_M_S, horizontal=True)

    def _approach(self, tcp: np.ndarray, over: np.ndarray, times: np.ndarray) -> np.ndarray:
        """A minimum-jerk move to the spot over the mouth, then along the mouth's course there."""
        cfg = self.config
        t_app = max(cfg.min_approach_s, float(np.linalg.norm(over[-1] - tcp)) / cfg.approach_speed_m_s)
        s = min_jerk(times / t_app)[:, None]
        return tcp + s * (over - tcp)

    def _insert(self, tcp: np.ndarray, course: np.ndarray, times: np.ndarray) -> np.ndarray:
        """Straight down over the mouth's course at ``INSERT_SPEED_M_S`` to ``PUSH_M`` past the seat; once the peg is
        in the hole, straight down where the TCP is (the hole guides it; a noisy measurement must not drag it)."""
        bottom_z = course[:, 2] - HOLE_DEPTH_M + PEG_BELOW_TCP_M - PUSH_M
        pos = course.copy()
        if tcp[2] < course[0, 2] + PEG_BELOW_TCP_M:  # the peg is in the hole: it guides the peg, straight down from here
            pos[:, :2] = tcp[:2]
        pos[:, 2] = np.maximum(tcp[2] - INSERT_SPEED_M_S * times, bottom_z)
        return pos


def make_insert_expert(bins: int = 2048, horizon: int = 16, dt_s: float = 0.1, lead: str = "velocity") -> InsertExpert:
    """The insert expert, its chunks quantized through the shared action tokenizer (bins 0: not quantized)."""
    tokenizer = expert_tokenizer(bins)
    return InsertExpert(InsertExpertConfig(horizon=horizon, dt_s=dt_s, lead=lead), tokenizer)
