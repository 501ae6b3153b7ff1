"""The MuJoCo Panda scene, built from the same URDF that Pinocchio loads.

``build_panda_model(SceneConfig())`` returns a compiled ``mujoco.MjModel`` with:

- the Panda arm from ``example-robot-data``'s ``panda.urdf`` (mesh URIs rewritten to the collision
  ``.stl`` files, ``balanceinertia="false"`` so inertias stay those of the URDF; MuJoCo merges
  ``panda_link8``/``panda_hand`` into ``panda_link7``);
- physics step ``dt_s`` (1 ms), integrator ``implicitfast``, arm joint armature from the config;
- 7 torque ``motor`` actuators ``tau1..tau7`` (gear 1, ctrlrange = +- URDF effort limits, N*m);
- one position actuator ``gripper`` on the tendon ``gripper_opening`` = finger1 + finger2, so its
  command is the total opening in metres (0..0.08) and each finger gets half;
- a site ``tcp`` on ``panda_link7`` at the pose of Pinocchio's ``panda_hand_tcp`` frame;
- a table whose top is the plane z = 0 (robot base on it), a floor, lights;
- mocap target spheres ``target0`` (red) and, with ``n_objects=2``, ``target1`` (blue), no collision;
- fixed cameras ``front``, ``top``, ``side`` aimed at the workspace, and ``box_front``, ``box_side`` that frame
  exactly the box the balls move in (a few millimetres per pixel at 96 px).

Collision bits: robot geoms have contype=1/conaffinity=2, environment geoms contype=2/conaffinity=1,
so the robot collides with the table and floor but not with itself; targets have 0/0.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

os.environ.setdefault("MUJOCO_GL", "egl")  # headless rendering; must precede the mujoco import

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from controllers.robot_description import (  # noqa: E402
    ARM_JOINTS,
    FINGER_JOINTS,
    HOME_Q_RAD,
    TCP_FRAME,
    JointLimits,
)
from scenarios.world.urdf_import import fixed_frame_pose, panda_urdf_for_mujoco  # noqa: E402,F401

#: name of the link that holds the hand after MuJoCo merges fixed-joint links.
HAND_BODY = "panda_link7"
#: name of the tool-centre-point site.
TCP_SITE = "tcp"
#: names of the arm torque actuators, in ``ARM_JOINTS`` order.
ARM_ACTUATORS: tuple[str, ...] = tuple(f"tau{i}" for i in range(1, 8))
#: name of the gripper position actuator (command: total opening, m).
GRIPPER_ACTUATOR = "gripper"
#: name of the tendon finger1 + finger2 (length = total opening, m).
GRIPPER_TENDON = "gripper_opening"
#: largest gripper opening (both fingers at their 0.04 m limit), m.
GRIPPER_MAX_M = 0.08
#: cameras the scene provides.
AVAILABLE_CAMERAS: tuple[str, ...] = ("front", "top", "side", "box_front", "box_side")
#: target body names and colours, by object index.
TARGET_BODIES: tuple[str, ...] = ("target0", "target1")
TARGET_COLORS: tuple[str, ...] = ("red", "blue")
TARGET_RGBA: tuple[tuple[float, float, float, float], ...] = ((0.9, 0.1, 0.1, 1.0), (0.1, 0.25, 0.95, 1.0))
#: target sphere radius, m.
TARGET_RADIUS_M = 0.025

# collision bits
_ROBOT_CONTYPE, _ROBOT_CONAFFINITY = 1, 2
_ENV_CONTYPE, _ENV_CONAFFINITY = 2, 1

# camera placements: (position m, look-at point m, vertical field of view deg)
_CAMERAS: dict[str, tuple[tuple[float, float, float], tuple[float, float, float], float]] = {
    # in front of the robot and to its right, a little above the workspace
    "front": ((1.55, -0.5, 0.75), (0.45, 0.02, 0.3), 45.0),
    # straight above the workspace, image "up" = +x (away from the robot)
    "top": ((0.5, 0.0, 1.6), (0.5, 0.0, 0.0), 45.0),
    # on the robot's right (-y), level with the workspace
    "side": ((0.45, -1.45, 0.45), (0.45, 0.0, 0.3), 45.0),
    # framing the box the balls move in (``scenarios.targets.TargetSpec`` workspace, 0.35-0.65 x -0.3-0.3 x
    # 0.15-0.45 m): every ball of the box lies whole inside the 96 px frame with >= 3 px to spare, and no wider.
    # From +x, 25 deg above the box centre, 2.5 m away: y across the image, z (and some x) up; 7.3-8.5 mm/px.
    "box_front": ((2.7658, 0.0, 1.3565), (0.5, 0.0, 0.3), 17.2),
    # From -y, level with the box centre, 1.8 m away: x across, z up; 3.9-5.5 mm/px (near-far face).
    "box_side": ((0.5, -1.8, 0.3), (0.5, 0.0, 0.3), 14.2),
}
#: the cameras that frame the workspace box (the 3-D policy's views since issue 25)
BOX_CAMERAS: tuple[str, ...] = ("box_front", "box_side")


@dataclass(frozen=True)
class SceneConfig:
    """What the simulated scene contains.

    Attributes:
        dt_s: physics time step, s.
        armature_kgm2: reflected rotor inertia added to each of the 7 arm joints, kg*m^2
            (give the same values to Pinocchio's ``model.armature``).
        n_objects: number of target spheres (1 or 2).
        image_size_px: rendered image width = height, px.
        camera_names: cameras rendered by ``SimWorld.render`` (subset of ``AVAILABLE_CAMERAS``).
        gripper_kp: gripper position gain, N/m (force on each finger per metre of opening error).
        gripper_dampratio: damping ratio of the gripper position actuator (1 = critical).
        gripper_force_n: the most force the gripper's actuator applies on each finger, N (the Franka Hand grasps
            with a set force; 100 is past anything the position gain asks in reach).
        task: what the scene is for (``scenarios.world.tasks``): ``reach`` (mocap balls, no contact), ``pick``
            (cubes on a conveyor, fingertip pads), ``insert`` (a peg in the fingers, a fixture with a hole).
        clearance_mm: insert: the hole's clearance over the peg, per side, mm.
    """

    dt_s: float = 0.001
    armature_kgm2: tuple[float, ...] = (0.1,) * 7
    n_objects: int = 1
    image_size_px: int = 96
    camera_names: tuple[str, ...] = ("front",)
    gripper_kp: float = 200.0
    gripper_dampratio: float = 1.0
    gripper_force_n: float = 100.0
    task: str = "reach"
    clearance_mm: float = 1.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.dt_s) and self.dt_s > 0):
            raise ValueError(f"SceneConfig.dt_s must be a positive number of seconds, got {self.dt_s!r}")
        if len(self.armature_kgm2) != len(ARM_JOINTS):
            raise ValueError(f"SceneConfig.armature_kgm2 needs {len(ARM_JOINTS)} values, got {self.armature_kgm2!r}")
        if any(not np.isfinite(a) or a < 0 for a in self.armature_kgm2):
            raise ValueError(f"SceneConfig.armature_kgm2 must be finite and >= 0, got {self.armature_kgm2!r}")
        if self.n_objects not in (1, 2):
            raise ValueError(f"SceneConfig.n_objects must be 1 or 2, got {self.n_objects!r}")
        if int(self.image_size_px) != self.image_size_px or self.image_size_px < 8:
            raise ValueError(f"SceneConfig.image_size_px must be an integer >= 8, got {self.image_size_px!r}")
        if not self.camera_names:
            raise ValueError("SceneConfig.camera_names must name at least one camera")
        for name in self.camera_names:
            if name not in AVAILABLE_CAMERAS:
                raise ValueError(f"SceneConfig.camera_names: unknown camera {name!r}; choose from {AVAILABLE_CAMERAS}")
        if not (np.isfinite(self.gripper_kp) and self.gripper_kp > 0):
            raise ValueError(f"SceneConfig.gripper_kp must be > 0 N/m, got {self.gripper_kp!r}")
        if not (np.isfinite(self.gripper_force_n) and self.gripper_force_n > 0):
            raise ValueError(f"SceneConfig.gripper_force_n must be > 0 N, got {self.gripper_force_n!r}")
        if not (np.isfinite(self.gripper_dampratio) and self.gripper_dampratio >= 0):
            raise ValueError(f"SceneConfig.gripper_dampratio must be >= 0, got {self.gripper_dampratio!r}")
        if not (np.isfinite(self.clearance_mm) and self.clearance_mm > 0):
            raise ValueError(f"SceneConfig.clearance_mm must be > 0 mm, got {self.clearance_mm!r}")


def _look_at_quat(pos_m: np.ndarray, target_m: np.ndarray) -> np.ndarray:
    """Camera orientation (wxyz) looking from ``pos_m`` at ``target_m`` with world +z up.

    MuJoCo cameras look along their -z axis with +y up in the image.
    """
    forward = np.asarray(target_m, float) - np.asarray(pos_m, float)
    forward /= np.linalg.norm(forward)
    up_world = np.array([0.0, 0.0, 1.0]) if abs(forward[2]) < 0.99 else np.array([1.0, 0.0, 0.0])
    x_axis = np.cross(forward, up_world)
    x_axis /= np.linalg.norm(x_axis)
    y_axis = np.cross(x_axis, forward)
    mat = np.column_stack([x_axis, y_axis, -forward])
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, mat.reshape(-1).copy())
    return quat


def build_panda_spec(config: SceneConfig = SceneConfig()) -> mujoco.MjSpec:
    """The scene as an editable ``mujoco.MjSpec`` (compile it with ``spec.compile()``)."""
    spec = mujoco.MjSpec.from_string(panda_urdf_for_mujoco())
    spec.compile()  # resolves the URDF import (fixed links merged into their parents)
    # the URDF visuals are gone now; keep what we add below (mocap bodies, non-colliding geoms)
    spec.compiler.fusestatic = False
    spec.compiler.discardvisual = False
    spec.modelname = "panda_scene"
    _physics_and_rendering(spec, config)
    _arm_actuators(spec, config)
    _gripper(spec, config)
    _robot_looks(spec)
    _environment(spec.worldbody, spec)
    _targets_and_cameras(spec.worldbody, config)
    if config.task != "reach":  # the contact tasks' bodies, pads and contact settings (scenarios.world.tasks)
        from scenarios.world.tasks.registry import task_by_name

        task_by_name(config.task).add_to_scene(spec, config)
    return spec


def _physics_and_rendering(spec: mujoco.MjSpec, config: SceneConfig) -> None:
    """The time step and integrator, the offscreen buffer and its rendering quality."""
    spec.option.timestep = config.dt_s
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.visual.global_.offwidth = max(640, int(config.image_size_px))
    spec.visual.global_.offheight = max(480, int(config.image_size_px))
    # software GL (Mesa llvmpipe) cost: 4096 px shadows + 4x MSAA ~100 ms/frame, this ~13 ms/frame
    spec.visual.quality.shadowsize = 1024
    spec.visual.quality.offsamples = 0
    spec.visual.headlight.ambient = [0.35, 0.35, 0.35]
    spec.visual.headlight.diffuse = [0.5, 0.5, 0.5]



def _arm_actuators(spec: mujoco.MjSpec, config: SceneConfig) -> None:
    """One torque motor per arm joint, limited to the Panda's effort; the armature the controller's model has."""
    limits = JointLimits()
    for name, armature, tau_max in zip(ARM_JOINTS, config.armature_kgm2, limits.tau_max_nm):
        spec.joint(name).armature = float(armature)
        act = spec.add_actuator(name=f"tau{ARM_JOINTS.index(name) + 1}", target=name)
        act.trntype = mujoco.mjtTrn.mjTRN_JOINT
        act.set_to_motor()
        act.gear[0] = 1.0
        act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.ctrlrange = [-tau_max, tau_max]



def _gripper(spec: mujoco.MjSpec, config: SceneConfig) -> None:
    """The gripper: a tendon over both fingers (the total opening) with one position actuator on it."""
    tendon = spec.add_tendon(name=GRIPPER_TENDON)
    for finger in FINGER_JOINTS:
        tendon.wrap_joint(finger, 1.0)
    grip = spec.add_actuator(name=GRIPPER_ACTUATOR, target=GRIPPER_TENDON)
    grip.trntype = mujoco.mjtTrn.mjTRN_TENDON
    grip.set_to_position(kp=float(config.gripper_kp), dampratio=float(config.gripper_dampratio))
    grip.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
    grip.ctrlrange = [0.0, GRIPPER_MAX_M]
    grip.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
    grip.forcerange = [-float(config.gripper_force_n), float(config.gripper_force_n)]



def _robot_looks(spec: mujoco.MjSpec) -> None:
    """The robot's collision bits and colours, and the TCP site."""
    for geom in spec.geoms:
        geom.contype, geom.conaffinity = _ROBOT_CONTYPE, _ROBOT_CONAFFINITY
        geom.rgba = [0.92, 0.92, 0.92, 1.0]
    for body_name in ("panda_leftfinger", "panda_rightfinger"):
        for geom in spec.body(body_name).geoms:
            geom.rgba = [0.2, 0.2, 0.2, 1.0]

    # TCP site on the link that holds the hand, at the URDF pose of panda_hand_tcp in panda_link7
    tcp_pos, tcp_quat = fixed_frame_pose(HAND_BODY, TCP_FRAME)
    spec.body(HAND_BODY).add_site(name=TCP_SITE, pos=tcp_pos, quat=tcp_quat, size=[0.006, 0, 0], rgba=[0.1, 0.8, 0.1, 0.6], group=3)



