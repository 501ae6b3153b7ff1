"""The multi-rate loop, run as one call: ``run_episode`` runs an :class:`~mmact_ctrl.runner.EpisodeRunner` to the end.

Physics and control at 1 kHz, perception at 100 Hz, the chunk source at ``replan_hz``. The observation is taken at
``t0``; the chunk it produces becomes active at ``t0 + latency`` while the previous chunk keeps running. The loop
itself (and everything it survives) is documented in ``mmact_ctrl.runner``.
"""

from __future__ import annotations

import numpy as np

from mmact_ctrl.chunk import ChunkSource
from mmact_ctrl.controller import HybridController
from mmact_ctrl.episode_log import CommandLink, EpisodeLog
from mmact_ctrl.perception import TargetSensor
from mmact_ctrl.runner import FRAME_GAP_S, SOURCE_TIMING_KEYS, EpisodeRunner, observe
from mmact_ctrl.world import World

__all__ = ["CommandLink", "EpisodeLog", "EpisodeRunner", "FRAME_GAP_S", "SOURCE_TIMING_KEYS", "observe", "run_episode"]


def run_episode(
    world: World,
    source: ChunkSource,
    controller: HybridController,
    seed: int,
    video_fps: float = 0.0,
    progress=None,
    link: CommandLink | None = None,
    initial_dq_rad_s: np.ndarray | None = None,
    sensor: TargetSensor | None = None,
    record: bool = False,
    lookahead: bool = True,
) -> EpisodeLog:
    """Run one episode of ``controller.config.duration_s`` and return its log (the arguments are
    :class:`~mmact_ctrl.runner.EpisodeRunner`'s)."""
    runner = EpisodeRunner(world, source, controller, seed, video_fps=video_fps, progress=progress, link=link,
                           initial_dq_rad_s=initial_dq_rad_s, sensor=sensor, record=record,
                           lookahead=lookahead)
    runner.advance()
    return runner.finish()
