"""The target motions themselves (``scenarios.world.targets`` documents the kinds and draws them from a spec and a
seed): their classes, and the builders of the motions precomputed on a grid. Pure numpy, deterministic."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # pragma: no cover - the spec's class lives in targets, which imports this module
    from scenarios.world.targets import TargetSpec

_GRID_DT_S = 0.01  # random-walk (and reversal, swerve, accelerating) precomputation grid, s
_FIRST_CHANGE_S = (1.0, 2.0)  # the first jump, flip or turn happens uniformly in this interval, s
_SWERVE_ANGLE_DEG = (45.0, 135.0)  # swerve turn angles, deg
_MAX_TRIES = 10_000
#: a workspace thinner than this in z is treated as a plane: linear motions stay horizontal.
PLANAR_EXTENT_M = 0.05


def _random_unit(rng: np.random.Generator) -> np.ndarray:
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def reflect_into_box(x: np.ndarray, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """Reflect unbounded coordinates into [low, high] (triangle wave), elementwise: where a point moving in a straight
    line is once it bounces off the walls (points inside are unchanged)."""
    width = high - low
    u = np.mod(x - low, 2.0 * width)
    return low + np.where(u > width, 2.0 * width - u, u)


_fold = reflect_into_box  # the name the motions (and their tests) use


def _course_direction(rng: np.random.Generator, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """Random unit direction (3,); horizontal in a flat workspace (objects at one height)."""
    direction = _random_unit(rng)
    if high[2] - low[2] < PLANAR_EXTENT_M:
        direction[2] = 0.0
        direction /= max(np.linalg.norm(direction), 1e-12)
    return direction


def _check_t(t_s: float) -> float:
    t = float(t_s)
    if not math.isfinite(t) or t < 0:
        raise ValueError(f"target time t_s must be finite and >= 0, got {t_s!r}")
    return t


def _start_point(spec: TargetSpec, rng: np.random.Generator, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """Uniform point in [low, high] at least ``spec.min_start_dist_m`` from ``spec.avoid_pos_m``."""
    avoid = np.asarray(spec.avoid_pos_m, dtype=float)
    for _ in range(_MAX_TRIES):
        p = rng.uniform(low, high)
        if np.linalg.norm(p - avoid) >= spec.min_start_dist_m:
            return p
    raise ValueError(f"TargetSpec: no start point in the workspace is {spec.min_start_dist_m} m away from "
                     f"avoid_pos_m={spec.avoid_pos_m!r}")


# --------------------------------------------------------------------------------------------
# motions


@dataclass(frozen=True, eq=False)
class StaticMotion:
    """The target stays at ``point_m``."""

    point_m: np.ndarray
    jump_times_s: tuple[float, ...] = ()
    change_times_s: tuple[float, ...] = ()

    def pos_m(self, t_s: float) -> np.ndarray:
        _check_t(t_s)
        return self.point_m.copy()


@dataclass(frozen=True, eq=False)
class LinearMotion:
    """Constant velocity ``velocity_m_s`` from ``start_m``, reflected off the box walls."""

    start_m: np.ndarray
    velocity_m_s: np.ndarray
    low_m: np.ndarray
    high_m: np.ndarray
    jump_times_s: tuple[float, ...] = ()
    change_times_s: tuple[float, ...] = ()

    def pos_m(self, t_s: float) -> np.ndarray:
        # _fold(start + v t, low, high) on Python floats: the world moves the object every 1 ms step,
        # and three scalar folds cost a third of the numpy version's seven array calls
        t = _check_t(t_s)
        out = []
        for s, v, lo, hi in self._axes:
            width = hi - lo
            u = (s + v * t - lo) % (2.0 * width)
            out.append(lo + (2.0 * width - u if u > width else u))
        return np.array(out)

    @cached_property
    def _axes(self) -> tuple[tuple[float, float, float, float], ...]:
        return tuple(zip(*(np.asarray(a, dtype=float).tolist() for a in (self.start_m, self.velocity_m_s, self.low_m, self.high_m))))


@dataclass(frozen=True, eq=False)
class CircleMotion:
    """Horizontal circle: centre, radius (m), angular rate (rad/s, signed), initial phase (rad)."""

    centre_m: np.ndarray
    radius_m: float
    rate_rad_s: float
    phase_rad: float
    jump_times_s: tuple[float, ...] = ()
    change_times_s: tuple[float, ...] = ()

    def pos_m(self, t_s: float) -> np.ndarray:
        t = _check_t(t_s)
        a = self.phase_rad + self.rate_rad_s * t
        return self.centre_m + np.array([self.radius_m * np.cos(a), self.radius_m * np.sin(a), 0.0])


@dataclass(frozen=True, eq=False)
class GridMotion:
    """Positions precomputed at ``grid_dt_s`` spacing, linearly interpolated, held after the end."""

    points_m: np.ndarray  # (N, 3)
    grid_dt_s: float
    jump_times_s: tuple[float, ...] = ()
    change_times_s: tuple[float, ...] = ()

    def pos_m(self, t_s: float) -> np.ndarray:
        t = _check_t(t_s)
        k = t / self.grid_dt_s
        i = int(np.floor(k))
        if i >= len(self.points_m) - 1:
            return self.points_m[-1].copy()
        w = k - i
        return (1.0 - w) * self.points_m[i] + w * self.points_m[i + 1]


@dataclass(frozen=True, eq=False)
class JumpMotion:
    """Piecewise-constant position: ``points_m[k]`` from ``jump_times_s[k-1]`` on."""

    points_m: np.ndarray  # (n_jumps + 1, 3)
    jump_times_s: tuple[float, ...]

    @property
    def change_times_s(self) -> tuple[float, ...]:
        """The jumps are the changes."""
        return self.jump_times_s

    def pos_m(self, t_s: float) -> np.ndarray:
        t = _check_t(t_s)
        k = int(np.searchsorted(np.asarray(self.jump_times_s), t, side="right"))
        return self.points_m[k].copy()


def _random_walk(spec: TargetSpec, rng: np.random.Generator, low: np.ndarray, high: np.ndarray) -> GridMotion:
    dt = _GRID_DT_S
    n = int(np.ceil(spec.horizon_s / dt)) + 1
    p = _start_point(spec, rng, low, high)
    direction = _random_unit(rng)
    omega = rng.normal(size=3) * spec.random_walk_turn_std_rad_s  # turn rate, rad/s
    decay = np.exp(-dt / spec.random_walk_turn_tau_s)
    kick = spec.random_walk_turn_std_rad_s * np.sqrt(1.0 - decay**2)
    noise = (kick * rng.normal(size=(n, 3))).tolist()
    # plain-float loop: ~15x faster than per-step numpy calls on 3-vectors
    px, py, pz = (float(v) for v in p)
    dx, dy, dz = (float(v) for v in direction)
    wx, wy, wz = (float(v) for v in omega)
    lo, hi = low.tolist(), high.tolist()
    step = spec.speed_m_s * dt
    out = [[px, py, pz]]
    for k in range(1, n):
        nx, ny, nz = noise[k]
        wx, wy, wz = decay * wx + nx, decay * wy + ny, decay * wz + nz
        # d <- normalize(d + (omega x d) dt)
        dx, dy, dz = dx + (wy * dz - wz * dy) * dt, dy + (wz * dx - wx * dz) * dt, dz + (wx * dy - wy * dx) * dt
        norm = (dx * dx + dy * dy + dz * dz) ** 0.5
        dx, dy, dz = dx / norm, dy / norm, dz / norm
        pos, vel = [px + step * dx, py + step * dy, pz + step * dz], [dx, dy, dz]
        for a in range(3):  # reflect at the walls: position and that direction component
            if pos[a] < lo[a]:
                pos[a], vel[a] = 2 * lo[a] - pos[a], -vel[a]
            elif pos[a] > hi[a]:
                pos[a], vel[a] = 2 * hi[a] - pos[a], -vel[a]
        (px, py, pz), (dx, dy, dz) = pos, vel
        out.append(pos)
    points = np.asarray(out)
    return GridMotion(points_m=points, grid_dt_s=dt)


def _jump(spec: TargetSpec, rng: np.random.Generator, low: np.ndarray, high: np.ndarray) -> JumpMotion:
    first = rng.uniform(1.0, 2.0)
    times = tuple(float(t) for t in np.arange(first, spec.horizon_s, spec.jump_period_s))
    points = [_start_point(spec, rng, low, high)]
    centre = 0.5 * (low + high)
    flat = high[2] - low[2] < PLANAR_EXTENT_M  # objects on one plane: jump within it
    for _ in times:
        p = points[-1]
        for _ in range(_MAX_TRIES):
            u = _random_unit(rng)
            if flat:
                u[2] = 0.0
                u /= max(np.linalg.norm(u), 1e-12)
            q = p + spec.jump_dist_m * u
            if np.all(q >= low) and np.all(q <= high):
                break
        else:  # pragma: no cover - practically unreachable: the box is wider than jump_dist_m
            d = centre - p
            d[2] = 0.0 if flat else d[2]
            q = p + spec.jump_dist_m * d / np.linalg.norm(d)
        points.append(q)
    return JumpMotion(points_m=np.asarray(points), jump_times_s=times)


# ---- reversal, swerve, accelerating: straight courses on the 10 ms grid (plain-float loops)


def _change_times(rng: np.random.Generator, min_gap_s: float, max_gap_s: float, horizon_s: float) -> tuple[float, ...]:
    """First change uniform in ``_FIRST_CHANGE_S``, then gaps uniform in [min_gap_s, max_gap_s], below horizon_s."""
    times, t = [], rng.uniform(*_FIRST_CHANGE_S)
    while t < horizon_s:
        times.append(float(t))
        t += rng.uniform(min_gap_s, max_gap_s)
    return tuple(times)


def _advance(p: list[float], d: list[float], dist_m: float, lo: list[float], hi: list[float]) -> None:
    """Move ``p`` by ``dist_m`` along the unit ``d``, reflecting ``p`` and ``d`` at the walls (in place)."""
    for a in range(3):
        x = p[a] + dist_m * d[a]
        while not lo[a] <= x <= hi[a]:
            x = 2.0 * lo[a] - x if x < lo[a] else 2.0 * hi[a] - x
            d[a] = -d[a]
        p[a] = x


def _turning_course(spec: TargetSpec, p0: np.ndarray, d0: np.ndarray, low: np.ndarray, high: np.ndarray,
                    times_s: tuple[float, ...], turns: list) -> GridMotion:
    """Constant speed from ``p0`` along ``d0``; at ``times_s[i]`` the direction becomes ``turns[i](d)``.

    A change inside a grid step is applied at its exact time, so grid points lie on the true course.
    """
    dt = _GRID_DT_S
    n = int(np.ceil(spec.horizon_s / dt)) + 1
    p, d = p0.tolist(), d0.tolist()
    lo, hi = low.tolist(), high.tolist()
    speed, e, out = spec.speed_m_s, 0, [list(p)]
    for k in range(1, n):
        t, t_end = (k - 1) * dt, k * dt
        while e < len(times_s) and times_s[e] < t_end:
            _advance(p, d, speed * (times_s[e] - t), lo, hi)
            d, t, e = turns[e](d), times_s[e], e + 1
        _advance(p, d, speed * (t_end - t), lo, hi)
        out.append(list(p))
    return GridMotion(points_m=np.asarray(out), grid_dt_s=dt, change_times_s=times_s)


def _reversal(spec: TargetSpec, rng: np.random.Generator, low: np.ndarray, high: np.ndarray) -> GridMotion:
    p0, d0 = _start_point(spec, rng, low, high), _course_direction(rng, low, high)
    times = _change_times(rng, spec.reversal_min_gap_s, spec.reversal_max_gap_s, spec.horizon_s)
    return _turning_course(spec, p0, d0, low, high, times, [lambda d: [-x for x in d]] * len(times))


def _swerve(spec: TargetSpec, rng: np.random.Generator, low: np.ndarray, high: np.ndarray) -> GridMotion:
    p0, d0 = _start_point(spec, rng, low, high), _course_direction(rng, low, high)
    times = _change_times(rng, spec.swerve_min_gap_s, spec.swerve_max_gap_s, spec.horizon_s)
    flat = high[2] - low[2] < PLANAR_EXTENT_M
    angles = np.radians(rng.uniform(*_SWERVE_ANGLE_DEG, size=len(times)))
    angles *= np.where(rng.uniform(size=len(times)) < 0.5, -1.0, 1.0)
    axes = rng.normal(size=(len(times), 3))  # 3-D: made perpendicular to the velocity at the turn

    def turn(angle: float, r: list[float]):
        c, s = math.cos(angle), math.sin(angle)

        def apply(d: list[float]) -> list[float]:
            if flat:  # about the vertical: the course stays horizontal
                return [c * d[0] - s * d[1], s * d[0] + c * d[1], d[2]]
            # axis a = r minus its component along d; d' = d cos + (a x d) sin (Rodrigues, a _|_ d)
            rd = r[0] * d[0] + r[1] * d[1] + r[2] * d[2]
            a = [r[i] - rd * d[i] for i in range(3)]
            na = math.sqrt(a[0] ** 2 + a[1] ** 2 + a[2] ** 2)
            if na < 1e-9:  # pragma: no cover - r parallel to d: probability zero
                a, na = [-d[1], d[0], 0.0], math.hypot(d[0], d[1]) or 1.0
            a = [x / na for x in a]
            axd = [a[1] * d[2] - a[2] * d[1], a[2] * d[0] - a[0] * d[2], a[0] * d[1] - a[1] * d[0]]
            out = [c * d[i] + s * axd[i] for i in range(3)]
            norm = math.sqrt(out[0] ** 2 + out[1] ** 2 + out[2] ** 2)
            return [x / norm for x in out]

        return apply

    turns = [turn(float(angle), r.tolist()) for angle, r in zip(angles, axes)]
    return _turning_course(spec, p0, d0, low, high, times, turns)


def _accelerating(spec: TargetSpec, rng: np.random.Generator, low: np.ndarray, high: np.ndarray) -> GridMotion:
    """Speed ``v (1 - cos(w t + phase)) / 2``, ``w = 2 pi / accel_period_s``, along a fixed course.

    Changes: the set-offs from rest, ``w t + phase = 2 pi m`` (t > 0). Not the speed peaks: there the
    speed has a smooth maximum, course and direction stay as they were and the tracker is already
    moving along with the target, so there is nothing to turn toward; at a set-off the target leaves
    rest, and a tracker that has (nearly) caught it must start moving again.
    """
    dt = _GRID_DT_S
    n = int(np.ceil(spec.horizon_s / dt)) + 1
    p0, d0 = _start_point(spec, rng, low, high), _course_direction(rng, low, high)
    phase = float(rng.uniform(0.0, 2.0 * math.pi))
    w = 2.0 * math.pi / spec.accel_period_s
    half_v = 0.5 * spec.speed_m_s

    def travelled_m(t: float) -> float:  # integral of the speed from 0 to t, up to a constant
        return half_v * (t - math.sin(w * t + phase) / w)

    p, d = p0.tolist(), d0.tolist()
    lo, hi = low.tolist(), high.tolist()
    out, s_prev = [list(p)], travelled_m(0.0)
    for k in range(1, n):
        s_now = travelled_m(k * dt)
        _advance(p, d, s_now - s_prev, lo, hi)
        s_prev = s_now
        out.append(list(p))
    first, times = (2.0 * math.pi - phase) / w, []  # the first set-off is in (0, accel_period_s]
    while first + len(times) * spec.accel_period_s < spec.horizon_s:
        times.append(first + len(times) * spec.accel_period_s)
    return GridMotion(points_m=np.asarray(out), grid_dt_s=dt, change_times_s=tuple(times))


def _circle(spec, rng: np.random.Generator, low: np.ndarray, high: np.ndarray) -> CircleMotion:
    """A horizontal circle of ``spec.circle_radius_m`` inside the box, starting away from ``avoid_pos_m``."""
    r = spec.circle_radius_m
    clow, chigh = low + np.array([r, r, 0.0]), high - np.array([r, r, 0.0])
    avoid = np.asarray(spec.avoid_pos_m, dtype=float)
    for _ in range(_MAX_TRIES):
        centre = rng.uniform(clow, chigh)
        phase = rng.uniform(0.0, 2 * np.pi)
        start = centre + r * np.array([np.cos(phase), np.sin(phase), 0.0])
        if np.linalg.norm(start - avoid) >= spec.min_start_dist_m:
            break
    else:
        raise ValueError(f"TargetSpec: no circle start is {spec.min_start_dist_m} m from avoid_pos_m={spec.avoid_pos_m!r}")
    sign = 1.0 if rng.uniform() < 0.5 else -1.0
    return CircleMotion(centre_m=centre, radius_m=r, rate_rad_s=sign * spec.speed_m_s / r, phase_rad=phase)