def _environment(world, spec: mujoco.MjSpec) -> None:
    """Sky, floor, the table (its top is the plane z = 0) and the lights."""
    # environment
    spec.add_texture(name="sky", type=mujoco.mjtTexture.mjTEXTURE_SKYBOX, builtin=mujoco.mjtBuiltin.mjBUILTIN_GRADIENT,
                     rgb1=[0.55, 0.62, 0.7], rgb2=[0.12, 0.14, 0.18], width=128, height=768)
    spec.add_texture(name="floor_tex", type=mujoco.mjtTexture.mjTEXTURE_2D, builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER,
                     rgb1=[0.25, 0.27, 0.3], rgb2=[0.35, 0.37, 0.4], width=256, height=256)
    floor_mat = spec.add_material(name="floor_mat", texrepeat=[6, 6], reflectance=0.05)
    floor_mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "floor_tex"
    world.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, pos=[0, 0, -0.75], size=[3, 3, 0.05],
                   material="floor_mat", contype=_ENV_CONTYPE, conaffinity=_ENV_CONAFFINITY)
    # table top: the plane z = 0, x in [-0.3, 1.0], y in [-0.6, 0.6]
    world.add_geom(name="table", type=mujoco.mjtGeom.mjGEOM_BOX, pos=[0.35, 0.0, -0.02], size=[0.65, 0.6, 0.02],
                   rgba=[0.55, 0.42, 0.3, 1.0], contype=_ENV_CONTYPE, conaffinity=_ENV_CONAFFINITY)
    for i, (x, y) in enumerate([(-0.25, -0.55), (-0.25, 0.55), (0.95, -0.55), (0.95, 0.55)]):
        world.add_geom(name=f"table_leg{i}", type=mujoco.mjtGeom.mjGEOM_BOX, pos=[x, y, -0.395], size=[0.03, 0.03, 0.355],
                       rgba=[0.4, 0.3, 0.22, 1.0], contype=0, conaffinity=0)
    world.add_light(name="key", pos=[0.5, -0.5, 2.0], dir=[-0.1, 0.3, -1.0], diffuse=[0.6, 0.6, 0.6], castshadow=True)
    world.add_light(name="fill", pos=[1.5, 1.0, 1.5], dir=[-1.0, -0.7, -0.8], diffuse=[0.3, 0.3, 0.3], castshadow=False)



