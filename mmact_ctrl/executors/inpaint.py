"""``inpaint``: real-time chunking (RTC, arXiv 2506.07339): the waypoints that will run while the next chunk is
computed are given to the source as known (``source.plan_inpaint(observation, known)``) and the rest is filled in,
so chunks join without a jump. The known prefix is taken from the chunk that will be executing then (the last one
accepted), at the new chunk's waypoint times."""

from __future__ import annotations

from typing import Callable

import numpy as np

from mmact_ctrl.chunk import ActionChunk, ChunkSource, Observation
from mmact_ctrl.executors.base import ClockedExecutor, QueryContext
from mmact_ctrl.reference import ChunkReference


def known_prefix(scheduled: ActionChunk | None, t_s: float, latency_s: float, chunk_dt_s: float | None) -> np.ndarray:
    """The waypoints (n, 7) of ``scheduled`` at the times ``t_s + (i + 1) dt`` that run during the latency
    (``n = ceil(latency / dt)``); empty without a scheduled chunk."""
    if scheduled is None:
        return np.zeros((0, 7))
    dt = chunk_dt_s or scheduled.dt_s
    n_known = int(np.ceil(latency_s / dt - 1e-9))
    ref = ChunkReference(chunk=scheduled, t_active_s=t_s, target_at_obs_m=None)
    return np.array([ref.sample(t_s + (i + 1) * dt)[0] for i in range(n_known)]).reshape(n_known, 7)


class InpaintExecutor(ClockedExecutor):
    """Asks the source to inpaint around the committed prefix."""

    name = "inpaint"
    needs = frozenset({"inpaint"})

    def request(self, source: ChunkSource, observation: Observation, ctx: QueryContext) -> Callable[[], ActionChunk]:
        prefix = known_prefix(ctx.scheduled, ctx.t_s, ctx.latency_s, ctx.chunk_dt_s)
        return lambda: source.plan_inpaint(observation, prefix)
