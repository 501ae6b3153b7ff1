"""The executors by name (``StackConfig.mode``, ``--mode``): the one place that says which modes exist and
validates a name, without importing any executor (each is imported when it is made)."""

from __future__ import annotations

import importlib
from types import MappingProxyType
from typing import Callable, Mapping

from mmact_ctrl.executors.base import ChunkExecutor

#: every built-in executor, by name, in the study's order (baselines first, ours last): ``module:class``
EXECUTOR_PATHS: Mapping[str, str] = MappingProxyType({
    "open_loop": "mmact_ctrl.executors.open_loop:OpenLoopExecutor",
    "receding": "mmact_ctrl.executors.receding:RecedingExecutor",
    "temporal_ensemble": "mmact_ctrl.executors.temporal_ensemble:TemporalEnsembleExecutor",
    "inpaint": "mmact_ctrl.executors.inpaint:InpaintExecutor",
    "residual": "mmact_ctrl.executors.residual:ResidualExecutor",
    "hybrid": "mmact_ctrl.executors.hybrid:HybridExecutor",
})
#: the names of the built-in modes, in the study's order
MODES: tuple[str, ...] = tuple(EXECUTOR_PATHS)


def check_mode(mode: str) -> str:
    """``mode`` if it names a built-in executor, else ``ValueError`` naming the modes."""
    if mode not in EXECUTOR_PATHS:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    return mode


def executor_class(mode: str) -> Callable[[], ChunkExecutor]:
    """The class of the built-in executor ``mode`` (imported now)."""
    module, _, name = EXECUTOR_PATHS[check_mode(mode)].partition(":")
    return getattr(importlib.import_module(module), name)


class _Lazy(Mapping):
    """``EXECUTORS``: name -> class, each imported when looked up."""

    def __getitem__(self, mode: str):
        if mode not in EXECUTOR_PATHS:
            raise KeyError(mode)
        return executor_class(mode)

    def __iter__(self):
        return iter(EXECUTOR_PATHS)

    def __len__(self) -> int:
        return len(EXECUTOR_PATHS)


#: every built-in executor by name (``name -> class``, imported on lookup)
EXECUTORS: Mapping[str, Callable[[], ChunkExecutor]] = _Lazy()


def make_executor(mode: str, executors: Mapping[str, Callable[[], ChunkExecutor]] = EXECUTORS) -> ChunkExecutor:
    """A fresh executor for ``mode`` from ``executors`` (default: the built-in ones)."""
    try:
        factory = executors[mode]
    except KeyError:
        raise ValueError(f"unknown mode {mode!r}; expected one of {tuple(executors)}") from None
    return factory()
