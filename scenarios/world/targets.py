"""Target motions: where the object to reach is at time t. Pure numpy, deterministic given a seed.

Kinds (``TargetSpec.kind``):

- ``static``: a random point in the workspace box.
- ``linear``: random start, random direction, constant ``speed_m_s``, reflecting off the box walls.
- ``circle``: horizontal circle of radius ``circle_radius_m`` (centre chosen so it stays inside),
  tangential speed ``speed_m_s``, random phase and direction.
- ``random_walk``: constant speed ``speed_m_s`` whose direction turns smoothly (the turn rate is an
  Ornstein-Uhlenbeck process, so the velocity is continuous and differentiable between wall
  bounces), reflecting at the walls; precomputed on a 10 ms grid up to ``horizon_s`` and linearly
  interpolated (so the speed is exact on every grid segment).
- ``jump``: a static point that teleports by ``jump_dist_m`` in a random direction (kept inside the
  box; horizontal in a flat workspace, the policy's plane), first at a random time in [1.0, 2.0] s, then every ``jump_period_s`` up to ``horizon_s``.
- ``reversal``: constant speed ``speed_m_s`` along a random direction (reflecting at the walls) whose
  velocity flips (v -> -v) at random times: the first uniform in [1.0, 2.0] s, then gaps uniform in
  [``reversal_min_gap_s``, ``reversal_max_gap_s``].
- ``swerve``: constant speed, straight segments (reflecting at the walls); at random times (first in
  [1.0, 2.0] s, gaps uniform in [``swerve_min_gap_s``, ``swerve_max_gap_s``]) the direction turns by
  an angle uniform in [45, 135] deg: about the vertical with a random sign in a flat workspace, about
  a random axis perpendicular to the velocity in 3-D.
- ``accelerating``: a random direction (reflecting at the walls), speed
  ``speed_m_s * (1 - cos(2 pi t / accel_period_s + phase)) / 2`` with a random phase: the target
  comes to rest and sets off again once per ``accel_period_s``.

``reversal``, ``swerve`` and ``accelerating`` use the ``random_walk`` grid (10 ms, up to
``horizon_s``; a flip or turn inside a grid step is applied at its exact time, so only that one
10 ms segment is a chord); linear motions (everything but ``circle`` and ``jump``) are horizontal in a
flat workspace (z extent < ``PLANAR_EXTENT_M``).

Every motion has ``change_times_s``, the times its course changes abruptly, for reaction metrics
(``mmact_ctrl.reaction``): the teleports of ``jump``, the flips of ``reversal``, the turns of
``swerve``, the moments ``accelerating`` sets off from rest; ``()`` for ``static``, ``linear``,
``circle`` and ``random_walk`` (their wall bounces are not changes: the walls are part of a course a
tracker can foresee, and the random walk turns smoothly). ``jump_times_s`` stays jumps only.

Start points are drawn at least ``min_start_dist_m`` away from ``avoid_pos_m`` (by default the home
TCP position of the Panda scene), so an episode is not solved at t = 0.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from scenarios.world.motions import (PLANAR_EXTENT_M, CircleMotion, GridMotion, JumpMotion,  # noqa: F401
                                     LinearMotion, StaticMotion, _accelerating, _circle, _course_direction, _fold,
                                     _jump, _random_walk, _reversal, _start_point, _swerve, reflect_into_box)

__all__ = ["HOME_TCP_POS_M", "KINDS", "PLANAR_EXTENT_M", "CircleMotion", "GridMotion", "JumpMotion", "LinearMotion",
           "StaticMotion", "TargetMotion", "TargetSpec", "make_motion", "plane_workspace", "reflect_into_box",
           "target_spec"]

KINDS: tuple[str, ...] = ("static", "linear", "circle", "random_walk", "jump", "reversal", "accelerating", "swerve")

#: world position (m) of the Panda's ``tcp`` site at ``HOME_Q_RAD`` with the gripper open, as
#: computed by ``scenarios.world.panda_scene.home_tcp_pos_m()`` (a test holds the two equal to 1 mm).
HOME_TCP_POS_M: tuple[float, float, float] = (0.30689, 0.0, 0.48688)



@dataclass(frozen=True)
class TargetSpec:
    """How the target moves.

    Attributes:
        kind: one of ``KINDS``.
        speed_m_s: target speed (linear, circle, random_walk, reversal, swerve; the peak speed of
            accelerating), m/s.
        workspace_low_m, workspace_high_m: corners of the box the target stays in, world frame, m.
        circle_radius_m: radius of the ``circle`` motion, m.
        jump_dist_m: distance of each teleport of the ``jump`` motion, m.
        jump_period_s: time between teleports after the first, s.
        horizon_s: length of precomputed motions (random_walk, reversal, swerve, accelerating, jump
            times), s; after it the grid motions hold their last position and no more jumps happen.
        random_walk_turn_std_rad_s: stationary std of the random walk's turn rate (per axis), rad/s.
        random_walk_turn_tau_s: correlation time of the random walk's turn rate, s.
        reversal_min_gap_s, reversal_max_gap_s: range of the uniform time between two flips, s.
        swerve_min_gap_s, swerve_max_gap_s: range of the uniform time between two turns, s.
        accel_period_s: period of the ``accelerating`` speed profile (rest to rest), s.
        min_start_dist_m: minimum distance of the start point from ``avoid_pos_m``, m.
        avoid_pos_m: point the start must stay away from (default: the home TCP), m.
    """

    kind: str = "static"
    speed_m_s: float = 0.2
    workspace_low_m: tuple[float, float, float] = (0.35, -0.3, 0.15)
    workspace_high_m: tuple[float, float, float] = (0.65, 0.3, 0.45)
    circle_radius_m: float = 0.08
    jump_dist_m: float = 0.15
    jump_period_s: float = 2.0
    horizon_s: float = 60.0
    random_walk_turn_std_rad_s: float = 1.5
    random_walk_turn_tau_s: float = 0.5
    reversal_min_gap_s: float = 0.8
    reversal_max_gap_s: float = 1.6
    swerve_min_gap_s: float = 0.8
    swerve_max_gap_s: float = 1.6
    accel_period_s: float = 2.0
    min_start_dist_m: float = 0.1
    avoid_pos_m: tuple[float, float, float] = HOME_TCP_POS_M

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"TargetSpec.kind: unknown kind {self.kind!r}; choose from {KINDS}")
        for name in ("speed_m_s", "min_start_dist_m"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"TargetSpec.{name} must be finite and >= 0, got {value!r}")
        for name in ("circle_radius_m", "jump_dist_m", "jump_period_s", "horizon_s", "random_walk_turn_tau_s",
                     "reversal_min_gap_s", "reversal_max_gap_s", "swerve_min_gap_s", "swerve_max_gap_s",
                     "accel_period_s"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"TargetSpec.{name} must be finite and > 0, got {value!r}")
        for family in ("reversal", "swerve"):
            lo_gap, hi_gap = getattr(self, f"{family}_min_gap_s"), getattr(self, f"{family}_max_gap_s")
            if lo_gap > hi_gap:
                raise ValueError(f"TargetSpec.{family}_min_gap_s={lo_gap!r} exceeds {family}_max_gap_s={hi_gap!r}")
        if not (np.isfinite(self.random_walk_turn_std_rad_s) and self.random_walk_turn_std_rad_s >= 0):
            raise ValueError(f"TargetSpec.random_walk_turn_std_rad_s must be >= 0, got {self.random_walk_turn_std_rad_s!r}")
        for name in ("workspace_low_m", "workspace_high_m", "avoid_pos_m"):
            value = np.asarray(getattr(self, name), dtype=float)
            if value.shape != (3,) or not np.all(np.isfinite(value)):
                raise ValueError(f"TargetSpec.{name} must be 3 finite numbers, got {getattr(self, name)!r}")
        low, high = self.low, self.high
        if np.any(high <= low):
            raise ValueError(f"TargetSpec: workspace_high_m {self.workspace_high_m!r} must exceed workspace_low_m "
                             f"{self.workspace_low_m!r} on every axis")
        if self.kind == "circle" and np.any(2 * self.circle_radius_m > (high - low)[:2]):
            raise ValueError(f"TargetSpec.circle_radius_m={self.circle_radius_m!r} does not fit in the workspace "
                             f"(x, y extents {(high - low)[:2].tolist()} m)")
        # a flat workspace (the objects on one plane) jumps within the plane: only its x, y extents count
        extents = (high - low)[:2] if high[2] - low[2] < PLANAR_EXTENT_M else high - low
        if self.kind == "jump" and self.jump_dist_m > float(np.min(extents)):
            raise ValueError(f"TargetSpec.jump_dist_m={self.jump_dist_m!r} exceeds the smallest workspace extent "
                             f"{float(np.min(extents))} m")

    @property
    def low(self) -> np.ndarray:
        """Workspace low corner (3,), m."""
        return np.asarray(self.workspace_low_m, dtype=float)

    @property
    def high(self) -> np.ndarray:
        """Workspace high corner (3,), m."""
        return np.asarray(self.workspace_high_m, dtype=float)


class TargetMotion(Protocol):
    """A target trajectory drawn from a ``TargetSpec`` and a seed."""

    #: times at which the target teleports, s (empty unless ``kind == "jump"``).
    jump_times_s: tuple[float, ...]
    #: times at which the course changes abruptly, s: jumps, flips, turns, set-offs from rest (see the
    #: module docstring); wall bounces are not changes.
    change_times_s: tuple[float, ...]

    def pos_m(self, t_s: float) -> np.ndarray:
        """Target position (3,) at time ``t_s`` (s >= 0), world frame, m."""
        ...


def plane_workspace(spec_low_m: tuple[float, float, float], spec_high_m: tuple[float, float, float], z_m: float,
                    thickness_m: float = 0.02) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """Workspace corners with the objects at height ``z_m`` (within ``thickness_m``), x/y unchanged."""
    return (spec_low_m[0], spec_low_m[1], z_m), (spec_high_m[0], spec_high_m[1], z_m + thickness_m)


def target_spec(kind: str, speed_m_s: float, plane_z_m: float = 0.0) -> "TargetSpec":
    """A target motion over the full workspace, or (``plane_z_m > 0``) over a plane at that height."""
    spec = TargetSpec(kind=kind, speed_m_s=speed_m_s)
    if plane_z_m > 0:
        low, high = plane_workspace(spec.workspace_low_m, spec.workspace_high_m, plane_z_m)
        spec = TargetSpec(kind=kind, speed_m_s=speed_m_s, workspace_low_m=low, workspace_high_m=high)
    return spec


def make_motion(spec: TargetSpec, seed: int) -> TargetMotion:
    """Draw the target motion of ``spec`` from ``seed`` (same seed, same motion)."""
    if not isinstance(spec, TargetSpec):
        raise TypeError(f"make_motion needs a TargetSpec, got {type(spec).__name__}")
    rng = np.random.default_rng(seed)
    low, high = spec.low, spec.high
    if spec.kind == "static":
        return StaticMotion(point_m=_start_point(spec, rng, low, high))
    if spec.kind == "linear":
        start = _start_point(spec, rng, low, high)
        direction = _course_direction(rng, low, high)
        return LinearMotion(start_m=start, velocity_m_s=spec.speed_m_s * direction, low_m=low, high_m=high)
    if spec.kind == "circle":
        return _circle(spec, rng, low, high)
    if spec.kind == "random_walk":
        return _random_walk(spec, rng, low, high)
    if spec.kind == "reversal":
        return _reversal(spec, rng, low, high)
    if spec.kind == "swerve":
        return _swerve(spec, rng, low, high)
    if spec.kind == "accelerating":
        return _accelerating(spec, rng, low, high)
    return _jump(spec, rng, low, high)
