"""Real time's tick order: the command first (state, the controller's tick, the safety check), then the rest once it
is out; a command ready after its cycle's deadline never reaches the robot, which re-applies the last torque."""

from __future__ import annotations

import time

from mmact_ctrl.control.samples import TickOutput


class DeadlineOrder:
    """The deadline order for one episode.

    Args:
        deadline: an object whose ``missed(k)`` says, once tick ``k``'s command is computed, whether it is ready too
            late for its cycle (``mmact_ctrl.realtime.pacer.WallClockPacer``; a deadline every command meets gives
            this order in simulated time).
    """

    defers_mpc = True

    def __init__(self, deadline) -> None:
        self.deadline = deadline
        self._arrived: list = []  # measurements arrived at this tick, fused once the command is out

    def on_arrival(self, runner, arrived: list, tick0_s: float) -> float:
        """Keep ``arrived`` for after the command; nothing done now."""
        self._arrived.extend(arrived)
        return 0.0

    def before_command(self, runner, t_s: float) -> float:
        """Nothing before the command: due chunks are admitted after it (active from the next tick)."""
        return 0.0

    def command(self, runner, k: int, t_s: float, state) -> TickOutput:
        """The controller's tick; when it is ready after its deadline, the robot never got it (counted, and the QP is
        put back to the torque the robot re-applied)."""
        controller, log = runner.controller, runner.log
        before = controller.command_state()
        out = controller.tick(t_s, state.q_rad, state.dq_rad_s)
        if self.deadline.missed(k):
            out = controller.late_tick(before, out)
            runner.missed_in_row += 1
            log.missed_ticks += 1
            log.late_commands += 1
        else:
            runner.missed_in_row = 0
        return out

    def after_command(self, runner, t_s: float) -> float:
        """Once the command of the tick at ``t_s`` is out: fuse what arrived at this tick, admit the chunks due by the
        next tick (active from it), then a stage of the controller's MPC update. Returns the time it took, us."""
        a0 = time.perf_counter()
        # a tick that built an observation for the source has had its share of work: its measurements wait a tick
        # (the filter fuses each at its capture time, so only when the estimate has them moves, by 1 ms)
        if self._arrived and not runner.asked_at(t_s):
            arrived, self._arrived = self._arrived, []
            runner.fuse(arrived)
        admitted = runner.admit_due(t_s + runner.dt_s)
        # a tick that admitted a chunk has had its share of work: the MPC's next stage waits a tick
        return (time.perf_counter() - a0) * 1e6 + runner.controller.end_tick(spare=admitted == 0)
