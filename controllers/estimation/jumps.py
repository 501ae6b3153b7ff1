"""Jumps: gated measurements that agree with each other are the target at a new place, not outliers.

``reset_after`` outliers in a row, each within ``jump_agree_m`` of the previous one, confirm a jump: the estimator
re-initialises on the last of them (instead of slowly gliding over) and remembers it as a :class:`Jump`; isolated or
scattered outliers never move it. :func:`estimate_at_observation` then corrects what an observation taken during
the confirmation recorded."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class GatedRun(NamedTuple):
    """The outliers gated in a row so far that agree with each other: how many, the last one (m), and the capture
    time of the first one (s)."""

    count: int
    last_m: np.ndarray | None
    since_s: float


NO_RUN = GatedRun(0, None, 0.0)  #: no outlier since the last fused measurement (or re-initialisation)


def extend_run(run: GatedRun, z_m: np.ndarray, t_s: float, jump_agree_m: float) -> GatedRun:
    """The run after one more outlier ``z_m`` captured at ``t_s``: one longer if it agrees with the last one (within
    ``jump_agree_m``, m), else a new run of one."""
    agrees = run.last_m is not None and np.linalg.norm(z_m - run.last_m) <= jump_agree_m
    count = run.count + 1 if (agrees or run.count == 0) else 1
    return GatedRun(count, z_m, t_s if count == 1 else run.since_s)


class Jump(NamedTuple):
    """A confirmed jump: the capture time of its first measurement (s), of the re-initialisation (s), and where the
    estimator re-initialised (3,) m."""

    started_s: float
    reset_at_s: float
    pos_m: np.ndarray


def estimate_at_observation(jump: Jump | None, t0_s: float, recorded_m: np.ndarray | None,
                            dt_s: float) -> np.ndarray | None:
    """The best estimate of where the target was at an observation time ``t0_s`` (s), given the last confirmed
    ``jump``: ``recorded_m``, the estimate taken at ``t0_s``, unless the jump had already begun at ``t0_s`` (its
    first measurement was captured at or before it, to half a period ``dt_s``) and was confirmed after it: the
    recorded estimate then predates the estimator's knowledge of a jump the observation already saw, and the
    post-jump position is returned instead (a chunk planned on the new position must not be shifted by the jump a
    second time)."""
    if recorded_m is None or jump is None or not (jump.started_s - 0.5 * dt_s <= t0_s < jump.reset_at_s):
        return recorded_m
    return jump.pos_m.copy()
