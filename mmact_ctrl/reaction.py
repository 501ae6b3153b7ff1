"""How fast the TCP reacts when the target's course changes (jump, flip, swerve, set-off). Pure numpy.

``reaction_metrics(t_s, ee_pos_m, target_pos_m, change_times_s)`` works on a logged episode (TCP and
target positions at the log times, world frame) and the change times of the target's motion
(``scenarios.world.targets``: ``motion.change_times_s``). Definitions, for each change at ``t_c``:

- evaluated: the change lies in the episode and its window ``[t_c, t_c + window_s]`` ends inside it
  (``window_s`` >= the 0.2 s course window below); otherwise both its times are NaN. Changes after
  the last sample are dropped.
- TCP velocity ``v(t)``: the TCP position resampled (linear interpolation) at ``vel_rate_hz`` (100 Hz)
  from the first sample, central differences, smoothed by a centred [1/4, 1/2, 1/4] kernel: the
  velocity of the motion over +-20 ms, with no lag. ``v0``: the TCP's mean velocity over the 50 ms
  before ``t_c``.
- the direction ``w`` the TCP has to turn toward: for a jump (the target moves > 2 cm between the
  last sample before ``t_c`` and ``t_c + 20 ms``) the direction from the TCP at ``t_c`` to the new
  target; otherwise the direction of the target's own velocity change, its mean velocity over the
  0.2 s after ``t_c`` minus its velocity over the 20 ms before. For a reversal ``w`` is the new
  course ``u``; for a swerve by ``a`` it lies between the new course and the reversed old one; for a
  set-off from rest it is the course. (A wall bounce inside those 0.2 s bends ``w``.)
- reaction time: the first time ``t >= t_c`` at which the TCP's velocity change since the change,
  projected on ``w``, ``(v(t) - v0) . w``, reaches ``threshold_m_s`` (0.05 m/s) and stays there for
  ``hold_s`` (50 ms); ``t - t_c``, the crossing interpolated between the 100 Hz samples; NaN if it
  does not happen by ``t_c + window_s`` (the TCP never turns) or ``w`` is undefined. This is the
  onset of the response, comparable across families. Two alternatives were rejected: "the velocity
  component along the new course ``u`` becomes positive" adds the braking time to a reversal (a TCP
  moving at 0.2 m/s with 2 m/s^2 brakes for 0.1 s before it turns) and is met before any response
  to a swerve by less than 90 deg (the old velocity already has a positive component along ``u``);
  "exceeds its value before the change by 0.05 m/s" is nearly unreachable for a 45 deg swerve (the
  component along ``u`` can only grow from cos 45 = 0.71 to 1 times the speed).
- reach time: the first log sample from one sample after ``t_c`` on (the convention of the jump
  recovery in ``mmact_ctrl.metrics``, so the target's logged position has moved) with the TCP within
  ``success_radius_m`` of the target, minus ``t_c``; about 0 when the TCP never lost the target; NaN
  if not within ``window_s``.
- ``reaction_s``, ``reach_after_change_s``: medians of the finite per-change times (NaN if none);
  ``n_changes``: changes in the episode (the length of the lists), ``n_evaluated``: those evaluated,
  ``reacted``, ``reached``: those with a finite reaction, reach time.
"""

from __future__ import annotations

import numpy as np

#: the target's new course is its mean velocity over this long after a change, s.
COURSE_S = 0.2
#: the target's velocity before a change, and the jump test, use this long a span, s.
BEFORE_S = 0.02
#: the TCP's velocity before a change is its mean over this long, s.
TCP_BEFORE_S = 0.05
#: a change whose target moves farther than this within ~``BEFORE_S`` is a jump (2 m/s: no course is that fast), m.
JUMP_MIN_M = 0.02


def _interp3(at_s: np.ndarray | float, t_s: np.ndarray, x_m: np.ndarray) -> np.ndarray:
    """Linear interpolation of ``x_m`` (N, 3) at ``at_s`` (scalar -> (3,), (M,) -> (M, 3))."""
    return np.stack([np.interp(at_s, t_s, x_m[:, a]) for a in range(3)], axis=-1)


def _nanmedian(values: list[float]) -> float:
    finite = [v for v in values if np.isfinite(v)]
    return float(np.median(finite)) if finite else float("nan")


def _turn_direction(t: np.ndarray, tcp_m: np.ndarray, target_m: np.ndarray, c_s: float) -> np.ndarray | None:
    """Unit direction the TCP has to turn toward after the change at ``c_s`` (module docstring), or None."""
    i_before = max(0, int(np.searchsorted(t, c_s, side="left")) - 1)
    after_m = _interp3(c_s + BEFORE_S, t, target_m)
    if np.linalg.norm(after_m - target_m[i_before]) > JUMP_MIN_M:  # a jump: toward the new target
        d = after_m - _interp3(c_s, t, tcp_m)
    else:
        at_c = _interp3(c_s, t, target_m)
        v_after = (_interp3(c_s + COURSE_S, t, target_m) - at_c) / COURSE_S
        span_s = min(BEFORE_S, c_s - t[0])
        v_before = (at_c - _interp3(c_s - span_s, t, target_m)) / span_s if span_s > 0 else np.zeros(3)
        d = v_after - v_before
    norm = float(np.linalg.norm(d))
    return d / norm if norm > 1e-6 else None