def _targets_and_cameras(world, config: SceneConfig) -> None:
    """The mocap target spheres (no collision) and the cameras."""
    # mocap targets (no collision): the reach task's balls
    for i in range(config.n_objects if config.task == "reach" else 0):
        body = world.add_body(name=TARGET_BODIES[i], mocap=True, pos=[0.5, -0.1 + 0.2 * i, 0.3])
        body.add_geom(name=f"{TARGET_BODIES[i]}_geom", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[TARGET_RADIUS_M, 0, 0],
                      rgba=list(TARGET_RGBA[i]), contype=0, conaffinity=0)

    # cameras
    for name, (pos, look_at, fovy) in _CAMERAS.items():
        world.add_camera(name=name, pos=list(pos), quat=_look_at_quat(np.array(pos), np.array(look_at)), fovy=fovy)


def build_panda_model(config: SceneConfig = SceneConfig()) -> mujoco.MjModel:
    """Compile the scene of ``config`` into a ``mujoco.MjModel``."""
    return build_panda_spec(config).compile()


# --------------------------------------------------------------------------------------------
# indices


def _ids(model: mujoco.MjModel, obj: mujoco.mjtObj, names: tuple[str, ...]) -> np.ndarray:
    ids = []
    for name in names:
        i = mujoco.mj_name2id(model, obj, name)
        if i < 0:
            raise KeyError(f"model has no {obj.name} named {name!r}")
        ids.append(i)
    return np.asarray(ids, dtype=np.int64)


