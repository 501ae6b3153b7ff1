"""How the state is carried from the last fused capture time to the next one: the gap cut into steps of at most the
nominal period, and the motion estimate dropped where the coast begins."""

from __future__ import annotations

MAX_SUBSTEPS = 64  #: a longer gap (a sensor blackout of seconds) is propagated in this many equal steps


def propagation_steps(gap_s: float, coast_s: float, dt_s: float) -> list[tuple[float, bool]]:
    """The propagation over ``gap_s`` seconds: (step length s, drop the motion estimate first) per step. A gap
    longer than ``coast_s`` (no fused measurement for that long) drops the motion estimate ``coast_s`` after its
    start; every step is at most ``dt_s`` (see :func:`split_gap`)."""
    if gap_s <= coast_s:
        return [(h, False) for h in split_gap(gap_s, dt_s)]
    steps = [(h, False) for h in split_gap(coast_s, dt_s)]
    rest = split_gap(gap_s - coast_s, dt_s)
    return steps + [(rest[0], True)] + [(h, False) for h in rest[1:]]


def split_gap(gap_s: float, dt_s: float) -> list[float]:
    """``gap_s`` in steps of at most ``dt_s`` seconds: one step up to dt_s, whole periods plus a remainder beyond (a
    regular stream's multiple of dt_s: equal steps, as a tick-by-tick filter would take), at most
    :data:`MAX_SUBSTEPS` equal steps. The piecewise-constant white-noise Q is defined per hold period: one Q over a
    0.3 s dropout would not be the tick-by-tick filter's."""
    n = int(gap_s / dt_s + 1e-6)
    if n <= 1 and gap_s <= dt_s * (1 + 1e-6):
        return [gap_s]
    if n >= MAX_SUBSTEPS:
        return [gap_s / MAX_SUBSTEPS] * MAX_SUBSTEPS
    rem = gap_s - n * dt_s
    if rem <= 1e-6 * dt_s:
        return [gap_s / n] * n
    return [dt_s] * n + [rem]
