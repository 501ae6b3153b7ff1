"""Is a frame the way a policy was trained to see it? The instructed ball must appear where the camera puts it.

:class:`UprightCheck` is the eye of a server that speaks a foreign convention with our scripted expert
(``python -m scenarios.serve --source expert --preset libero``): the expert reads the true target (privileged), so
it knows where the instructed ball must appear in an upright frame of a scene camera (the pinhole model of MuJoCo's
camera: ``f = (H / 2) / tan(fovy / 2)``, principal point at the centre, row 0 at the top), finds the ball's colour
in the frame it was sent, and refuses a frame where the ball sits where a frame turned by 180 degrees would put
it: a LIBERO-trained policy sees frames upright (openpi's client turns robosuite's raw renders by 180 degrees), so
a client that sends them turned is misreading the convention, and the server says so in its error text.

A frame where the ball is hidden (by the arm), or near the centre (where upright and turned agree), is not judged.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from scenarios.world.panda_scene import TARGET_COLORS, TARGET_RGBA
from scenarios.world.sim_world import instructed_index

#: pixels of the ball's colour needed to judge a frame
MIN_BALL_PX = 6
#: upright and turned positions closer than this (px, at 224 px) cannot be told apart
MIN_SEPARATION_PX = 24.0


def _ball_mask(frame: np.ndarray, rgba: tuple[float, ...]) -> np.ndarray:
    """Pixels whose dominant channel is the ball's (red or blue) by a clear margin."""
    f = frame.astype(np.int16)
    ch = int(np.argmax(rgba[:3]))
    others = [c for c in range(3) if c != ch]
    return (f[..., ch] > 90) & (f[..., ch] > 2 * f[..., others[0]] + 20) & (f[..., ch] > 2 * f[..., others[1]] + 20)


class UprightCheck:
    """Refuses frames of ``camera`` that are not upright.

    Args:
        model: the MuJoCo model of the scene (its camera placement and field of view).
        camera: the scene camera the image key shows.
        key: the observation key of its frame.
        n_objects: the scene's objects (the instruction names one of them by colour).
    """

    def __init__(self, model: mujoco.MjModel, camera: str, key: str, n_objects: int = 2) -> None:
        cam = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera)
        if cam < 0:
            raise ValueError(f"the scene has no camera {camera!r}")
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        self.pos_m = data.cam_xpos[cam].copy()
        self.rot = data.cam_xmat[cam].reshape(3, 3).copy()
        self.fovy_deg = float(model.cam_fovy[cam])
        self.camera, self.key, self.n_objects = camera, key, int(n_objects)
        self.judged = 0

    def pixel(self, point_m: np.ndarray, size_hw: tuple[int, int]) -> tuple[float, float]:
        """(column, row) of ``point_m`` in an upright frame of ``size_hw``."""
        h, w = size_hw
        p = self.rot.T @ (np.asarray(point_m, dtype=float) - self.pos_m)  # camera frame: x right, y up, looking at -z
        f = 0.5 * h / math.tan(math.radians(self.fovy_deg) / 2.0)
        return 0.5 * w + f * p[0] / -p[2], 0.5 * h - f * p[1] / -p[2]

    def __call__(self, obs: dict, observation) -> None:
        frame = np.asarray(obs.get(self.key))
        if frame.ndim != 3 or not np.all(np.isfinite(observation.target_pos_m)):
            return
        h, w = frame.shape[:2]
        rgba = TARGET_RGBA[instructed_index(observation.instruction, self.n_objects)]
        rows, cols = np.nonzero(_ball_mask(frame, rgba))
        if len(rows) < MIN_BALL_PX:
            return
        seen = np.array([cols.mean() + 0.5, rows.mean() + 0.5])
        up = np.array(self.pixel(observation.target_pos_m, (h, w)))
        turned = np.array([w, h]) - up
        if np.linalg.norm(up - turned) < MIN_SEPARATION_PX * h / 224.0:
            return
        self.judged += 1
        if np.linalg.norm(seen - turned) < np.linalg.norm(seen - up):
            colour = TARGET_COLORS[TARGET_RGBA.index(rgba)]
            raise ValueError(f"{self.key} is upside down: the {colour} ball is at pixel ({seen[0]:.0f}, {seen[1]:.0f}), "
                             f"where an upright frame has it at ({up[0]:.0f}, {up[1]:.0f}); a policy of this convention "
                             "was trained on upright frames")
