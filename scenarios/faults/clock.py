"""Simulated time for the fault injectors: the world's clock and whether a time falls in a fault window."""

from __future__ import annotations

#: tolerance on window edges, s (a tick exactly at the onset is inside, one exactly at the end is outside).
EPS_S = 1e-9


def in_window(window: tuple[float, float], t_s: float) -> bool:
    """``t_s`` in the fault window ``[start, end)`` (edges within :data:`EPS_S`)."""
    return window[0] - EPS_S <= t_s < window[1] - EPS_S


def sim_time_s(world) -> float:
    """The world's simulated time (the loop's ``t`` at the tick being computed)."""
    data = getattr(world, "data", None)
    if data is not None and hasattr(data, "time"):
        return float(data.time)
    return float(world.state().t_s)
