"""``insert``: put the peg held in the fingers into the fixture's hole, ``--clearance-mm`` per side, 25 mm deep.

The peg starts in the fingers (held by friction: the pads and the gripper's squeeze, not welded), its bottom 6 cm
under the TCP; the fixture stands on the table, static or moving in the table's plane as the episode's motion family
at ``--speed`` (0.02-0.1 m/s is the study's range). The 100 Hz target channel measures the centre of the hole's mouth
(with the same noise, dropout and latency models as reach). Success: the peg's bottom at least 20 mm below the mouth,
inside the hole. Figures (``task_report``): time to seat, the depth reached, lateral error at the first contact with
the fixture, jams, peak contact force on the robot, the peg's slip in the fingers.
"""

from __future__ import annotations

import mujoco
import numpy as np

from mmact_ctrl.control.force_guard import YIELD_M_S_PER_N
from scenarios.world.panda_scene import SceneConfig
from scenarios.world.targets import JumpMotion, TargetSpec, make_motion, plane_workspace
from scenarios.world.tasks.contact_world import ContactWorld
from scenarios.world.tasks.insert_progress import InsertProgress
from scenarios.world.tasks.insert_scene import (FIXTURE_BODY, FIXTURE_START_M, HOLE_DEPTH_M, PEG_BELOW_TCP_M, PEG_BODY,
                                                PEG_LENGTH_M, PEG_SIDE_M, add_insert_scene, hole_half_m)

#: success: the peg's bottom this far below the hole's mouth, m
SEAT_M = 0.020
INSTRUCTION_TEMPLATES: tuple[str, ...] = (
    "insert the peg into the hole",
    "put the peg in the hole",
    "plug the peg into the fixture",
)
#: each finger's joint position closed on the peg at the reset (the squeeze settles at about 7.8 mm), m
FINGER_ON_PEG_M = PEG_SIDE_M / 2.0 - 0.0003
#: the fixture's course stays in this box (its centre on the table), m
FIXTURE_LOW_M, FIXTURE_HIGH_M = (0.4, -0.15), (0.6, 0.15)


def insert_target_spec(kind: str, speed_m_s: float) -> TargetSpec:
    """The fixture's course: the motion family in the table's plane inside ``FIXTURE_LOW_M .. FIXTURE_HIGH_M``."""
    base = TargetSpec(kind=kind, speed_m_s=speed_m_s)
    low, high = plane_workspace((*FIXTURE_LOW_M, 0.0), (*FIXTURE_HIGH_M, 0.0), FIXTURE_START_M[2], thickness_m=1e-6)
    return TargetSpec(kind=kind, speed_m_s=speed_m_s, workspace_low_m=low, workspace_high_m=high,
                      jump_dist_m=min(base.jump_dist_m, 0.1))