def arm_qpos_adr(model: mujoco.MjModel) -> np.ndarray:
    """Indices into ``data.qpos`` of the 7 arm joints, in ``ARM_JOINTS`` order."""
    return model.jnt_qposadr[_ids(model, mujoco.mjtObj.mjOBJ_JOINT, ARM_JOINTS)].astype(np.int64)


def arm_dof_adr(model: mujoco.MjModel) -> np.ndarray:
    """Indices into ``data.qvel`` / ``qfrc_*`` / mass-matrix rows of the 7 arm joints."""
    return model.jnt_dofadr[_ids(model, mujoco.mjtObj.mjOBJ_JOINT, ARM_JOINTS)].astype(np.int64)


def finger_qpos_adr(model: mujoco.MjModel) -> np.ndarray:
    """Indices into ``data.qpos`` of the 2 finger joints (each 0..0.04 m)."""
    return model.jnt_qposadr[_ids(model, mujoco.mjtObj.mjOBJ_JOINT, FINGER_JOINTS)].astype(np.int64)


def arm_actuator_ids(model: mujoco.MjModel) -> np.ndarray:
    """Indices into ``data.ctrl`` of the 7 arm torque actuators."""
    return _ids(model, mujoco.mjtObj.mjOBJ_ACTUATOR, ARM_ACTUATORS)


