"""``CameraSensor``: measure the instructed ball from rendered camera frames, at a frame rate, with latency.

``SimWorld.measure_target`` returns the truth plus white noise at every tick. A camera does not: it
exposes a frame every ``1/rate_hz`` s, the measurement reaches the controller ``latency_ms`` later,
its error comes from finite pixels and depth noise and grows with distance, and it loses the ball
when the arm is in the way. This module simulates that from the MuJoCo scene itself::

    sensor = CameraSensor(world, CameraSensorConfig(rate_hz=30, latency_ms=50))
    sensor.reset(seed)
    for each control tick:
        for m in sensor.poll(world.state().t_s):   # measurements that have arrived by now
            if m.pos_m is not None: ...            # else: a missed detection (m.status says why)

How a frame is measured, and why
--------------------------------
Per capture and camera: ``mj_kinematics`` + ``mj_camlight`` (so geoms and cameras are where
``qpos``/``mocap_pos`` say now, a few microseconds), one ``update_scene``, then two renders of the
same scene by one ``mujoco.Renderer``: a depth image (metric z-depth along the optical axis) and a
segmentation image (per-pixel (objid, objtype)). The instructed ball's pixels are those whose geom
is the instructed mocap body's sphere.

- Segmentation rather than an RGB colour threshold: it is what a trained detector/segmenter
  approximates, it is exact about which pixels belong to which object (a colour threshold would
  misfire on shading, shadows and the anti-aliased rim, and needs tuning per colour), and it is
  free: MuJoCo's depth pass already renders with flat segment colours, so the second pass costs
  the same as an RGB pass. What this leaves out is detector error (false positives, mask
  erosion); pixel quantization, depth noise, latency and occlusion are modelled.
- Each ball pixel (u, v) with noisy depth d~ = d + N(0, (k d^2)^2) (``k = depth_noise_m_per_m2``,
  the quadratic growth of stereo/ToF depth error) is back-projected with the pinhole intrinsics
  (``f = (H/2) / tan(fovy/2)``, principal point at the image centre, pixel centres at +0.5) and the
  camera pose (``cam_xpos``, ``cam_xmat``; MuJoCo cameras look along -z, +y up) to a point on the
  ball's surface.
- The centre is a least-squares fit of a sphere of the known radius (the geom size) to those points
  (Gauss-Newton, a few 3x3 solves). Its start is the mean surface point pushed back along the
  viewing ray by 2/3 of the radius: the pixel-weighted mean depth of a visible hemisphere lies
  ``2R/3`` in front of the centre, so pushing by the full radius (the naive rule) is biased by
  ``R/3`` = 8 mm away from the camera; the fit also stays right when only part of the ball is
  visible (partial occlusion, image border), where the mean-point rule shifts.
- Several cameras: each one that sees the ball gives a centre; they are averaged weighted by their
  pixel counts (``camera`` then names the contributing cameras joined by ``+``).
- Fewer than ``min_pixels`` ball pixels in every camera: not detected, ``pos_m`` None. The sensor
  labels the miss from the truth (the simulator knows it; a real consumer only sees None):
  ``occluded`` when the ball centre projects inside some camera's image in front of it (the arm or
  the other ball hides it), ``too_small`` when it would cover fewer than ``min_pixels`` even
  unoccluded, else ``out_of_view``.

Timing: the first ``poll`` of an episode captures; after that a capture is due every ``1/rate_hz``
s on a fixed grid from that first time (not drifting with the poll period). A due capture renders
the world *now* and is stamped ``t_capture_s = t_s``; it is returned by the first poll with
``t_s >= t_capture_s + latency`` (to 1e-9 s). Polling slower than the frame rate skips the frames it
missed (the past cannot be rendered) rather than bunching them.

Measured (2-core shared CPU, EGL on Mesa software GL, 160x120, one camera; ``test_capture_cost_is_reported``
prints it): one capture (kinematics + depth render + segmentation render + back-projection and fit)
~3.0 ms (depth pass ~1.1 ms, segmentation pass ~1.3 ms incl. its id remap, the rest ~0.6 ms), so
~90 ms of wall time per simulated second at 30 Hz, i.e. ~10 % on top of a 1 kHz control loop;
linear in the rate and the number of cameras (a single pass reading colour and depth together would
save one render, ~1 ms, but needs the Renderer's private GL context; not worth it at this cost).

Accuracy (``front`` camera, 160x120, default depth noise, 20 frames each): mean centre error
~0.25 mm at 0.97 m, ~0.5-0.7 mm at 1.25 m, ~1.2 mm at 1.56 m (the far corner of the workspace), worst
frame 1.9 mm; without depth noise ~0.2 mm everywhere. Pixel quantization costs little because every
ball pixel's depth is sampled at its pixel centre on the true surface; the 0.2 mm floor is the
rendered sphere's tessellation lying slightly inside the true sphere. The naive mean + R rule is
~8 mm off; the fit's start alone (mean + 2R/3) ~1.8 mm. With three quarters of the ball hidden
(6 of ~22 pixels) the fit is still within ~4 mm (mean 1.6 mm). Not modelled: motion blur (a 30 Hz frame is a snapshot),
lens distortion, calibration error, detector mistakes.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass

os.environ.setdefault("MUJOCO_GL", "egl")  # headless rendering; must precede the mujoco import

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from scenarios.world.sim_world import SimWorld  # noqa: E402

#: time tolerance for "due" and "arrived" comparisons, s (poll times are sums of float ticks).
_TIME_EPS_S = 1e-9
#: Gauss-Newton iterations of the known-radius sphere fit.
_FIT_ITERS = 6


@dataclass(frozen=True)
class CameraSensorConfig:
    """How the camera sees.

    Attributes:
        rate_hz: frames per second.
        latency_ms: exposure + processing: the frame of the scene at t arrives at t + latency.
        cameras: scene cameras used; with several, their detections are fused (pixel-weighted mean).
        width_px, height_px: image size, px.
        min_pixels: fewer visible pixels of the ball than this = not detected.
        depth_noise_m_per_m2: per-pixel depth noise std = this * depth^2 (m, depth in m).
    """

    rate_hz: float = 30.0
    latency_ms: float = 50.0
    cameras: tuple[str, ...] = ("front",)
    width_px: int = 160
    height_px: int = 120
    min_pixels: int = 4
    depth_noise_m_per_m2: float = 0.001

    def __post_init__(self) -> None:
        if not (isinstance(self.rate_hz, (int, float)) and math.isfinite(self.rate_hz) and self.rate_hz > 0):
            raise ValueError(f"CameraSensorConfig.rate_hz must be a finite number of frames per second > 0, got {self.rate_hz!r}")
        if not (isinstance(self.latency_ms, (int, float)) and math.isfinite(self.latency_ms) and self.latency_ms >= 0):
            raise ValueError(f"CameraSensorConfig.latency_ms must be finite and >= 0 ms, got {self.latency_ms!r}")
        if isinstance(self.cameras, str) or not self.cameras:
            raise ValueError(f"CameraSensorConfig.cameras must be a non-empty tuple of camera names, got {self.cameras!r}")
        if len(set(self.cameras)) != len(self.cameras):
            raise ValueError(f"CameraSensorConfig.cameras names a camera twice: {self.cameras!r}")
        for name in ("width_px", "height_px"):
            value = getattr(self, name)
            if not (isinstance(value, (int, np.integer)) and value >= 8):
                raise ValueError(f"CameraSensorConfig.{name} must be an integer >= 8 px, got {value!r}")
        if not (isinstance(self.min_pixels, (int, np.integer)) and self.min_pixels >= 1):
            raise ValueError(f"CameraSensorConfig.min_pixels must be an integer >= 1, got {self.min_pixels!r}")
        if not (math.isfinite(self.depth_noise_m_per_m2) and self.depth_noise_m_per_m2 >= 0):
            raise ValueError(f"CameraSensorConfig.depth_noise_m_per_m2 must be finite and >= 0, got {self.depth_noise_m_per_m2!r}")


@dataclass(frozen=True)
class TargetMeasurement:
    """One frame's measurement of the instructed ball.

    Attributes:
        t_capture_s: sim time the frame was exposed (the scene state it shows).
        t_arrival_s: ``t_capture_s + latency``: when the consumer gets it.
        pos_m: (3,) ball centre, world frame, m; None when the ball was not detected.
        n_pixels: visible ball pixels (summed over the cameras).
        camera: the camera(s) that saw the ball (``+``-joined), or all configured ones when none did.
        status: ``detected``, ``occluded``, ``out_of_view`` or ``too_small`` (the latter three only
            with ``pos_m`` None; labelled from the simulator's truth).
    """

    t_capture_s: float
    t_arrival_s: float
    pos_m: np.ndarray | None
    n_pixels: int
    camera: str
    status: str = "detected"


class CameraSensor:
    """Camera measurements of ``world``'s instructed ball: rate, latency, pixel/depth error, occlusion.

    Args:
        world: the scene (its ``model``/``data`` are read, never stepped).
        config: rate, latency, cameras, image size, detection threshold, depth noise.
        seed: seed of the depth-noise generator (``reset(seed)`` draws a new one per episode).

    Raises:
        ValueError: an unknown or orthographic camera, or an image larger than the model's offscreen buffer.
    """

    def __init__(self, world: SimWorld, config: CameraSensorConfig = CameraSensorConfig(), seed: int = 0) -> None:
        if not isinstance(config, CameraSensorConfig):
            raise TypeError(f"config must be a CameraSensorConfig, got {type(config).__name__}")
        self.world = world
        self.config = config
        model = world.model
        scene_cams = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_CAMERA, i) for i in range(model.ncam)]
        self._cam_ids: list[int] = []
        for name in config.cameras:
            cam_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, str(name))
            if cam_id < 0:
                raise ValueError(f"unknown camera {name!r}; the scene has: {', '.join(scene_cams)}")
            if hasattr(model, "cam_orthographic") and int(model.cam_orthographic[cam_id]):
                raise ValueError(f"camera {name!r} is orthographic; CameraSensor needs a perspective camera")
            self._cam_ids.append(cam_id)
        buf_w, buf_h = int(model.vis.global_.offwidth), int(model.vis.global_.offheight)
        if config.width_px > buf_w or config.height_px > buf_h:
            raise ValueError(f"CameraSensorConfig image {config.width_px}x{config.height_px} px exceeds the scene's "
                             f"offscreen buffer {buf_w}x{buf_h} px")
        self._w, self._h = int(config.width_px), int(config.height_px)
        # focal length (px) of each camera; square pixels, so one f for both axes (fovy is vertical)
        self._f_px = [0.5 * self._h / math.tan(math.radians(float(model.cam_fovy[c])) / 2.0) for c in self._cam_ids]
        # pixel-centre offsets from the principal point, in units of f: x right, y up (row 0 = top)
        self._u_off = np.arange(self._w) + 0.5 - 0.5 * self._w
        self._v_off = 0.5 * self._h - (np.arange(self._h) + 0.5)
        self._near_m = float(model.vis.map.znear * model.stat.extent)
        # mocap id -> (sphere geom id) of each target body
        self._mocap_geom: dict[int, int] = {}
        for body in range(model.nbody):
            mocap = int(model.body_mocapid[body])
            if mocap >= 0 and model.body_geomnum[body] >= 1:
                self._mocap_geom[mocap] = int(model.body_geomadr[body])
        self._renderer: mujoco.Renderer | None = None
        self._latency_s = float(config.latency_ms) / 1000.0
        self._period_s = 1.0 / float(config.rate_hz)
        self.reset(seed)

    # ---------------------------------------------------------------- episode

    def reset(self, seed: int) -> None:
        """New episode: empty queue, capture schedule restarts at the next poll, new noise rng, zeroed stats."""
        self._rng = np.random.default_rng([int(seed), 0xCA3])
        self._queue: list[TargetMeasurement] = []
        self._t0: float | None = None
        self._next_k = 0
        self._last_poll_s = -math.inf
        self._stats = {"frames": 0, "detections": 0, "occluded": 0, "out_of_view": 0, "too_small": 0,
                       "render_ms_total": 0.0}

    @property
    def stats(self) -> dict:
        """Counts since ``reset``: frames, detections, occluded (centre in view, hidden), out_of_view,
        too_small, render_ms_total (wall time of all captures: kinematics + renders + back-projection)."""
        return dict(self._stats)

    # ---------------------------------------------------------------- polling

    def poll(self, t_s: float) -> list[TargetMeasurement]:
        """Capture if a frame is due at ``t_s`` (rendering the world's current state); return the
        measurements that have arrived by ``t_s``, in capture order (misses included, ``pos_m`` None)."""
        t = float(t_s)
        if not math.isfinite(t):
            raise ValueError(f"poll time t_s must be finite, got {t_s!r}")
        if t < self._last_poll_s - _TIME_EPS_S:
            raise ValueError(f"poll time went back from {self._last_poll_s!r} s to {t!r} s; call reset(seed) for a new episode")
        self._last_poll_s = t
        if self._t0 is None:
            self._t0 = t
        if t + _TIME_EPS_S >= self._t0 + self._next_k * self._period_s:
            self._queue.append(self.capture(t))
            # next due frame on the grid t0 + k / rate strictly after t (missed frames are skipped)
            self._next_k = int(math.floor((t - self._t0) / self._period_s + _TIME_EPS_S)) + 1
        n_ready = 0
        while n_ready < len(self._queue) and self._queue[n_ready].t_arrival_s <= t + _TIME_EPS_S:
            n_ready += 1
        ready, self._queue = self._queue[:n_ready], self._queue[n_ready:]
        return ready

    # ---------------------------------------------------------------- one frame

    def capture(self, t_s: float) -> TargetMeasurement:
        """Render the world now and measure the instructed ball (not queued; ``poll`` is the usual entry)."""
        t_start = time.perf_counter()
        world, model, data = self.world, self.world.model, self.world.data
        renderer = self._get_renderer()
        mujoco.mj_kinematics(model, data)  # geoms where qpos / mocap_pos put them now
        mujoco.mj_camlight(model, data)    # camera poses (cam_xpos / cam_xmat)
        mocap = int(world._mocap[world.target_index])
        geom = self._mocap_geom[mocap]
        radius = float(model.geom_size[geom, 0])
        truth = data.geom_xpos[geom].copy()

        centres, weights, seen_by = [], [], []
        n_total, in_view, too_small = 0, False, True
        for name, cam_id, f_px in zip(self.config.cameras, self._cam_ids, self._f_px):
            renderer.update_scene(data, camera=cam_id)
            renderer.enable_depth_rendering()
            depth = renderer.render()
            renderer.enable_segmentation_rendering()
            seg = renderer.render()
            renderer.disable_segmentation_rendering()
            cam_pos, cam_rot = data.cam_xpos[cam_id].copy(), data.cam_xmat[cam_id].reshape(3, 3).copy()

            mask = (seg[..., 0] == geom) & (seg[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM))
            rows, cols = np.nonzero(mask)
            n = int(rows.size)
            n_total += n
            # truth-based labels for the miss statistics
            p_cam = cam_rot.T @ (truth - cam_pos)
            z = -p_cam[2]
            if z > self._near_m:
                u = 0.5 * self._w + f_px * p_cam[0] / z
                v = 0.5 * self._h - f_px * p_cam[1] / z
                if 0.0 <= u < self._w and 0.0 <= v < self._h:
                    in_view = True
                    if math.pi * (f_px * radius / z) ** 2 >= self.config.min_pixels:
                        too_small = False
            if n < self.config.min_pixels:
                continue
            d = depth[rows, cols].astype(np.float64)
            if self.config.depth_noise_m_per_m2 > 0:
                d = d + self._rng.normal(0.0, 1.0, size=n) * (self.config.depth_noise_m_per_m2 * d * d)
            # back-project: camera frame (x right, y up, looking along -z), then world
            pts_cam = np.stack([self._u_off[cols] / f_px * d, self._v_off[rows] / f_px * d, -d], axis=1)
            pts = pts_cam @ cam_rot.T + cam_pos
            centres.append(_fit_sphere_centre(pts, radius, cam_pos))
            weights.append(float(n))
            seen_by.append(name)

        if centres:
            pos = np.average(np.stack(centres), axis=0, weights=np.asarray(weights))
            status, camera = "detected", "+".join(seen_by)
        else:
            pos, camera = None, "+".join(self.config.cameras)
            status = "occluded" if (in_view and not too_small) else ("too_small" if in_view else "out_of_view")
        stats = self._stats
        stats["frames"] += 1
        stats["detections" if status == "detected" else status] += 1
        stats["render_ms_total"] += (time.perf_counter() - t_start) * 1e3
        return TargetMeasurement(t_capture_s=float(t_s), t_arrival_s=float(t_s) + self._latency_s, pos_m=pos,
                                 n_pixels=n_total, camera=camera, status=status)

    # ---------------------------------------------------------------- resources

    def _get_renderer(self) -> mujoco.Renderer:
        if self._renderer is None:
            try:
                self._renderer = mujoco.Renderer(self.world.model, height=self._h, width=self._w)
            except Exception as exc:  # noqa: BLE001 - GL backends raise assorted errors
                raise RuntimeError(f"cannot create a MuJoCo renderer with MUJOCO_GL={os.environ.get('MUJOCO_GL')!r}: "
                                   f"{exc}. Set MUJOCO_GL (egl for headless) before mujoco is first imported") from exc
        return self._renderer

    def close(self) -> None:
        """Free the renderer (a later capture makes a new one)."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def __enter__(self) -> "CameraSensor":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _fit_sphere_centre(pts: np.ndarray, radius: float, cam_pos: np.ndarray) -> np.ndarray:
    """Centre of a sphere of known ``radius`` through surface points ``pts`` (n, 3) seen from ``cam_pos``.

    Start: the mean point pushed ``2R/3`` away from the camera (the mean depth of a visible hemisphere,
    sampled uniformly in the image, lies ``2R/3`` in front of the centre); then Gauss-Newton on
    ``|p_i - c| - R``. Falls back to the start when the fit is ill-posed or moves off by more than R.
    """
    mean = pts.mean(axis=0)
    ray = mean - cam_pos
    ray /= np.linalg.norm(ray)
    start = mean + (2.0 / 3.0) * radius * ray
    c = start.copy()
    for _ in range(_FIT_ITERS):
        diff = pts - c
        dist = np.linalg.norm(diff, axis=1)
        if np.any(dist < 1e-9):
            return start
        jac = -diff / dist[:, None]
        res = dist - radius
        jtj = jac.T @ jac
        if np.linalg.cond(jtj) > 1e8:
            return start
        step = np.linalg.solve(jtj, -jac.T @ res)
        c = c + step
        if np.linalg.norm(step) < 1e-7:
            break
    if not np.all(np.isfinite(c)) or np.linalg.norm(c - start) > radius:
        return start
    return c


def make_camera_sensor(world: SimWorld) -> CameraSensor:
    """The default camera sensor on ``world`` (for ``python -m mmact_ctrl.bench --sensor``)."""
    return CameraSensor(world, CameraSensorConfig())
