"""Whether the fingers are still closing on nothing, from their measured opening (``RobotState.gripper_m``).

The grasp latch (``ChunkStage``) holds the chunk's correction while the fingers hold the object: what they hold moves
with the hand, and its measured motion must no longer steer the hand. Until the pads are on the object, though, the
object still moves with the world, and the fingers take 0.175 s to close from open onto a 4.5 cm cube (the Franka
Hand's 0.1 m/s a finger). Latched from the closing *command*, the hand went on along the chunk's course for that
long while the object did not: on the reversal at 0.2 m/s (hybrid, seed 1024) the cube, centred when the closing
began, was 14 mm off the fingers' axis when a pad met it, and the carrier dragged it against that finger (36 N). The
fingers are on nothing yet while they are wide open or their opening still shrinks at their free closing speed; from
the tick they stop (on the object, or closed on nothing) the latch's own test decides, as before.
"""

from __future__ import annotations

from mmact_ctrl.control.chunk_stage import GRIPPER_OPEN_M

#: the opening's free closing speed, m/s (the Franka Hand's 0.1 m/s a finger, as the contact tasks' gripper model
#: moves them)
OPENING_CLOSES_M_S = 0.2
#: the opening shrinks faster than this while the fingers close freely, m/s: half the Franka Hand's free closing
#: speed (0.1 m/s a finger, 0.2 m/s the opening). Measured on the reversal's seed 1024: 0.200 m/s free, under
#: 0.03 m/s once the pads hold the cube; a pad that meets the cube first and is pushed back stops the shrinking too
#: (the latch's own test then decides, and the measured force over 3 N latches anyway)
FREE_CLOSING_M_S = 0.5 * OPENING_CLOSES_M_S
#: fingers measured wider than this are still open (a closing command has not moved them yet), m
WIDE_OPEN_M = GRIPPER_OPEN_M - 0.002


class FingerWatch:
    """See the module. ``update`` once a tick with the measured opening (None: the world measures none)."""

    def __init__(self, dt_s: float) -> None:
        self.dt_s = float(dt_s)
        self.reset()

    def reset(self) -> None:
        self.opening_m: float | None = None
        self.rate_m_s = 0.0  # the opening's rate of change over the last tick, m/s

    def update(self, opening_m: float | None) -> None:
        if opening_m is None:
            self.reset()
            return
        if self.opening_m is not None:
            self.rate_m_s = (opening_m - self.opening_m) / self.dt_s
        self.opening_m = float(opening_m)

    @property
    def on_nothing_yet(self) -> bool:
        """Whether the fingers are measured wide open or still closing freely (False where nothing is measured)."""
        return self.opening_m is not None and (self.opening_m > WIDE_OPEN_M or self.rate_m_s < -FREE_CLOSING_M_S)
