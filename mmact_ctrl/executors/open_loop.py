"""``open_loop``: each chunk's dequantized waypoints are interpolated and tracked by the QP, nothing else; the
source is queried on the clock at ``replan_hz`` and the newest chunk replaces the running one on arrival."""

from __future__ import annotations

from mmact_ctrl.executors.base import ClockedExecutor


class OpenLoopExecutor(ClockedExecutor):
    """Every default of :class:`~mmact_ctrl.executors.base.ClockedExecutor`."""

    name = "open_loop"
