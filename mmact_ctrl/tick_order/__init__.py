"""The order of one tick's work, as a strategy of the runner (``mmact_ctrl.runner``).

- :class:`SimulatedOrder` (``simulated.py``): everything before the command (how every published study ran); the work
  real time does after the command is timed apart (``EpisodeLog.after_us``).
- :class:`DeadlineOrder` (``deadline.py``): what the command needs first (the state, the controller's tick, the
  safety check), the rest once it is out (fusing the measurements that arrived, admitting the chunks due by the next
  tick, the MPC's update in two stages); a command ready after its deadline never reaches the robot.

Both give the runner four steps: :meth:`on_arrival` (measurements arrived), :meth:`before_command`,
:meth:`command`, :meth:`after_command`.
"""

from mmact_ctrl.tick_order.deadline import DeadlineOrder
from mmact_ctrl.tick_order.simulated import SimulatedOrder


def make_order(deadline=None):
    """The tick order of a runner: :class:`DeadlineOrder` with a deadline (real time), else :class:`SimulatedOrder`."""
    return SimulatedOrder() if deadline is None else DeadlineOrder(deadline)


__all__ = ["DeadlineOrder", "SimulatedOrder", "make_order"]
