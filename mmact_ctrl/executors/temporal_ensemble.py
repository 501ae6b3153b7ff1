"""``temporal_ensemble``: ACT's temporal ensembling: every chunk still covering the present is averaged with
exponential weights ``exp(-decay * (t0_chunk - t0_oldest))``, the oldest weighing most
(``StackConfig.ensemble_decay_per_s``)."""

from __future__ import annotations

import numpy as np

from mmact_ctrl.executors.base import ClockedExecutor
from mmact_ctrl.reference import ChunkReference


class TemporalEnsembleExecutor(ClockedExecutor):
    """Keeps the chunks that still cover the future and blends them."""

    name = "temporal_ensemble"

    def __init__(self) -> None:
        super().__init__()
        self.chunks: list[ChunkReference] = []

    def reset(self) -> None:
        self.chunks = []

    def activate(self, ref: ChunkReference, t_s: float) -> None:
        self.chunks = [c for c in self.chunks if c.t_last_s > t_s] + [ref]

    def sample(self, t_s: float, active: ChunkReference) -> tuple[np.ndarray, np.ndarray]:
        live = [c for c in self.chunks if c.t_last_s >= t_s] or [self.chunks[-1] if self.chunks else active]
        oldest = live[0].chunk.t0_s
        decay = self.view.config.ensemble_decay_per_s
        action, rate, total = np.zeros(7), np.zeros(7), 0.0
        for c in live:
            w = float(np.exp(-decay * (c.chunk.t0_s - oldest)))
            a, r = c.sample(t_s)
            action += w * a
            rate += w * r
            total += w
        return action / total, rate / total

    def sample_positions(self, times_s: np.ndarray, active: ChunkReference) -> np.ndarray:
        return np.array([self.sample(t, active)[0][:3] for t in times_s]).reshape(-1, 3)
