"""``SimWorld``: the MuJoCo Panda scene with moving target(s), behind ``mmact_ctrl.world.World``.

Kinematic quantities (TCP position, rendered object positions) always refer to the current state:
after ``mj_step`` MuJoCo's ``xpos`` arrays lag one step behind ``qpos``, so ``state()`` and
``render()`` refresh them with ``mj_kinematics`` first (a few microseconds; the dynamics are not
touched, so runs stay deterministic).
"""

from __future__ import annotations

import math
import os

os.environ.setdefault("MUJOCO_GL", "egl")  # headless rendering; must precede the mujoco import

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from controllers.robot_description import ARM_JOINTS, HOME_Q_RAD  # noqa: E402
from mmact_ctrl.world import RobotState  # noqa: E402
from scenarios.world.panda_scene import (  # noqa: E402
    GRIPPER_MAX_M,
    TARGET_COLORS,
    SceneConfig,
    arm_actuator_ids,
    arm_dof_adr,
    arm_qpos_adr,
    build_panda_model,
    finger_qpos_adr,
    gripper_actuator_id,
    home_tcp_pos_m,
    target_mocap_ids,
    tcp_site_id,
)
from scenarios.world.targets import StaticMotion, TargetMotion, TargetSpec, make_motion  # noqa: E402

#: instruction templates; ``{color}`` is the colour of the instructed object.
INSTRUCTION_TEMPLATES: tuple[str, ...] = (
    "reach the {color} ball",
    "move the gripper to the {color} ball",
    "go to the {color} sphere",
    "touch the {color} ball",
)
#: minimum initial distance between two objects, m.
MIN_OBJECT_SEPARATION_M = 0.15


def instructed_index(instruction: str, n_objects: int) -> int:
    """Which object an instruction names (by its colour); a clear error when it names none or several."""
    words = instruction.lower().replace(",", " ").replace(".", " ").split()
    named = [i for i, color in enumerate(TARGET_COLORS[:n_objects]) if color in words]
    if len(named) != 1:
        colors = ", ".join(TARGET_COLORS[:n_objects])
        raise ValueError(f"instruction {instruction!r} must name exactly one object colour of this scene ({colors})")
    return named[0]


