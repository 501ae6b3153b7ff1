"""The 1 kHz control layer: kept at this path for its importers; the chain of stages lives in ``mmact_ctrl.control``."""

from mmact_ctrl.control.chunk_stage import GRIPPER_OPEN_M
from mmact_ctrl.control.controller import HybridController
from mmact_ctrl.control.samples import ControllerCounters, TickOutput

__all__ = ["GRIPPER_OPEN_M", "ControllerCounters", "HybridController", "TickOutput"]
