"""One episode recorded for a LeRobot dataset: the stack runs as ``moving_target`` runs it (any source, any mode, any
task), and at every frame time ``m / fps`` the run is paused between two ticks to take the frame: each camera's
view, the robot's state and the true target. The actions are read from the chunks the episode executed once it is
over (``mmact_ctrl.datasets.frame_actions``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from controllers.ik import solve_ik
from controllers.rotations import rot_from_rotvec
from mmact_ctrl.controller import HybridController
from mmact_ctrl.datasets.frame_actions import ChunkActivation, frame_actions
from mmact_ctrl.metrics import episode_metrics
from mmact_ctrl.runner import EpisodeRunner

#: the dataset's action spaces: the TCP pose the command asked for, or the same command in joints
ACTION_SPACES: tuple[str, ...] = ("tcp_pose", "joint_pos")


@dataclass(frozen=True)
class FrameSettings:
    """What is taken at each frame.

    Attributes:
        fps: frames per second of the dataset.
        cameras: the scene cameras recorded, in this order.
        image_size_px: side of the square frames, px.
        action_space: ``tcp_pose`` (``[x, y, z, rx, ry, rz, gripper]``: the command active at the frame, the pose
            for the next frame's time) or ``joint_pos`` (``[q1..q7, gripper]``: the same command in joints, the
            inverse kinematics of that pose started from the joints measured at the next frame, so that the arm's
            own redundancy is kept; with the gripper command).
    """

    fps: int = 10
    cameras: tuple[str, ...] = ("front", "side")
    image_size_px: int = 96
    action_space: str = "tcp_pose"

    def __post_init__(self) -> None:
        if self.action_space not in ACTION_SPACES:
            raise ValueError(f"--action-space must be one of {ACTION_SPACES}, got {self.action_space!r}")
        if not self.cameras:
            raise ValueError("--cameras must name at least one camera")

    def frame_tick(self, m: int, dt_s: float) -> int:
        """The control tick at which frame ``m`` is taken (the nearest one where ``m / fps`` falls between two)."""
        return int(round(m / (self.fps * dt_s)))


@dataclass(frozen=True)
class RecordedEpisode:
    """An episode as a dataset stores it (``N`` frames).

    Attributes:
        seed: the episode's seed (its scene, motion and noise).
        instruction: the language instruction (the dataset's task).
        images: camera -> ``(N, H, W, 3)`` uint8.
        state: ``(N, 8)`` joints (rad) and gripper opening (m).
        action: ``(N, 7)`` (tcp_pose) or ``(N, 8)`` (joint_pos).
        target_pos_m: ``(N, 3)`` the instructed object's true position (for analysis only).
        metrics: the episode's figures (``mmact_ctrl.metrics.episode_metrics``: success, final_error_m, ...).
    """

    seed: int
    instruction: str
    images: dict[str, np.ndarray]
    state: np.ndarray
    action: np.ndarray
    target_pos_m: np.ndarray
    metrics: dict = field(default_factory=dict)

    @property
    def length(self) -> int:
        return int(self.state.shape[0])


def record_episode(world, source, controller: HybridController, sensor, seed: int,
                   settings: FrameSettings) -> RecordedEpisode:
    """Run one episode of ``controller.config.duration_s`` and take its frames."""
    runner = EpisodeRunner(world, source, controller, seed, sensor=sensor, record=True)
    dt = runner.dt_s
    n_frames = int(np.ceil(runner.n_ticks * dt * settings.fps - 1e-9))
    images = {cam: [] for cam in settings.cameras}
    state, q, target = [], [], []
    hold = None
    for m in range(n_frames):
        runner.advance(settings.frame_tick(m, dt) * dt)
        if runner.done and runner.k < runner.n_ticks:  # aborted: the frames end where the run did
            break
        views = world.render_views(settings.cameras, settings.image_size_px)
        for cam, view in zip(settings.cameras, views):
            images[cam].append(view)
        s = world.state()
        if hold is None:  # the start pose, held until the first chunk is active
            pos, rotvec = controller.ee_pose(s.q_rad)
            hold = np.concatenate([pos, rotvec, [s.gripper_m]])
        state.append(np.concatenate([s.q_rad, [s.gripper_m]]))
        q.append(s.q_rad.copy())
        target.append(world.target_pos_m())
    runner.advance()
    log = runner.finish()
    n = len(state)
    q.append(world.state().q_rad.copy())  # where the last frame's command brought the joints
    chunks = [ChunkActivation(t_active_s=t, times_s=times, waypoints=w) for t, times, w in log.recording["chunks"]]
    tcp = frame_actions(chunks, hold, n, settings.fps)
    action = tcp if settings.action_space == "tcp_pose" else joint_actions(controller, tcp, np.asarray(q[1:n + 1]))
    metrics = episode_metrics(log)
    return RecordedEpisode(seed=int(seed), instruction=world.instruction,
                           images={cam: np.stack(v) for cam, v in images.items()},
                           state=np.asarray(state, dtype=np.float32), action=action.astype(np.float32),
                           target_pos_m=np.asarray(target, dtype=np.float32), metrics=metrics)


def joint_actions(controller: HybridController, tcp: np.ndarray, q_next_rad: np.ndarray) -> np.ndarray:
    """``joint_pos`` actions ``(N, 8)`` of the ``tcp_pose`` actions ``tcp`` ``(N, 7)``: each pose's inverse kinematics
    (``controllers.ik``) started from ``q_next_rad[m]`` (the joints the arm reached by the next frame: the solution
    is the one of the arm's own posture), and the gripper command. The joints the arm *reached* would not do: a
    replay commands them and the arm lags them once more (measured on the linear target: 16 of 20 replays within
    2 mm of the recorded final error, 6.6 mm at worst, where the command's own joints agree as the TCP poses do)."""
    model = controller.model
    out = np.empty((len(tcp), 8))
    for m in range(len(tcp)):
        rot = rot_from_rotvec(tcp[m, 3:6], controller.rot_nominal)
        out[m, :7], _ = solve_ik(model, tcp[m, :3], rot, q_next_rad[m])
    out[:, 7] = tcp[:, 6]
    return out
