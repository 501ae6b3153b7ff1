"""The scripted expert: the honest stand-in for a chunk policy.

It plans a minimum-jerk approach from the current TCP pose at the nominal grasp orientation with
the gripper open, and its chunk goes through the same action tokenizer as the learned policy's (so
quantization is real). What it aims at is ``ExpertConfig.lead``:

- ``"none"``: what one camera frame shows: where the target is at the observation time ``t0``, not
  where it is going (a single-frame policy);
- ``"velocity"``: it sees two frames (``t0 - frame_gap`` and ``t0``, ``Observation.target_prev_pos_m``),
  estimates the target's velocity from them, and aims each waypoint at where the target will be at that
  waypoint's time (waypoint ``i`` runs at ``t0 + (i + 1) dt``: the inference latency, during which the
  first waypoints are already past when the chunk arrives, is included by construction). A two-frame
  velocity above ``max_lead_speed_m_s`` is not a motion but a discontinuity (a jump between the frames):
  it then aims where the target is now, as a real two-frame estimator with a plausibility gate would.
  With ``workspace_low_m`` / ``workspace_high_m`` set (the box the targets move in: the region of the table the
  scene shows), the constant-velocity prediction is reflected at its walls, as the targets' motions are: a lead
  that extrapolates through a wall sends the arm out of the workspace. Every execution mode is given the same
  chunks, so this knowledge is shared by all of them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mmact_ctrl.chunk import ActionChunk, Observation
from policy.action_tokenizer import ActionTokenizer
from policy.vocab import VocabLayout
from scenarios.world.targets import reflect_into_box

GRIPPER_OPEN_M = 0.08
#: what the expert aims at (``ExpertConfig.lead``)
LEADS: tuple[str, ...] = ("none", "velocity")


@dataclass(frozen=True)
class ExpertConfig:
    """Attributes:
    horizon: waypoints per chunk (H).
    dt_s: waypoint spacing, s.
    approach_speed_m_s: average TCP speed of the approach, m/s.
    min_approach_s: shortest approach duration, s.

    lead: ``"none"`` (aim where the target is at t0) or ``"velocity"`` (aim where it will be; see the module).
    max_lead_speed_m_s: lead ``"velocity"``: a two-frame speed above this is taken for a jump, m/s.
    workspace_low_m, workspace_high_m: lead ``"velocity"``: the box the target stays in (its prediction is
        reflected at the walls), m; None: unbounded.
    """

    horizon: int = 16
    dt_s: float = 0.1
    approach_speed_m_s: float = 0.4
    min_approach_s: float = 0.5
    lead: str = "none"
    max_lead_speed_m_s: float = 0.8
    workspace_low_m: tuple[float, float, float] | None = None
    workspace_high_m: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        if self.lead not in LEADS:
            raise ValueError(f"ExpertConfig.lead must be one of {LEADS}, got {self.lead!r}")
        if not self.max_lead_speed_m_s > 0:
            raise ValueError(f"ExpertConfig.max_lead_speed_m_s must be > 0, got {self.max_lead_speed_m_s}")
        if (self.workspace_low_m is None) != (self.workspace_high_m is None):
            raise ValueError("ExpertConfig.workspace_low_m and workspace_high_m must be given together")
        if self.workspace_low_m is not None and not np.all(np.asarray(self.workspace_high_m) > np.asarray(self.workspace_low_m)):
            raise ValueError(f"ExpertConfig.workspace_high_m {self.workspace_high_m} must exceed workspace_low_m "
                             f"{self.workspace_low_m} on every axis")
        if self.horizon < 1:
            raise ValueError(f"ExpertConfig.horizon must be >= 1, got {self.horizon}")
        for name in ("dt_s", "approach_speed_m_s", "min_approach_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"ExpertConfig.{name} must be > 0, got {getattr(self, name)}")


def min_jerk(s: np.ndarray) -> np.ndarray:
    """Minimum-jerk time scaling on [0, 1]."""
    s = np.clip(s, 0.0, 1.0)
    return s**3 * (10.0 - 15.0 * s + 6.0 * s**2)


def lead_velocity_m_s(config: ExpertConfig, observation: Observation) -> np.ndarray:
    """The target velocity (3,) m/s the expert leads with: zero for ``lead="none"``, without an earlier frame, or
    when the two frames imply a speed above ``max_lead_speed_m_s`` (a jump)."""
    return two_frame_velocity_m_s(observation, config.lead, config.max_lead_speed_m_s)


def two_frame_velocity_m_s(observation: Observation, lead: str, max_speed_m_s: float,
                           horizontal: bool = False) -> np.ndarray:
    """The target's velocity (3,) m/s from the observation's two frames (``horizontal``: its z zeroed, for objects
    that move in the table's plane); zero for ``lead="none"``, without an earlier frame, or above ``max_speed_m_s``
    (a jump, not a motion). Every expert leads with it."""
    prev, gap = observation.target_prev_pos_m, float(observation.frame_gap_s)
    if lead == "none" or prev is None or not gap > 0:
        return np.zeros(3)
    vel = (np.asarray(observation.target_pos_m, dtype=np.float64) - np.asarray(prev, dtype=np.float64)) / gap
    if horizontal:
        vel[2] = 0.0
    if not np.all(np.isfinite(vel)) or float(np.linalg.norm(vel)) > max_speed_m_s:
        return np.zeros(3)
    return vel


def expert_tokenizer(bins: int) -> ActionTokenizer | None:
    """The shared action tokenizer every expert's chunks go through (``bins`` 0: not quantized)."""
    return ActionTokenizer(bins=bins, token_offset=VocabLayout(action_bins=bins).action_offset) if bins else None


def expert_actions(config: ExpertConfig, ee_pos_m: np.ndarray, target_pos_m: np.ndarray,
                   target_vel_m_s: np.ndarray | None = None) -> np.ndarray:
    """Float chunk ``(H, 7)``: min-jerk from ``ee_pos_m`` toward ``target_pos_m``, nominal orientation, open
    gripper. With ``target_vel_m_s``, waypoint ``i`` aims at the target's constant-velocity position at its own
    time ``(i + 1) dt`` after the observation (the approach duration is set by the distance to the target at the
    end of the approach)."""
    start = np.asarray(ee_pos_m, dtype=np.float64)
    goal = np.asarray(target_pos_m, dtype=np.float64)
    times = config.dt_s * np.arange(1, config.horizon + 1)
    vel = np.zeros(3) if target_vel_m_s is None else np.asarray(target_vel_m_s, dtype=np.float64)
    duration = max(config.min_approach_s, float(np.linalg.norm(goal - start)) / config.approach_speed_m_s)
    if np.any(vel):  # where it will be once reached (two fixed-point steps of duration <-> distance)
        for _ in range(2):
            duration = max(config.min_approach_s,
                           float(np.linalg.norm(goal + vel * duration - start)) / config.approach_speed_m_s)
    goals = goal + times[:, None] * vel
    if np.any(vel) and config.workspace_low_m is not None:  # the target reflects at the walls: so does the lead
        goals = reflect_into_box(goals, np.asarray(config.workspace_low_m, dtype=float), np.asarray(config.workspace_high_m, dtype=float))
    s = min_jerk(times / duration)[:, None]
    actions = np.zeros((config.horizon, 7))
    actions[:, :3] = start + s * (goals - start)
    actions[:, 6] = GRIPPER_OPEN_M
    return actions


class ExpertBase:
    """What every scripted expert (reach's, and each task's in ``scenarios.world.tasks``) shares as a
    ``ChunkSource``: a frozen config with ``dt_s``, an optional tokenizer its float chunks are quantized through, and
    the chunk built from them (:meth:`_finish`)."""

    needs_image = False

    def __init__(self, config, tokenizer: ActionTokenizer | None = None) -> None:
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

    def _finish(self, actions: np.ndarray, observation: Observation) -> ActionChunk:
        """The chunk of the float ``actions`` (H, 7), quantized through the tokenizer when there is one."""
        if self.tokenizer is None:
            return ActionChunk(waypoints=actions, dt_s=self.config.dt_s, t0_s=observation.t0_s)
        waypoints, tokens, n_clipped = self.tokenizer.roundtrip(actions)
        return ActionChunk(
            waypoints=waypoints, dt_s=self.config.dt_s, t0_s=observation.t0_s, tokens=tokens, n_clipped=n_clipped
        )


class ScriptedExpert(ExpertBase):
    """``ChunkSource`` that aims at the target it sees in one frame, or (``lead="velocity"``) where two frames say
    it will be."""

    def __init__(self, config: ExpertConfig = ExpertConfig(), tokenizer: ActionTokenizer | None = None) -> None:
        super().__init__(config, tokenizer)

    def plan(self, observation: Observation) -> ActionChunk:
        actions = expert_actions(self.config, observation.ee_pos_m, observation.target_pos_m,
                                 lead_velocity_m_s(self.config, observation))
        return self._finish(actions, observation)

    def plan_inpaint(self, observation: Observation, known: np.ndarray) -> ActionChunk:
        """Real-time chunking with the expert: the first ``len(known)`` waypoints are frozen (they run
        while this chunk is computed); the rest is a min-jerk approach from the last frozen waypoint."""
        known = np.asarray(known, dtype=np.float64).reshape(-1, 7)
        n = min(len(known), self.config.horizon)
        if n == 0:
            return self.plan(observation)
        vel = lead_velocity_m_s(self.config, observation)
        # the rest starts at the last frozen waypoint's time: aim at the target then (+ n dt) and on
        rest = expert_actions(self.config, known[n - 1, :3], observation.target_pos_m + n * self.config.dt_s * vel,
                              vel)[: self.config.horizon - n]
        return self._finish(np.vstack([known[:n], rest]), observation)
