"""The estimator's predictions folded into a known box: an object that moves on a carrier of known extent (pick's
conveyor, insert's fixture rail) turns at its walls, which a constant-velocity prediction runs through.

The chunk source of a contact task knows the box (its lead is reflected at the walls); the fast layer is given the
same knowledge (``StackConfig.target_box_m``): its predictions of position and velocity are reflected at the walls of
the axes the box spans (more than ``MIN_EXTENT_M``; a flat box's thin axis is left alone). What was measured is not
changed: only where the object will be; and an object the estimate puts outside the box (pushed off its carrier) is
predicted unbounded on that axis, not mirrored back in.
"""

from __future__ import annotations

import numpy as np

#: an axis of the box narrower than this is not a direction the object moves in (a flat box's height), m
MIN_EXTENT_M = 0.01


def fold(x: np.ndarray, low: np.ndarray, high: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unbounded coordinates reflected into ``[low, high]`` (a triangle wave), and the sign (+1 / -1) a velocity takes
    there (the same shapes as ``x``). The wave of the target motions' and the experts' ``reflect_into_box``
    (``scenarios.world.motions``, beyond this package's wall), with the sign, and a coordinate inside the box kept to
    the bit (``low + (x - low)`` need not be ``x``)."""
    width = high - low
    u = np.mod(x - low, 2.0 * width)
    back = u > width
    inside = (x >= low) & (x <= high)
    return np.where(inside, x, low + np.where(back, 2.0 * width - u, u)), np.where(back, -1.0, 1.0)


class BoxedPrediction:
    """Read-only view of a target estimator (``initialized``, ``predict_pos``, ``predict_pos_many``, ``predict_vel``;
    anything else is the estimator's) whose predictions are reflected at the walls of ``low`` .. ``high`` (3,)."""

    def __init__(self, estimator, low_m, high_m) -> None:
        low, high = np.asarray(low_m, dtype=float), np.asarray(high_m, dtype=float)
        self._est = estimator
        self._axes = np.flatnonzero(high - low > MIN_EXTENT_M)
        self._low, self._high = low[self._axes], high[self._axes]

    def __getattr__(self, name: str):
        return getattr(self._est, name)

    def _walls(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(axes, low, high) of the box's axes on which the estimate (at its last fused time) is inside the box."""
        p = self._est.pos_m[self._axes]
        keep = (p >= self._low) & (p <= self._high)
        return self._axes[keep], self._low[keep], self._high[keep]

    def predict_pos(self, t_s: float) -> np.ndarray:
        p = np.array(self._est.predict_pos(t_s), dtype=float)
        axes, low, high = self._walls()
        p[axes] = fold(p[axes], low, high)[0]
        return p

    def predict_pos_many(self, times_s: np.ndarray) -> np.ndarray:
        p = np.array(self._est.predict_pos_many(times_s), dtype=float)
        axes, low, high = self._walls()
        p[:, axes] = fold(p[:, axes], low, high)[0]
        return p

    def predict_vel(self, t_s: float) -> np.ndarray:
        v = np.array(self._est.predict_vel(t_s), dtype=float)
        axes, low, high = self._walls()
        v[axes] = v[axes] * fold(self._est.predict_pos(t_s)[axes], low, high)[1]
        return v