class SimWorld:
    """A simulated Panda on a table with one or two moving target spheres.

    Implements ``mmact_ctrl.world.World``. Extra attributes: ``model``/``data`` (MuJoCo),
    ``target_index`` (which object is instructed), ``n_objects``; extra methods:
    ``objects_pos_m()``, ``close()``.

    Args:
        scene: what the scene contains (step, armature, objects, cameras).
        target: how every object moves (each object draws its own motion).
        noise_m: std of the per-axis Gaussian noise of ``measure_target``, m.
        dropout: probability that ``measure_target`` returns None.
    """

    def __init__(self, scene: SceneConfig, target: TargetSpec, noise_m: float = 0.002, dropout: float = 0.0,
                 instruction: str | None = None) -> None:
        if not isinstance(scene, SceneConfig):
            raise TypeError(f"scene must be a SceneConfig, got {type(scene).__name__}")
        if not isinstance(target, TargetSpec):
            raise TypeError(f"target must be a TargetSpec, got {type(target).__name__}")
        if not (np.isfinite(noise_m) and noise_m >= 0):
            raise ValueError(f"noise_m must be finite and >= 0 m, got {noise_m!r}")
        if not (0.0 <= dropout < 1.0):
            raise ValueError(f"dropout must be in [0, 1), got {dropout!r}")
        self.fixed_instruction = instruction
        self.fixed_target_index = None if instruction is None else instructed_index(instruction, scene.n_objects)
        self.scene = scene
        self.target = target
        self.noise_m = float(noise_m)
        self.dropout = float(dropout)
        self.dt_s: float = scene.dt_s
        self.instruction: str = ""
        self.n_objects: int = scene.n_objects
        self.target_index: int = 0

        self.model = build_panda_model(scene)
        self.data = mujoco.MjData(self.model)
        self._arm_qpos = arm_qpos_adr(self.model)
        self._arm_dof = arm_dof_adr(self.model)
        # the arm's addresses are contiguous: slices read faster than index arrays at 1 kHz
        assert np.all(np.diff(self._arm_qpos) == 1) and np.all(np.diff(self._arm_dof) == 1)
        self._arm_q_slice = slice(int(self._arm_qpos[0]), int(self._arm_qpos[-1]) + 1)
        self._arm_v_slice = slice(int(self._arm_dof[0]), int(self._arm_dof[-1]) + 1)
        self._finger_qpos = finger_qpos_adr(self.model)
        self._finger_q0, self._finger_q1 = (int(i) for i in self._finger_qpos)  # state() reads them as scalars
        self._arm_act = arm_actuator_ids(self.model)
        self._grip_act = gripper_actuator_id(self.model)
        self._tcp = tcp_site_id(self.model)
        self._mocap = target_mocap_ids(self.model)
        self._motions: list[TargetMotion] = []
        self._moving: list[tuple[int, TargetMotion]] = []
        self._meas_rng: np.random.Generator | None = None
        self._renderer: mujoco.Renderer | None = None
        self._video_renderer: mujoco.Renderer | None = None
        self._views_renderer: mujoco.Renderer | None = None  # render_views's, at the size it was last asked for
        self._render_process = None  # scenarios.world.render_worker.RenderProcess, started by render_snapshot
        self._kinematics_stale = True

    # ---------------------------------------------------------------- episode

    def reset(self, seed: int, target_index: int | None = None) -> RobotState:
        """New episode: arm at ``HOME_Q_RAD`` at rest, fingers open (0.08 m), motions drawn from ``seed``.

        Object 0 moves as ``make_motion(target, seed)``; with two objects, object 1 gets an
        independent motion that starts at least ``MIN_OBJECT_SEPARATION_M`` away. ``target_index``
        picks the instructed object (None: random from ``seed``).
        """
        if target_index is not None and not (0 <= target_index < self.n_objects):
            raise ValueError(f"target_index must be in [0, {self.n_objects}) or None, got {target_index!r}")
        rng = np.random.default_rng([int(seed), 0])
        motions: list[TargetMotion] = [make_motion(self.target, int(seed))]
        if self.n_objects == 2:
            start0 = motions[0].pos_m(0.0)
            for _ in range(1000):
                other = make_motion(self.target, int(rng.integers(2**62)))
                if np.linalg.norm(other.pos_m(0.0) - start0) >= MIN_OBJECT_SEPARATION_M:
                    break
            else:  # pragma: no cover - the workspace is far larger than the separation
                raise RuntimeError(f"could not place two objects {MIN_OBJECT_SEPARATION_M} m apart (seed {seed})")
            motions.append(other)
        self._motions = motions
        # static objects are placed once here; step() moves only the others
        self._moving = [(int(i), mo) for i, mo in zip(self._mocap, motions) if not isinstance(mo, StaticMotion)]
        ids = [int(i) for i in self._mocap[: len(motions)]]  # objects_pos_m's rows: a slice where they are contiguous
        self._object_rows = slice(ids[0], ids[-1] + 1) if ids == list(range(ids[0], ids[-1] + 1)) else ids
        self._draw_instruction(rng, seed, target_index, INSTRUCTION_TEMPLATES)

        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)
        d.qpos[self._arm_qpos] = HOME_Q_RAD
        d.qpos[self._finger_qpos] = GRIPPER_MAX_M / 2.0
        d.ctrl[self._grip_act] = GRIPPER_MAX_M
        self._place_objects(0.0, zip(self._mocap, self._motions))
        mujoco.mj_forward(m, d)
        self._kinematics_stale = False
        return self.state()

    def set_arm_state(self, q_rad: np.ndarray, dq_rad_s: np.ndarray | None = None) -> RobotState:
        """Put the arm at ``q_rad`` (7,) with velocity ``dq_rad_s`` (default rest), e.g. for a random start."""
        self._require_reset()
        q = np.asarray(q_rad, dtype=np.float64)
        dq = np.zeros(7) if dq_rad_s is None else np.asarray(dq_rad_s, dtype=np.float64)
        if q.shape != (7,) or dq.shape != (7,) or not (np.all(np.isfinite(q)) and np.all(np.isfinite(dq))):
            raise ValueError(f"set_arm_state needs 7 finite joint positions and velocities, got {q!r}, {dq!r}")
        self.data.qpos[self._arm_qpos] = q
        self.data.qvel[self._arm_dof] = dq
        mujoco.mj_forward(self.model, self.data)
        self._kinematics_stale = False
        return self.state()

    def _require_reset(self) -> None:
        if not self._motions:
            raise RuntimeError("SimWorld: call reset(seed) before using the world")

    def _place_objects(self, t_s: float, placements) -> None:
        """Move the mocap bodies of ``placements`` ((mocap id, motion) pairs) to their positions at ``t_s``."""
        mocap_pos = self.data.mocap_pos
        for mocap_id, motion in placements:
            mocap_pos[mocap_id] = motion.pos_m(t_s)

    def _refresh_kinematics(self) -> None:
        if self._kinematics_stale:
            mujoco.mj_kinematics(self.model, self.data)
            self._kinematics_stale = False

    # ---------------------------------------------------------------- World protocol

    def step(self, tau_nm: np.ndarray, gripper_m: float) -> None:
        """Apply arm torques (7,) N*m (clipped to the effort limits by the actuators) and a gripper
        opening target (m, clipped to [0, 0.08]); advance one ``dt_s``; move the objects."""
        self._require_reset()
        tau = np.asarray(tau_nm, dtype=np.float64)
        if tau.shape != (len(ARM_JOINTS),):
            raise ValueError(f"tau_nm must have shape ({len(ARM_JOINTS)},), got {tau.shape}")
        if not np.isfinite(tau).all() or not math.isfinite(gripper_m):
            raise ValueError(f"non-finite command: tau_nm={tau.tolist()}, gripper_m={gripper_m!r}")
        d = self.data
        d.ctrl[self._arm_act] = tau
        d.ctrl[self._grip_act] = gripper_m
        mujoco.mj_step(self.model, d)
        self._place_objects(d.time, self._moving)
        self._kinematics_stale = True

    def _draw_instruction(self, rng: np.random.Generator, seed: int, target_index: int | None,
                          templates: tuple[str, ...]) -> None:
        """The instructed object (drawn from ``rng`` unless given or fixed), then the instruction's template (from
        ``rng``, in this order), named by the object's colour; the measurement noise's stream of ``seed``."""
        if target_index is None and self.fixed_target_index is not None:
            target_index = self.fixed_target_index
        self.target_index = int(rng.integers(self.n_objects)) if target_index is None else int(target_index)
        template = templates[int(rng.integers(len(templates)))]
        self.instruction = self.fixed_instruction or template.format(color=TARGET_COLORS[self.target_index])
        self._meas_rng = np.random.default_rng([int(seed), 1])

    def state(self) -> RobotState:
        """Current time, arm joints, gripper opening (sum of both fingers), TCP position and the measured external
        wrench (:meth:`measured_wrench`)."""
        self._require_reset()
        self._refresh_kinematics()
        d = self.data
        return RobotState(
            t_s=float(d.time),
            q_rad=d.qpos[self._arm_q_slice].copy(),
            dq_rad_s=d.qvel[self._arm_v_slice].copy(),
            gripper_m=float(d.qpos[self._finger_q0] + d.qpos[self._finger_q1]),  # a tenth of a fancy-indexed sum's time
            ee_pos_m=d.site_xpos[self._tcp].copy(),
            wrench_ext=self.measured_wrench(),
            gripper_cmd_m=self.gripper_command_m(),
        )

    def gripper_command_m(self) -> float | None:
        """The opening the gripper is driven to, m, or None: reach's gripper holds nothing (a contact task's world
        reports it: it may be squeezing an object from the reset on)."""
        return None

    def measured_wrench(self) -> np.ndarray | None:
        """The external wrench on the robot at the TCP (6,), or None: reach's balls touch nothing (a contact task's
        world measures it: ``scenarios.world.tasks.contact_world``)."""
        return None

    def target_pos_m(self) -> np.ndarray:
        """Ground-truth position (3,) of the instructed object now, m."""
        self._require_reset()
        return self.data.mocap_pos[self._mocap[self.target_index]].copy()  # placed at this time by step/reset

    def objects_pos_m(self) -> np.ndarray:
        """Positions (n_objects, 3) of all objects now, m (row ``target_index`` is the instructed one)."""
        self._require_reset()
        return self.data.mocap_pos[self._object_rows].copy()

    def measure_target(self) -> np.ndarray | None:
        """Truth + N(0, noise_m^2) per axis, or None with probability ``dropout``."""
        self._require_reset()
        missed = self._meas_rng.uniform() < self.dropout
        noise = self._meas_rng.normal(0.0, self.noise_m, size=3)
        return None if missed else self.target_pos_m() + noise

    def render(self) -> np.ndarray:
        """Frames ``(V, H, W, 3)`` uint8 of ``scene.camera_names``."""
        self._require_reset()
        if self._renderer is None:
            size = int(self.scene.image_size_px)
            try:
                self._renderer = mujoco.Renderer(self.model, height=size, width=size)
            except Exception as exc:  # noqa: BLE001 - GL backends raise assorted errors
                raise RuntimeError(f"cannot create a MuJoCo renderer with MUJOCO_GL={os.environ.get('MUJOCO_GL')!r}: "
                                   f"{exc}. MUJOCO_GL is read when mujoco is first imported: set it (egl for headless) or import "
                                   f"scenarios.world.sim_world before anything imports mujoco") from exc
        self._refresh_kinematics()
        mujoco.mj_camlight(self.model, self.data)
        frames = []
        for name in self.scene.camera_names:
            self._renderer.update_scene(self.data, camera=name)
            frames.append(self._renderer.render())
        return np.stack(frames)

    def render_video(self, size_px: int = 320, camera: str | None = None) -> np.ndarray:
        """One larger frame ``(H, W, 3)`` for videos (its own renderer, so the policy's frames keep their size)."""
        self._require_reset()
        size_px = min(int(size_px), 640)
        if self._video_renderer is None or self._video_renderer.height != min(size_px, 480):
            if self._video_renderer is not None:
                self._video_renderer.close()
            self._video_renderer = mujoco.Renderer(self.model, height=min(size_px, 480), width=size_px)
        self._refresh_kinematics()
        mujoco.mj_camlight(self.model, self.data)
        self._video_renderer.update_scene(self.data, camera=camera or self.scene.camera_names[0])
        return self._video_renderer.render()

    def render_views(self, cameras: tuple[str, ...], size_px: int) -> np.ndarray:
        """Frames ``(V, size_px, size_px, 3)`` uint8 of ``cameras`` (any of the scene's), from a renderer of their
        own: a dataset's views, whatever size and cameras the source driving the arm sees (:meth:`render`)."""
        self._require_reset()
        size = int(size_px)
        r = self._views_renderer
        if r is None or r.height != size:
            if r is not None:
                r.close()
            self._views_renderer = r = mujoco.Renderer(self.model, height=size, width=size)
        self._refresh_kinematics()
        mujoco.mj_camlight(self.model, self.data)
        frames = []
        for name in cameras:
            r.update_scene(self.data, camera=name)
            frames.append(r.render())
        return np.stack(frames)

    def target_jump_times_s(self) -> tuple[float, ...]:
        """Times (s) at which the instructed object teleports this episode."""
        self._require_reset()
        return tuple(self._motions[self.target_index].jump_times_s)

    def target_change_times_s(self) -> tuple[float, ...]:
        """Times (s) at which the instructed object's course changes abruptly this episode (jumps, flips, turns)."""
        self._require_reset()
        return tuple(self._motions[self.target_index].change_times_s)

    # ---------------------------------------------------------------- extras

    def home_tcp_pos_m(self) -> np.ndarray:
        """TCP position (3,) at ``HOME_Q_RAD`` with the gripper open, m."""
        return home_tcp_pos_m(self.model)

    def snapshot(self) -> dict:
        """What the cameras would see now, as copies (positions and mocap poses, ~10 us): for
        :meth:`render_snapshot`, off the 1 kHz path."""
        d = self.data
        return {"time": float(d.time), "qpos": d.qpos.copy(), "mocap_pos": d.mocap_pos.copy(),
                "mocap_quat": d.mocap_quat.copy()}

    def render_snapshot(self, snapshot: dict) -> np.ndarray:
        """The frames ``(V, H, W, 3)`` of :meth:`render` for a :meth:`snapshot`, rendered in a process of its own
        (``scenarios.world.render_worker``; MuJoCo's renderer holds the GIL); safe to call from another thread."""
        if self._render_process is None:
            from scenarios.world.render_worker import RenderProcess

            self._render_process = RenderProcess(self.scene)
        return self._render_process.render(snapshot)

    def close(self) -> None:
        """Free the renderers (the world stays usable; a later ``render`` makes a new one)."""
        for name in ("_renderer", "_video_renderer", "_views_renderer", "_render_process"):
            renderer = getattr(self, name)
            if renderer is not None:
                renderer.close()
                setattr(self, name, None)

    def __enter__(self) -> "SimWorld":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
