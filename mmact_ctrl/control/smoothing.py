"""The Ruckig stage: the reference smoothed within the smoother's jerk limits (``controllers.smoother``), or passed
through as it is when smoothing is off; either way turned into a rotation for the QP."""

from __future__ import annotations

import numpy as np

from controllers.rotations import rot_from_rotvec
from controllers.smoother import TaskSpaceSmoother
from mmact_ctrl.control.floor import FloorClamp
from mmact_ctrl.control.samples import ReferenceSample, SmoothedSample


class SmoothingStage:
    """Ruckig on the (floored) reference.

    Args:
        smoother: the task-space smoother (None: smoothing off, the reference passes through).
        floor: the floor stage (the smoother's decaying offset of a chunk switch may dip below the floor).
        rot_nominal: the nominal grasp rotation (3, 3) the rotation vectors are relative to.
    """

    def __init__(self, smoother: TaskSpaceSmoother | None, floor: FloorClamp, rot_nominal: np.ndarray) -> None:
        self.smoother = smoother
        self.floor = floor
        self.rot_nominal = rot_nominal
        self.smoothed_pos_m: np.ndarray | None = None  # the last smoothed position (the splice check reads it)

    @property
    def enabled(self) -> bool:
        return self.smoother is not None

    def reset(self, pos_m: np.ndarray, rotvec_rad: np.ndarray) -> None:
        self.smoothed_pos_m = None
        if self.smoother is not None:
            self.smoother.reset(pos_m, rotvec_rad)

    def __call__(self, ref: ReferenceSample) -> SmoothedSample:
        pos, vel, rotvec, rotvec_rate, gripper = ref
        if self.smoother is not None:
            pos, vel, acc, rotvec, ang_vel, ang_acc = self.smoother.step(pos, vel, rotvec, rotvec_rate)
            if pos[2] < self.floor.floor_m:
                pos, (vel, acc) = self.floor.raise_to_floor(pos, vel, acc)
            self.smoothed_pos_m = pos
        else:
            acc, ang_vel, ang_acc = np.zeros(3), rotvec_rate, np.zeros(3)
        return SmoothedSample(pos, vel, acc, rot_from_rotvec(rotvec, self.rot_nominal), ang_vel, ang_acc, gripper)