def gripper_actuator_id(model: mujoco.MjModel) -> int:
    """Index into ``data.ctrl`` of the gripper actuator (command: total opening, m)."""
    return int(_ids(model, mujoco.mjtObj.mjOBJ_ACTUATOR, (GRIPPER_ACTUATOR,))[0])


def tcp_site_id(model: mujoco.MjModel) -> int:
    """Index of the ``tcp`` site (``data.site_xpos[i]``, ``data.site_xmat[i]``)."""
    return int(_ids(model, mujoco.mjtObj.mjOBJ_SITE, (TCP_SITE,))[0])


def target_mocap_ids(model: mujoco.MjModel) -> np.ndarray:
    """Indices into ``data.mocap_pos`` of the target spheres, by object index."""
    n = sum(mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name) >= 0 for name in TARGET_BODIES)
    body_ids = _ids(model, mujoco.mjtObj.mjOBJ_BODY, TARGET_BODIES[:n])
    return model.body_mocapid[body_ids].astype(np.int64)


def home_tcp_pos_m(model: mujoco.MjModel | None = None, gripper_m: float = GRIPPER_MAX_M) -> np.ndarray:
    """World position (m) of the ``tcp`` site with the arm at ``HOME_Q_RAD``."""
    model = build_panda_model() if model is None else model
    data = mujoco.MjData(model)
    data.qpos[arm_qpos_adr(model)] = HOME_Q_RAD
    data.qpos[finger_qpos_adr(model)] = gripper_m / 2.0
    mujoco.mj_kinematics(model, data)
    return data.site_xpos[tcp_site_id(model)].copy()
