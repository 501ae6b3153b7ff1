"""The executors by name (``StackConfig.mode``, ``--mode``)."""

from __future__ import annotations

from types import MappingProxyType
from typing import Callable, Mapping

from mmact_ctrl.executors.base import ChunkExecutor
from mmact_ctrl.executors.hybrid import HybridExecutor
from mmact_ctrl.executors.inpaint import InpaintExecutor
from mmact_ctrl.executors.open_loop import OpenLoopExecutor
from mmact_ctrl.executors.receding import RecedingExecutor
from mmact_ctrl.executors.residual import ResidualExecutor
from mmact_ctrl.executors.temporal_ensemble import TemporalEnsembleExecutor

#: every built-in executor, by name, in the study's order (baselines first, ours last)
EXECUTORS: Mapping[str, Callable[[], ChunkExecutor]] = MappingProxyType({
    "open_loop": OpenLoopExecutor,
    "receding": RecedingExecutor,
    "temporal_ensemble": TemporalEnsembleExecutor,
    "inpaint": InpaintExecutor,
    "residual": ResidualExecutor,
    "hybrid": HybridExecutor,
})


def make_executor(mode: str, executors: Mapping[str, Callable[[], ChunkExecutor]] = EXECUTORS) -> ChunkExecutor:
    """A fresh executor for ``mode`` from ``executors`` (default: the built-in ones)."""
    try:
        factory = executors[mode]
    except KeyError:
        raise ValueError(f"unknown mode {mode!r}; expected one of {tuple(executors)}") from None
    return factory()
