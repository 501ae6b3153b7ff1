"""The first stage: what is being executed. The watchdog's braking stop, the hold before the first chunk, or the
executor's sample of the executed chunk(s) plus its correction (``mmact_ctrl.executors``)."""

from __future__ import annotations

import numpy as np

from controllers.stop import StopTrajectory
from mmact_ctrl.control.samples import ReferenceSample
from mmact_ctrl.reference import ChunkReference

GRIPPER_OPEN_M = 0.08
#: a gripper command below this closes the gripper (half the Panda's 8 cm), m
GRIPPER_CLOSING_BELOW_M = 0.04


class ChunkStage:
    """The executed chunk's raw reference.

    Args:
        executor: how chunks are executed (its ``sample`` / ``offset``).
        stop_limits: ``(a_max m/s^2, j_max m/s^3, dw_max rad/s^2, ddw_max rad/s^3)`` of the watchdog's stop.
    """

    def __init__(self, executor, stop_limits: tuple[float, float, float, float], in_hand=lambda: False) -> None:
        self.executor = executor
        #: whether the object is between the fingers now (asked only while the chunk closes the gripper)
        self.in_hand = in_hand
        #: whether the robot touches the world now (the measured external force over a threshold; set by the
        #: controller each tick from the measured wrench, False where none is measured)
        self.touching = False
        self.stop_limits = stop_limits
        self.active: ChunkReference | None = None
        self.stop: StopTrajectory | None = None  # the watchdog's braking reference while no valid chunk covers now
        self.watchdog_stops = 0
        self.hold_pos_m, self.hold_rotvec_rad, self.hold_gripper_m = np.zeros(3), np.zeros(3), GRIPPER_OPEN_M
        # the grasp latch: (the chunk it was latched for, the correction held) while the gripper is commanded closed
        self._latch: tuple[ChunkReference | None, np.ndarray] | None = None

    def reset(self, pos_m: np.ndarray, rotvec_rad: np.ndarray, gripper_m: float = GRIPPER_OPEN_M) -> None:
        """A new episode: hold ``pos_m`` / ``rotvec_rad`` and the gripper's opening ``gripper_m`` (what it holds stays
        held) until the first chunk is active."""
        self.hold_pos_m, self.hold_rotvec_rad, self.hold_gripper_m = pos_m, rotvec_rad, float(gripper_m)
        self.active, self.stop, self.watchdog_stops = None, None, 0
        self._latch = None
        self.touching = False

    def activate(self, ref: ChunkReference, t_s: float) -> None:
        """``ref`` becomes the executed chunk at ``t_s``; a watchdog stop ends."""
        self.stop = None
        self.active = ref
        self.executor.activate(ref, t_s)

    def covered(self, t_s: float) -> bool:
        """Whether a chunk (or, before the first one, the initial hold) covers ``t_s``."""
        return self.active is None or t_s <= self.active.t_last_s  # the newest chunk ends last

    def brake(self, t_s: float, now: ReferenceSample) -> bool:
        """The watchdog: brake from the reference ``now`` at ``t_s`` to rest within the stop's limits and hold there
        until a chunk is activated. Returns whether a stop started (counted); a stop under way goes on."""
        if self.stop is not None:
            return False
        a, j, dw, ddw = self.stop_limits
        self.stop = StopTrajectory(t_s, np.concatenate([now.pos_m, now.rotvec_rad, [now.gripper_m]]),
                                   np.concatenate([now.vel_m_s, now.rotvec_rate_rad_s, [0.0]]), a, j, dw, ddw)
        self.watchdog_stops += 1
        return True

    def sample(self, t_s: float) -> ReferenceSample:
        """The raw reference at ``t_s``."""
        if self.stop is not None:
            action, rate = self.stop.sample(t_s)
            return ReferenceSample(action[:3], rate[:3], action[3:6], rate[3:6], float(action[6]))
        if self.active is None:
            return ReferenceSample(self.hold_pos_m, np.zeros(3), self.hold_rotvec_rad, np.zeros(3), self.hold_gripper_m)
        action, rate = self.executor.sample(t_s, self.active)
        if self.touching or (action[6] < GRIPPER_CLOSING_BELOW_M and self.in_hand()):  # latched (_latched)
            return ReferenceSample(action[:3] + self._latched(t_s), rate[:3], action[3:6], rate[3:6], float(action[6]))
        self._latch = None
        offset, offset_vel = self.executor.offset(t_s, self.active)
        return ReferenceSample(action[:3] + offset, rate[:3] + offset_vel, action[3:6], rate[3:6], float(action[6]))

    def _latched(self, t_s: float) -> np.ndarray:
        """The correction while the gripper is commanded closed with the object between the fingers: the one the
        executor gave when that began, held from then on (what the fingers hold moves with the hand, so its measured
        motion is no longer the world's and must not steer the hand); a chunk that is already closed when it becomes
        active was planned with the object in the hand and runs as it is. While the fingers close on nothing yet
        the correction goes on (the object may have turned away). Reach's chunks never close the gripper: nothing
        changes."""
        if self._latch is None:
            self._latch = (self.active, self.executor.offset(t_s, self.active)[0].copy())
        elif self._latch[0] is not self.active:
            self._latch = (self.active, np.zeros(3))
        return self._latch[1]

    def positions(self, times_s: np.ndarray) -> np.ndarray:
        """Positions (N, 3) of :meth:`sample` at many times at once (the MPC's preview), vectorized."""
        if self.stop is not None:
            return self.stop.sample_positions(times_s)
        if self.active is None:
            return np.tile(self.hold_pos_m, (len(times_s), 1))
        pos = self.executor.sample_positions(times_s, self.active)
        if self._latch is not None:  # holding: the latched correction (see sample)
            return pos + self._latch[1]
        offsets = self.executor.offsets_many(times_s, self.active)
        return pos if offsets is None else pos + offsets
