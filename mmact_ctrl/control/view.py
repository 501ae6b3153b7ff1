"""What an executor may know of the controller that runs it: a narrow, read-only view.

An executor (``mmact_ctrl.executors``) reads the stack's settings (its retargeting rule, the replan rate, ...), the
target estimate (the 100 Hz channel, filtered) and the TCP's state at the last tick; it is never handed the
controller itself, so it cannot reach into the QP, the MPC or the smoother.
"""

from __future__ import annotations

import numpy as np

from mmact_ctrl.config import StackConfig


class ExecutorView:
    """Read-only: ``config``, ``estimate`` (the target estimator: ``initialized``, ``predict_pos``, ``predict_vel``,
    ``predict_pos_many``), ``tcp_pos_m`` / ``tcp_vel_m_s`` (the TCP at the last tick, None before the first)."""

    __slots__ = ("_controller",)

    def __init__(self, controller) -> None:
        self._controller = controller

    @property
    def config(self) -> StackConfig:
        return self._controller.config

    @property
    def estimate(self):
        """The target estimator of this episode (read it; it is fused by the controller), its predictions reflected
        at the walls of ``config.target_box_m`` when a task gives one."""
        return self._controller.estimate

    @property
    def tcp_pos_m(self) -> np.ndarray | None:
        terms = self._controller.terms
        return None if terms is None else terms.pos_m

    @property
    def tcp_vel_m_s(self) -> np.ndarray | None:
        terms = self._controller.terms
        return None if terms is None else terms.vel[:3]
