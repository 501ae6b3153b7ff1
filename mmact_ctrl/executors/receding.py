"""``receding``: the first ``k`` waypoints of each chunk run, then the source is queried again (Diffusion Policy
style): replanning is paced by execution, not by the clock. ``k = StackConfig.receding_k``, or (0) the waypoints
one replan period covers, ``1 / (replan_hz * chunk dt)``."""

from __future__ import annotations

import math

from mmact_ctrl.chunk import ActionChunk
from mmact_ctrl.executors.base import ClockedExecutor
from mmact_ctrl.reference import ChunkReference


def receding_k(receding_k_cfg: int, replan_hz: float, chunk: ActionChunk) -> int:
    """Waypoints a receding-horizon executor runs per chunk."""
    if receding_k_cfg:
        return min(receding_k_cfg, chunk.horizon)
    return int(min(chunk.horizon, max(1, round(1.0 / (replan_hz * chunk.dt_s)))))


class RecedingExecutor(ClockedExecutor):
    """Query, wait for the chunk, run ``k`` of its waypoints, query again."""

    name = "receding"

    def after_request(self, t_s: float, chunk: ActionChunk | None, next_query_s: float, period_s: float) -> float:
        # the next query is set when this chunk starts running; a refused call asks again one period on
        return math.inf if chunk is not None else t_s + period_s

    def after_activation(self, t_s: float, ref: ChunkReference, next_query_s: float) -> float:
        cfg = self.view.config
        return t_s + receding_k(cfg.receding_k, cfg.replan_hz, ref.chunk) * ref.chunk.dt_s

    def after_refusal(self, t_s: float, next_query_s: float) -> float:
        return t_s if next_query_s == math.inf else next_query_s  # the chunk it waited for was refused: ask now
