"""Simulated time's tick order: fuse, admit, command, the rest; everything before the command, as every study ran."""

from __future__ import annotations

import time

from mmact_ctrl.control.samples import TickOutput


class SimulatedOrder:
    """Measurements are fused as they arrive and due chunks admitted before the command; the MPC's update runs inside
    the controller's tick (``defers_mpc`` False). The time of the work real time does after the command is measured
    here and recorded apart, so ``tick_us`` is the command path in both orders."""

    defers_mpc = False

    def on_arrival(self, runner, arrived: list, tick0_s: float) -> float:
        """Fuse ``arrived`` now; returns the time it took, us (work real time does after the command)."""
        runner.fuse(arrived)
        return (time.perf_counter() - tick0_s) * 1e6

    def before_command(self, runner, t_s: float) -> float:
        """Admit the chunks due at ``t_s``; returns the time it took, us."""
        a0 = time.perf_counter()
        runner.admit_due(t_s)
        return (time.perf_counter() - a0) * 1e6

    def command(self, runner, k: int, t_s: float, state) -> TickOutput:
        """The controller's tick; the command reaches the robot."""
        runner.missed_in_row = 0
        return runner.controller.tick(t_s, state.q_rad, state.dq_rad_s)

    def after_command(self, runner, t_s: float) -> float:
        """Nothing deferred (the controller's share returns 0); the time it took, us."""
        return runner.controller.end_tick()
