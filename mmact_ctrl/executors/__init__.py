"""Ways of executing action chunks, one class per file behind one protocol (``base.ChunkExecutor``)."""

from mmact_ctrl.executors.base import ChunkExecutor, ClockedExecutor, Layers, QueryContext
from mmact_ctrl.executors.registry import EXECUTORS, make_executor

__all__ = ["ChunkExecutor", "ClockedExecutor", "Layers", "QueryContext", "EXECUTORS", "make_executor"]
