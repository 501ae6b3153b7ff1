"""Chunk retargeting: correct the active chunk's positions for what the policy could not see.

Three rules, all evaluated at the time ``t_s`` a reference is needed (so they keep working
past the chunk's last waypoint, where the last waypoint is held):

- ``displacement``: shift by how far the estimated target has moved since the chunk's
  observation time: ``offset(t) = p_hat(t) - p_hat(t0)``.
- ``snap``: pull the chunk onto the filtered target: the displacement above plus the chunk's
  aim error at observation time, blended from 0 at the chunk's activation to 1 at its last
  waypoint that will run (the caller passes ``t_last_s``: the chunk's last waypoint, or the time
  the next chunk is due if that is earlier): ``offset(t) = p_hat(t) - p_hat(t0) + alpha(t) * (p_hat(t0) - aim)``, ``aim`` being
  the chunk's last waypoint. At and after the last waypoint the reference is exactly the
  filtered target, so this also removes the chunk source's aim error and the dequantization
  error. (A pure pull ``alpha(t) * (p_hat(t) - aim)`` lags a moving target: with 1.6 s chunks
  replaced every second, alpha never passes ~0.6 and the TCP trailed by half a second.)
- ``warp`` (the default): ``snap`` with the blend weight taken from the chunk's own progress towards its aim,
  ``w(t) = 1 - |aim - c(t)| / |aim - c(0)|`` (clipped to [0, 1]; ``c`` the chunk's position, ``c(0)`` its first
  waypoint) instead of the time since activation: the chunk's path is bent so that it ends on the filtered target,
  each point moved in proportion to how far along the path it is. A chunk that travels less than
  ``min_travel_m`` (it rests where it starts) has no progress to measure and is blended in time as ``snap`` does.
  Why: ``snap``'s time blend reaches 1 when the next chunk is due, whatever is left of the chunk's path. When a
  chunk aims beside the ball and keeps heading there while the arm is already on the ball (the 3-D policy at
  5 Hz), the full aim error is applied to a point of the path that is still near its start, and the reference
  lands beside the ball on the other side: the arm is pushed off at every replan. With ``warp`` the reference
  stays on the ball (``tests/test_warp_retarget.py``). A rule that lands on the target within each replan period
  instead (tried) turns a far approach at 5 Hz into a 1.7 m/s saw-tooth of the reference and drove the fingers
  into the table.

All are gated by a trust radius: when the target estimate at the chunk's observation time
is farther than ``trust_radius_m`` from the chunk's aim, the target is not the chunk's
target, and the chunk runs unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

RULES: tuple[str, ...] = ("none", "displacement", "snap", "warp")
#: the axes a chunk is retargeted on: ``xyz`` (its aim is the target: reach), or ``xy`` only (its waypoints keep their
#: heights over an object that moves in the table's plane: a pick's approach above the cube, its descent, its lift)
PULL_AXES: tuple[str, ...] = ("xyz", "xy")


@dataclass(frozen=True)
class RetargetConfig:
    """Attributes:
    rule: one of ``RULES``.
    trust_radius_m: gate on the distance between the chunk's aim and the target at observation time, m.
    min_travel_m: ``warp``: a chunk whose aim is nearer than this to its first waypoint is blended in time, m.
    pull_axes: one of ``PULL_AXES``.
    """

    rule: str = "warp"
    trust_radius_m: float = 0.3
    min_travel_m: float = 0.02
    pull_axes: str = "xyz"

    def __post_init__(self) -> None:
        if self.rule not in RULES:
            raise ValueError(f"retarget rule must be one of {RULES}, got {self.rule!r}")
        if not self.trust_radius_m > 0:
            raise ValueError(f"trust_radius_m must be > 0, got {self.trust_radius_m}")
        if self.pull_axes not in PULL_AXES:
            raise ValueError(f"retarget pull_axes must be one of {PULL_AXES}, got {self.pull_axes!r}")
        if not self.min_travel_m > 0:
            raise ValueError(f"min_travel_m must be > 0, got {self.min_travel_m}")


def trusted(config: RetargetConfig, aim_pos_m: np.ndarray, target_at_obs_m: np.ndarray | None) -> bool:
    """Whether the tracked target is this chunk's target (inside the trust radius of its aim)."""
    if config.rule == "none" or target_at_obs_m is None:
        return False
    return bool(np.linalg.norm(aim_pos_m - target_at_obs_m) <= config.trust_radius_m)