def _check_inputs(t: np.ndarray, tcp_m: np.ndarray, target_m: np.ndarray, window_s: float, vel_rate_hz: float,
                  threshold_m_s: float, hold_s: float) -> None:
    if t.ndim != 1 or len(t) < 2 or np.any(np.diff(t) <= 0):
        raise ValueError(f"reaction_metrics: t_s must be >= 2 increasing times, got shape {t.shape}")
    if tcp_m.shape != (len(t), 3) or target_m.shape != (len(t), 3):
        raise ValueError(f"reaction_metrics: ee_pos_m {tcp_m.shape} and target_pos_m {target_m.shape} must be "
                         f"({len(t)}, 3)")
    if not (window_s >= COURSE_S and vel_rate_hz > 0 and threshold_m_s > 0 and hold_s >= 0):
        raise ValueError(f"reaction_metrics: need window_s >= {COURSE_S} (got {window_s!r}), vel_rate_hz > 0 "
                         f"(got {vel_rate_hz!r}), threshold_m_s > 0 (got {threshold_m_s!r}), hold_s >= 0 (got {hold_s!r})")


def _first_crossing(gain: np.ndarray, n: int, hold_n: int, threshold_m_s: float, grid: np.ndarray, k0: int,
                    h: float, c: float) -> float:
    """The time after ``c`` (s) at which ``gain`` first reaches the threshold and stays there ``hold_n`` samples
    (interpolated between the samples around the crossing), or NaN."""
    above = gain >= threshold_m_s
    for j in range(n):
        if above[j] and (j + hold_n > len(above) or above[j:j + hold_n].all()):
            if j == 0:
                return max(0.0, float(grid[k0]) - c)
            frac = (threshold_m_s - gain[j - 1]) / (gain[j] - gain[j - 1])  # between j-1 (below) and j (at or above)
            return max(0.0, float(grid[k0 + j - 1] + frac * h) - c)
    return float("nan")


def reaction_metrics(t_s: np.ndarray, ee_pos_m: np.ndarray, target_pos_m: np.ndarray,
                     change_times_s: tuple[float, ...] | list[float], success_radius_m: float = 0.03,
                     window_s: float = 1.5, vel_rate_hz: float = 100.0, threshold_m_s: float = 0.05,
                     hold_s: float = 0.05) -> dict:
    """Reaction and reach times after each change of the target's course (module docstring); JSON-ready."""
    t = np.asarray(t_s, dtype=float)
    tcp_m, target_m = np.asarray(ee_pos_m, dtype=float), np.asarray(target_pos_m, dtype=float)
    _check_inputs(t, tcp_m, target_m, window_s, vel_rate_hz, threshold_m_s, hold_s)
    t0, t_end = float(t[0]), float(t[-1])
    h = 1.0 / vel_rate_hz
    grid = t0 + h * np.arange(int(np.floor((t_end - t0) / h + 1e-9)) + 1)
    v = np.gradient(_interp3(grid, t, tcp_m), h, axis=0) if len(grid) > 1 else np.zeros((1, 3))
    v[1:-1] = 0.25 * v[:-2] + 0.5 * v[1:-1] + 0.25 * v[2:]  # right side is evaluated before assignment
    hold_n = max(1, int(round(hold_s / h)))
    inside = np.linalg.norm(tcp_m - target_m, axis=1) < success_radius_m

    changes = [float(c) for c in change_times_s if t0 <= c <= t_end]
    reaction, reach, evaluated = [], [], 0
    for c in changes:
        if c + window_s > t_end + 1e-9:
            reaction.append(float("nan"))
            reach.append(float("nan"))
            continue
        evaluated += 1
        # reach: from one log sample after the change on
        i0 = int(np.searchsorted(t, c, side="left")) + 1
        i1 = int(np.searchsorted(t, c + window_s, side="right"))
        hit = np.flatnonzero(inside[i0:i1])
        reach.append(float(t[i0 + hit[0]] - c) if hit.size else float("nan"))
        # reaction: (v - v0) . w >= threshold for hold_n samples
        w = _turn_direction(t, tcp_m, target_m, c)
        if w is None:
            reaction.append(float("nan"))
            continue
        span_s = min(TCP_BEFORE_S, c - t0)
        v0 = (_interp3(c, t, tcp_m) - _interp3(c - span_s, t, tcp_m)) / span_s if span_s > 0 else np.zeros(3)
        k0 = int(np.searchsorted(grid, c - 1e-9, side="left"))
        k1 = int(np.searchsorted(grid, c + window_s + 1e-9, side="right"))
        reaction.append(_first_crossing((v[k0:] - v0) @ w, k1 - k0, hold_n, threshold_m_s, grid, k0, h, c))
    return {
        "reaction_s": _nanmedian(reaction),
        "reach_after_change_s": _nanmedian(reach),
        "n_changes": len(changes),
        "n_evaluated": evaluated,
        "reacted": int(np.sum(np.isfinite(reaction))),
        "reached": int(np.sum(np.isfinite(reach))),
        "reaction_times_s": reaction,
        "reach_times_s": reach,
    }