class InsertWorld(ContactWorld):
    """The insert scene behind ``mmact_ctrl.world.World`` (see the module)."""

    def __init__(self, scene: SceneConfig, target: TargetSpec, noise_m: float = 0.002, dropout: float = 0.0,
                 instruction: str | None = None) -> None:
        super().__init__(scene, target, noise_m=noise_m, dropout=dropout, instruction=instruction)
        m = self.model
        fixture = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, FIXTURE_BODY)
        self._fixture_mocap = int(m.body_mocapid[fixture])
        peg = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, PEG_BODY)
        self._peg_q = int(m.jnt_qposadr[m.body_jntadr[peg]])
        self._peg_geom = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, f"{PEG_BODY}_geom")
        self._fixture_geom = np.asarray(m.geom_bodyid == fixture)
        self.hole_half_m = hole_half_m(scene.clearance_mm)
        self.progress = InsertProgress(SEAT_M, self.hole_half_m, m.opt.timestep)
        self._motion = None
        self.n_objects = 1

    # ---- the episode --------------------------------------------------------------------------------------------
    def reset(self, seed: int, target_index: int | None = None):
        """Arm at home, the peg in the fingers (closed on it), the fixture at its course's start."""
        from controllers.robot_description import HOME_Q_RAD

        rng = np.random.default_rng([int(seed), 0])
        self._motion = make_motion(self.target, int(seed))
        self._motions = [self._motion]
        self._draw_instruction(rng, seed, 0, INSTRUCTION_TEMPLATES)  # one object: instructed, nothing drawn for it
        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)
        d.qpos[self._arm_qpos] = HOME_Q_RAD
        d.qpos[self._finger_qpos] = FINGER_ON_PEG_M  # the pads closed on the peg
        d.ctrl[self._grip_act] = 0.0
        self._gripper_cmd_m = 0.0
        d.mocap_pos[self._fixture_mocap] = self._motion.pos_m(0.0)
        mujoco.mj_forward(m, d)
        tcp = d.site_xpos[self._tcp].copy()
        d.qpos[self._peg_q:self._peg_q + 3] = tcp - np.array([0.0, 0.0, PEG_BELOW_TCP_M - PEG_LENGTH_M / 2.0])
        d.qpos[self._peg_q + 3:self._peg_q + 7] = [1.0, 0.0, 0.0, 0.0]
        mujoco.mj_forward(m, d)
        self._kinematics_stale = False
        self.progress.reset(self.peg_bottom_m() - tcp)
        return self.state()

    def step(self, tau_nm: np.ndarray, gripper_m: float) -> None:
        super().step(tau_nm, gripper_m)
        d = self.data
        d.mocap_pos[self._fixture_mocap] = self._motion.pos_m(float(d.time))
        mujoco.mj_kinematics(self.model, d)
        self._kinematics_stale = False
        bottom = self.peg_bottom_m()
        self.progress.update(float(d.time), bottom, bottom - d.site_xpos[self._tcp], self.target_pos_m(),
                             self._peg_touches_fixture(), float(np.linalg.norm(self.measured_wrench()[:3])))

    def peg_bottom_m(self) -> np.ndarray:
        """The centre of the peg's bottom face, m (world)."""
        d = self.data
        rot = np.empty(9)
        mujoco.mju_quat2Mat(rot, d.qpos[self._peg_q + 3:self._peg_q + 7])
        return d.qpos[self._peg_q:self._peg_q + 3] - rot.reshape(3, 3)[:, 2] * (PEG_LENGTH_M / 2.0)

    def _peg_touches_fixture(self) -> bool:
        d = self.data
        for i in range(d.ncon):
            c = d.contact[i]
            if (c.geom1 == self._peg_geom and self._fixture_geom[c.geom2]) or \
                    (c.geom2 == self._peg_geom and self._fixture_geom[c.geom1]):
                return True
        return False

    def target_pos_m(self) -> np.ndarray:
        """The centre of the hole's mouth now, m."""
        return self.data.mocap_pos[self._fixture_mocap] + np.array([0.0, 0.0, HOLE_DEPTH_M])

    def objects_pos_m(self) -> np.ndarray:
        return self.target_pos_m()[None, :]

    def target_jump_times_s(self) -> tuple[float, ...]:
        return tuple(self._motion.jump_times_s) if isinstance(self._motion, JumpMotion) else ()

    def target_change_times_s(self) -> tuple[float, ...]:
        return tuple(self._motion.change_times_s)

    def task_report(self) -> dict:
        """The task's figures of the episode so far (``InsertProgress``)."""
        return self.progress.report()


class InsertTask:
    """The insert task (see the module)."""

    name = "insert"
    #: the lowest TCP reference, m: seated, the peg's bottom (6 cm under the TCP) on the table
    tcp_floor_m = PEG_BELOW_TCP_M - 0.002
    #: the axes the hybrid layer retargets a chunk on: the hole moves in the table's plane; the TCP is 6 cm above the
    #: peg's bottom, so a chunk's aim is never the mouth itself
    pull_axes = "xy"
    contact = True
    descent_band_m = None
    close_below_m = None
    close_below_reading_m = None
    close_stops_descent_m = None
    capture_tol_m = None
    capture_clear_m = 0.0
    mpc_z_weight = 1.0
    guard_yield_m_s_per_n = YIELD_M_S_PER_N
    empty_hand_after_s = None
    empty_hand_beside_m = None
    landing_speed_m_s = None
    empty_grip_below_m = None
    compliance_caps_pressing = False
    #: the gripper squeezes the peg with about 40 N a finger (the Franka Hand: 70 N continuous); at 20 N the peg slid
    #: and turned in the fingers under the push (hybrid 40 of 50 seated, 11 of its 12 failures with 11-23 mm of slip)
    scene_overrides = {"gripper_kp": 2000.0, "n_objects": 1}
    world_class = InsertWorld

    def add_to_scene(self, spec, config: SceneConfig) -> None:
        add_insert_scene(spec, config)

    def target_spec(self, kind: str, speed_m_s: float, plane_z_m: float = 0.0) -> TargetSpec:
        return insert_target_spec(kind, speed_m_s)

    def make_expert(self, bins: int, horizon: int, dt_s: float, lead: str, world=None):
        from scenarios.world.tasks.insert_expert import make_insert_expert

        return make_insert_expert(bins=bins, horizon=horizon, dt_s=dt_s, lead=lead)
