"""The scripted expert: the honest stand-in for a single-frame chunk policy.

It sees what one camera frame shows: where the target is at the observation time ``t0``,
not where it is going. It plans a minimum-jerk approach from the current TCP pose to that
point at the nominal grasp orientation with the gripper open, and its chunk goes through
the same action tokenizer as the learned policy's (so quantization is real).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mmact_ctrl.chunk import ActionChunk, Observation
from policy.action_tokenizer import ActionTokenizer

GRIPPER_OPEN_M = 0.08


@dataclass(frozen=True)
class ExpertConfig:
    """Attributes:
    horizon: waypoints per chunk (H).
    dt_s: waypoint spacing, s.
    approach_speed_m_s: average TCP speed of the approach, m/s.
    min_approach_s: shortest approach duration, s.
    """

    horizon: int = 16
    dt_s: float = 0.1
    approach_speed_m_s: float = 0.4
    min_approach_s: float = 0.5

    def __post_init__(self) -> None:
        if self.horizon < 1:
            raise ValueError(f"ExpertConfig.horizon must be >= 1, got {self.horizon}")
        for name in ("dt_s", "approach_speed_m_s", "min_approach_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"ExpertConfig.{name} must be > 0, got {getattr(self, name)}")


def min_jerk(s: np.ndarray) -> np.ndarray:
    """Minimum-jerk time scaling on [0, 1]."""
    s = np.clip(s, 0.0, 1.0)
    return s**3 * (10.0 - 15.0 * s + 6.0 * s**2)


def expert_actions(config: ExpertConfig, ee_pos_m: np.ndarray, target_pos_m: np.ndarray) -> np.ndarray:
    """Float chunk ``(H, 7)``: min-jerk from ``ee_pos_m`` to ``target_pos_m``, nominal orientation, open gripper."""
    start = np.asarray(ee_pos_m, dtype=np.float64)
    goal = np.asarray(target_pos_m, dtype=np.float64)
    duration = max(config.min_approach_s, float(np.linalg.norm(goal - start)) / config.approach_speed_m_s)
    times = config.dt_s * np.arange(1, config.horizon + 1)
    s = min_jerk(times / duration)[:, None]
    actions = np.zeros((config.horizon, 7))
    actions[:, :3] = start + s * (goal - start)
    actions[:, 6] = GRIPPER_OPEN_M
    return actions


class ScriptedExpert:
    """``ChunkSource`` that aims at the target it sees in one frame."""

    needs_image = False

    def __init__(self, config: ExpertConfig = ExpertConfig(), tokenizer: ActionTokenizer | None = None) -> None:
        self.config = config
        self.tokenizer = tokenizer

    @property
    def chunk_dt_s(self) -> float:
        return self.config.dt_s

    @property
    def action_token_range(self) -> tuple[int, int] | None:
        """Half-open range of the action tokens its chunks carry (None: not quantized)."""
        tok = self.tokenizer
        return None if tok is None else (int(tok.token_offset), int(tok.token_offset) + int(tok.bins))

    def plan(self, observation: Observation) -> ActionChunk:
        actions = expert_actions(self.config, observation.ee_pos_m, observation.target_pos_m)
        return self._finish(actions, observation)

    def plan_inpaint(self, observation: Observation, known: np.ndarray) -> ActionChunk:
        """Real-time chunking with the expert: the first ``len(known)`` waypoints are frozen (they run
        while this chunk is computed); the rest is a min-jerk approach from the last frozen waypoint."""
        known = np.asarray(known, dtype=np.float64).reshape(-1, 7)
        n = min(len(known), self.config.horizon)
        if n == 0:
            return self.plan(observation)
        rest = expert_actions(self.config, known[n - 1, :3], observation.target_pos_m)[: self.config.horizon - n]
        return self._finish(np.vstack([known[:n], rest]), observation)

    def _finish(self, actions: np.ndarray, observation: Observation) -> ActionChunk:
        if self.tokenizer is None:
            return ActionChunk(waypoints=actions, dt_s=self.config.dt_s, t0_s=observation.t0_s)
        waypoints, tokens, n_clipped = self.tokenizer.roundtrip(actions)
        return ActionChunk(
            waypoints=waypoints, dt_s=self.config.dt_s, t0_s=observation.t0_s, tokens=tokens, n_clipped=n_clipped
        )
