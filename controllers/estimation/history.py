"""The history of processed measurements that makes fusion independent of the arrival order: each entry keeps the
estimator's snapshot from just before it, so a measurement that arrives out of order (captured before the newest one
processed) rolls the estimator back to the entry after it and the later ones are re-fused in capture order."""

from __future__ import annotations

from bisect import bisect_right
from typing import NamedTuple

import numpy as np


class HistoryEntry(NamedTuple):
    """A processed measurement: capture time (s), value (3,) m, the estimator's snapshot just before it, and the
    capture time of the measurement processed before it (a roll-back to this entry is valid only for later
    captures), s."""

    t_s: float
    z_m: np.ndarray
    before: tuple
    t_prev_s: float


def trim(history: list[HistoryEntry], horizon_s: float) -> None:
    """Drop the entries captured before ``horizon_s`` (s), in place; the newest one always stays."""
    drop = 0
    while drop < len(history) - 1 and history[drop].t_s < horizon_s:
        drop += 1
    if drop:
        del history[:drop]


def rollback_index(history: list[HistoryEntry], t_s: float, history_s: float) -> int | None:
    """For a measurement captured at ``t_s`` before the newest entry: the index of the first entry after it (roll
    back to that entry's snapshot), or None when it is older than ``history_s`` (s) behind the newest entry or than
    the stored history reaches (drop it)."""
    k = bisect_right([e.t_s for e in history], t_s)
    if history[-1].t_s - t_s > history_s or history[k].t_prev_s > t_s:
        return None
    return k


def first_after(history: list[HistoryEntry], t_s: float) -> HistoryEntry | None:
    """The oldest entry captured after ``t_s`` (s), or None."""
    for entry in history:
        if entry.t_s > t_s:
            return entry
    return None