def progress(config: RetargetConfig, aim_pos_m: np.ndarray, start_pos_m: np.ndarray, pos_m: np.ndarray,
             vel_m_s: np.ndarray) -> tuple[float, float] | None:
    """``warp``'s weight ``w`` and its rate ``dw/dt`` (1/s) at a point ``pos_m`` of the chunk moving at ``vel_m_s``:
    ``1 - |aim - pos| / |aim - start|`` clipped to [0, 1]; None when the chunk travels less than
    ``config.min_travel_m`` (the caller blends in time)."""
    travel = float(np.linalg.norm(aim_pos_m - start_pos_m))
    if travel < config.min_travel_m:
        return None
    d = aim_pos_m - pos_m
    left = float(np.linalg.norm(d))
    w = 1.0 - left / travel
    if w <= 0.0:
        return 0.0, 0.0
    if w >= 1.0 or left < 1e-12:
        return 1.0, 0.0
    return w, float(d @ vel_m_s) / (left * travel)


def progresses(config: RetargetConfig, aim_pos_m: np.ndarray, start_pos_m: np.ndarray,
               pos_m: np.ndarray) -> np.ndarray | None:
    """:func:`progress`'s weights (N,) at many points ``pos_m`` (N, 3) at once (None: blend in time)."""
    travel = float(np.linalg.norm(aim_pos_m - start_pos_m))
    if travel < config.min_travel_m:
        return None
    return np.clip(1.0 - np.linalg.norm(aim_pos_m - pos_m, axis=1) / travel, 0.0, 1.0)


def retarget_offset(
    config: RetargetConfig,
    t_s: float,
    aim_pos_m: np.ndarray,
    target_at_obs_m: np.ndarray,
    target_pos_m: np.ndarray,
    target_vel_m_s: np.ndarray,
    t_active_s: float,
    t_last_s: float,
    weight: tuple[float, float] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """(offset m, offset velocity m/s) to add to the chunk's position reference at ``t_s``.

    Args:
        aim_pos_m: the chunk's last waypoint position.
        target_at_obs_m: filtered target estimate at the chunk's observation time.
        target_pos_m, target_vel_m_s: filtered target estimate (predicted) at ``t_s``.
        t_active_s: when the chunk became active; t_last_s: time of its last waypoint that will run.
        weight: ``warp``: ``(w, dw/dt)`` of :func:`progress` (None: the time blend of ``snap``).
    """
    if config.rule == "displacement":
        return target_pos_m - target_at_obs_m, target_vel_m_s
    if config.rule in ("snap", "warp"):
        if config.rule == "warp" and weight is not None:
            alpha, dalpha = weight
        else:
            span = max(t_last_s - t_active_s, 1e-6)
            alpha = min(max((t_s - t_active_s) / span, 0.0), 1.0)
            dalpha = 1.0 / span if 0.0 < alpha < 1.0 else 0.0
        aim_error = target_at_obs_m - aim_pos_m
        return target_pos_m - target_at_obs_m + alpha * aim_error, target_vel_m_s + dalpha * aim_error
    return np.zeros(3), np.zeros(3)


def retarget_offsets(
    config: RetargetConfig,
    times_s: np.ndarray,
    aim_pos_m: np.ndarray,
    target_at_obs_m: np.ndarray,
    target_pos_m: np.ndarray,
    t_active_s: float,
    t_last_s: float,
    weights: np.ndarray | None = None,
) -> np.ndarray:
    """Position offsets (N, 3) of :func:`retarget_offset` at many times at once (the MPC's preview).

    ``target_pos_m`` (N, 3) is the predicted target at ``times_s`` (N,); ``weights`` (N,) ``warp``'s
    :func:`progresses` (None: the time blend)."""
    times_s = np.asarray(times_s, dtype=float)
    if config.rule == "displacement":
        return target_pos_m - target_at_obs_m
    if config.rule in ("snap", "warp"):
        if config.rule == "warp" and weights is not None:
            alpha = weights
        else:
            span = max(t_last_s - t_active_s, 1e-6)
            alpha = np.clip((times_s - t_active_s) / span, 0.0, 1.0)
        return target_pos_m - target_at_obs_m + alpha[:, None] * (target_at_obs_m - aim_pos_m)
    return np.zeros((len(times_s), 3))
