"""The grasp reflex (``StackConfig.grasp_reflex``, ``--grasp-reflex``): the fast layer decides when the gripper
closes, from the measured object, not from the chunk's clock.

A chunk closes the gripper at the time it planned to be at the object; if the hand is late (a moving object, a
stale chunk) the fingers close where the object *was*. With the reflex the gripper stays open while the chunk asks
to close and the object's estimate is not yet between the fingers, and closes as soon as it is (even a little before
the chunk asks); it opens again only when the chunk asks to open and the object is not between the fingers.
Off, the chunk's gripper channel passes unchanged. It needs the object's measurement: a mode that does not read the
target (``open_loop``, ``receding``, ...) cannot have it (:func:`reflex_refusal`, one line), rather than a reflex
that never sees the object and never closes.
"""

from __future__ import annotations

import numpy as np

from mmact_ctrl.control.chunk_stage import GRIPPER_CLOSING_BELOW_M, GRIPPER_OPEN_M

#: the object is between the fingers when its estimate is within these of the TCP: across the fingers' faces
#: (horizontal) and along them (vertical), m; a 4.5 cm cube in the 8 cm opening has 1.75 cm to spare a side
BETWEEN_XY_M, BETWEEN_Z_M = 0.012, 0.015
#: an object the closed fingers measure (they stopped on it) stays in the pads' grip this far off the TCP
#: horizontally, m: the pads centre it along the fingers' axis, but across them it may sit anywhere the pads still
#: press its faces (half a 4.5 cm object plus the pads' half width, 8.5 mm, less a margin). A held cube 18-24 mm
#: across the axis was taken for a miss: the correction was let go and swept the hand at 0.5-0.8 m/s
HOLD_XY_M = 0.03
#: a gripper command below this closes the gripper, and the open and closed commands, m (the chunk stage's)
CLOSING_BELOW_M, OPEN_M = GRIPPER_CLOSING_BELOW_M, GRIPPER_OPEN_M
CLOSED_M = 0.0


def reflex_refusal(mode: str) -> str:
    """The one line that refuses the reflex to ``mode``, which does not read the object's measurement."""
    from mmact_ctrl.executors.registry import EXECUTORS

    readers = ", ".join(name for name, cls in EXECUTORS.items() if cls.layers.reads_target)
    return (f"--grasp-reflex needs the object's measurement, which --mode {mode} does not read "
            f"(modes that read it: {readers})")


class GraspReflex:
    """See the module. ``enabled`` False passes the chunk's command through."""

    def __init__(self, enabled: bool) -> None:
        self.enabled = bool(enabled)
        self.reset()

    def reset(self) -> None:
        self.closed = False
        self.closings = 0

    def __call__(self, gripper_cmd_m: float, tcp_pos_m: np.ndarray, object_pos_m: np.ndarray | None) -> float:
        """The gripper command to send: ``gripper_cmd_m`` (the chunk's, m) as the reflex has it, given the measured
        TCP and the object's current estimate (None: no estimate yet)."""
        if not self.enabled:
            return gripper_cmd_m
        between = object_pos_m is not None and self.between(tcp_pos_m, object_pos_m)
        if between and not self.closed:
            self.closed = True
            self.closings += 1
        elif gripper_cmd_m >= CLOSING_BELOW_M and not between:
            self.closed = False
        if self.closed:
            return CLOSED_M
        return gripper_cmd_m if gripper_cmd_m >= CLOSING_BELOW_M else OPEN_M

    @staticmethod
    def holding(tcp_pos_m: np.ndarray, object_pos_m: np.ndarray) -> bool:
        """Whether an object the fingers have closed on (their measured opening says so: the caller's) is still in
        the grip: within ``HOLD_XY_M`` of the TCP horizontally, ``BETWEEN_Z_M`` vertically."""
        return GraspReflex._within(tcp_pos_m, object_pos_m, HOLD_XY_M)

    @staticmethod
    def between(tcp_pos_m: np.ndarray, object_pos_m: np.ndarray) -> bool:
        """Whether the object is between the fingers: within ``BETWEEN_XY_M`` / ``BETWEEN_Z_M`` of the TCP."""
        return GraspReflex._within(tcp_pos_m, object_pos_m, BETWEEN_XY_M)

    @staticmethod
    def _within(tcp_pos_m: np.ndarray, object_pos_m: np.ndarray, xy_m: float) -> bool:
        d = np.asarray(object_pos_m, dtype=float) - np.asarray(tcp_pos_m, dtype=float)
        return bool(np.hypot(d[0], d[1]) < xy_m and abs(d[2]) < BETWEEN_Z_M)
