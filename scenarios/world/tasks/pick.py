"""``pick``: grasp the instructed cube while a conveyor carries it, and lift it.

Two cubes (4.5 cm, 0.1 kg, free joints) ride a conveyor (``pick_scene``) whose velocity follows the episode's motion
family at ``--speed``: the instructed cube's course is the motion's (the carrier's velocity is the motion's), the
other rides beside it. The 100 Hz target channel measures the instructed cube's position (with the same noise,
dropout and latency models as reach). Success: the instructed cube lifted at least 5 cm above the carrier and held
there for 1 s. Figures (``task_report``): time to grasp, gripper closings, drops, wrong object, the cube's speed at
the grasp, peak contact force.
"""

from __future__ import annotations

import mujoco
import numpy as np

from mmact_ctrl.control.force_guard import YIELD_M_S_PER_N
from scenarios.world.panda_scene import GRIPPER_MAX_M, SceneConfig
from scenarios.world.targets import JumpMotion, TargetSpec, make_motion, plane_workspace
from scenarios.world.tasks.contact_world import ContactWorld
from scenarios.world.tasks.pick_scene import (BELT_CENTRE_M, BELT_GEOM, BELT_HALF_M, CUBE_BODIES, CUBE_HALF_M,
                                              CUBE_REST_Z_M, add_pick_scene)
from scenarios.world.tasks.progress import PickProgress

#: success: lifted this far above the carrier, for this long
LIFT_M = 0.05
HOLD_S = 1.0
#: the open fingertips reach this far below the TCP, m (the finger geoms' lowest corner on the model)
FINGERTIP_BELOW_TCP_M = 0.0095
#: the TCP heights at which the fingertips pass the cubes' top (from 3 mm below it to 4 mm above), m: an open hand that
#: lands on a cube at the approach's 0.25 m/s peaked at 60-110 N (pick at 0.4 m/s, seeds 1001-1015)
DESCENT_BAND_M = (CUBE_REST_Z_M + CUBE_HALF_M + FINGERTIP_BELOW_TCP_M - 0.003,
                  CUBE_REST_Z_M + CUBE_HALF_M + FINGERTIP_BELOW_TCP_M + 0.004)
#: the TCP's grasp height, m: the expert's, 6 mm above a resting cube's centre (``pick_expert.GRASP_ABOVE_CENTRE_M``,
#: held equal by a test); with ``--close-at-grasp``, in a mode that reads the cube, the gripper starts closing only
#: with the TCP down there, and the descent stops there (README, Contact, point 14)
CLOSE_AT_GRASP_M = CUBE_REST_Z_M + 0.006
#: the gripper starts closing only with the TCP this close above its grasp height, m: the fingertips then 2 cm below
#: the cubes' top, the pads on the cube's sides
CLOSE_BELOW_M = CLOSE_AT_GRASP_M + 0.008
#: once the gripper starts closing (in a mode that reads the cube) the hand comes down no more than this under the
#: TCP's height then, m (``mmact_ctrl.control.closing_gate``). The one value tried: README, Contact, point 14
CLOSE_STOPS_DESCENT_M = 0.002
#: the open fingers' pads' inner faces are this far from the TCP along the fingers' axis, m (measured on the model)
OPEN_PAD_INNER_M = 0.0415
#: how far a cube's centre may be off the TCP along the fingers' axis for the open hand to go down over it, m: at 19 mm
#: a cube's side meets a pad. Measured on pick, hybrid, seeds 1000-1049: the grasps that succeed come down with the
#: cube 12-18 mm off the axis (the hand lags the cube), so a margin costs picks: 12 mm took 10 of 28 picks on the
#: reversal, 15 mm 5 of 46 at 0.2 m/s; 18.5 mm 1 of 46 (``mmact_ctrl.control.capture_gate``)
CAPTURE_TOL_M = OPEN_PAD_INNER_M - CUBE_HALF_M - 0.0005
#: a finger's half-width across the fingers' axis, m (the finger geoms on the model)
FINGER_HALF_WIDTH_M = 0.010
#: across the fingers' axis a cube whose centre is farther off the TCP than this clears the fingers, m (a cube's
#: half-width, a finger's half-width, 4.5 mm to spare)
CAPTURE_CLEAR_M = CUBE_HALF_M + FINGER_HALF_WIDTH_M + 0.0045
#: a closing that has gone on this long with the cube's estimate not between the fingers found nothing, s: the
#: fingers close at ``grip.GRIPPER_SPEED_M_S`` (0.2 m/s together), 0.175 s from open onto a 4.5 cm cube, and are past
#: its width by 0.25 s (``mmact_ctrl.control.empty_hand``). Measured on the tuning seeds (6000-6049, hybrid): at the
#: closing's first tick it took the grasps that start with the cube 2-3 cm off (linear 0.2 m/s: 45 -> 17 picks)
EMPTY_HAND_AFTER_S = 0.25
#: a cube whose centre is this far off the TCP across the fingers' axis is beside the fingers, not between the pads,
#: m: a closing whose measured opening can no longer take it in has missed at once (``mmact_ctrl.control.empty_hand``)
EMPTY_HAND_BESIDE_M = CUBE_HALF_M + FINGER_HALF_WIDTH_M
#: the speed at which a mode that does not read the cube passes the band, m/s: an open hand landing on a cube at the
#: TCP's 0.155 m/s peaked at 20 N stiff and 27 N with ``--compliance``, at 0.18 m/s at 27 and 34 N
#: (``docs/contact/landing_floor.txt``); 0.12 m/s keeps a margin for the tracking's lag
LANDING_SPEED_M_S = 0.12
#: the fingers closed on a 4.5 cm cube stop at its width; closer than this they hold nothing, m
EMPTY_GRIP_BELOW_M = 0.03
#: the distractor starts this far from the instructed cube, m
DISTRACTOR_GAP_M = (0.12, 0.2)
INSTRUCTION_TEMPLATES: tuple[str, ...] = (
    "pick up the {color} cube",
    "grasp the {color} cube and lift it",
    "lift the {color} block",
)


def pick_target_spec(kind: str, speed_m_s: float) -> TargetSpec:
    """The carrier's course: the motion family on the belt, at the cubes' resting height (a flat workspace: linear
    motions stay horizontal), inside the belt with a cube's margin."""
    base = TargetSpec(kind=kind, speed_m_s=speed_m_s)
    low, high = plane_workspace(base.workspace_low_m, base.workspace_high_m, CUBE_REST_Z_M, thickness_m=1e-6)
    return TargetSpec(kind=kind, speed_m_s=speed_m_s, workspace_low_m=low, workspace_high_m=high,
                      jump_dist_m=min(base.jump_dist_m, 0.15))


class PickWorld(ContactWorld):
    """The pick scene behind ``mmact_ctrl.world.World`` (see the module)."""

    def __init__(self, scene: SceneConfig, target: TargetSpec, noise_m: float = 0.002, dropout: float = 0.0,
                 instruction: str | None = None) -> None:
        super().__init__(scene, target, noise_m=noise_m, dropout=dropout, instruction=instruction)
        m = self.model
        self._cube_q = [int(m.jnt_qposadr[m.body_jntadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, b)]])
                        for b in CUBE_BODIES[: scene.n_objects]]
        self._cube_v = [int(m.jnt_dofadr[m.body_jntadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, b)]])
                        for b in CUBE_BODIES[: scene.n_objects]]
        self._belt = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, BELT_GEOM)
        #: body id -> cube index, and a scratch state for checking where a jump would put a cube
        self._cube_of_body = {mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, b): i
                              for i, b in enumerate(CUBE_BODIES[: scene.n_objects])}
        self._scratch = mujoco.MjData(m)
        self._motion = None
        self._gripper_cmd_m = GRIPPER_MAX_M
        self._jumps: list[tuple[float, np.ndarray]] = []
        # a cube's centre stays this far inside the belt's top when the carrier jumps it (the instructed cube's course
        # keeps to its box, well inside; the other rides 12-20 cm beside it)
        self._on_belt_low = np.array(BELT_CENTRE_M[:2]) - np.array(BELT_HALF_M[:2]) + CUBE_HALF_M
        self._on_belt_high = np.array(BELT_CENTRE_M[:2]) + np.array(BELT_HALF_M[:2]) - CUBE_HALF_M
        self.progress = PickProgress(LIFT_M, HOLD_S, CUBE_REST_Z_M, m.opt.timestep)

    # ---- the episode --------------------------------------------------------------------------------------------
    def reset(self, seed: int, target_index: int | None = None):
        """Arm at home, fingers open, the cubes on the belt: the instructed one at the course's start, the other
        beside it; the instruction names the instructed cube's colour."""
        rng = np.random.default_rng([int(seed), 0])
        motion = make_motion(self.target, int(seed))
        self._motion = motion
        self._motions = [motion] * self.n_objects  # both ride the one carrier
        self._draw_instruction(rng, seed, target_index, INSTRUCTION_TEMPLATES)
        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)
        d.qpos[self._arm_qpos] = self._home_q()
        d.qpos[self._finger_qpos] = GRIPPER_MAX_M / 2.0
        d.ctrl[self._grip_act] = GRIPPER_MAX_M
        start = motion.pos_m(0.0)
        for i, adr in enumerate(self._cube_q):
            pos = start if i == self.target_index else self._beside(start, rng)
            d.qpos[adr:adr + 3] = [pos[0], pos[1], CUBE_REST_Z_M]
            d.qpos[adr + 3:adr + 7] = [1.0, 0.0, 0.0, 0.0]
        self._jumps = self._jump_steps(motion)
        self._set_belt(0.0)
        mujoco.mj_forward(m, d)
        self._kinematics_stale = False
        self.progress.reset(self.target_index)
        self._gripper_cmd_m = GRIPPER_MAX_M
        return self.state()

    def _home_q(self) -> np.ndarray:
        from controllers.robot_description import HOME_Q_RAD

        return np.asarray(HOME_Q_RAD)

    def _beside(self, start: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """A start for the distractor ``DISTRACTOR_GAP_M`` from ``start``, inside the course's box."""
        low, high = self.target.low, self.target.high
        for _ in range(1000):
            angle, gap = rng.uniform(0.0, 2 * np.pi), rng.uniform(*DISTRACTOR_GAP_M)
            p = start + gap * np.array([np.cos(angle), np.sin(angle), 0.0])
            if np.all(p[:2] >= low[:2]) and np.all(p[:2] <= high[:2]):
                return p
        raise RuntimeError("no room for the second cube on the belt")  # pragma: no cover - the belt is large

    @staticmethod
    def _jump_steps(motion) -> list[tuple[float, np.ndarray]]:
        """(time, displacement) of each teleport of a jump motion: the carrier jumps with both cubes."""
        if not isinstance(motion, JumpMotion):
            return []
        return [(t, motion.pos_m(t + 1e-6) - motion.pos_m(t - 1e-6)) for t in motion.jump_times_s]

    def _set_belt(self, t_s: float) -> None:
        """The carrier's velocity at ``t_s``: the motion's (a jump motion rests between its teleports)."""
        h = self.dt_s
        v = (self._motion.pos_m(t_s + h) - self._motion.pos_m(t_s)) / h if not self._jumps else np.zeros(3)
        self.model.geom_surfacevel[self._belt, :2] = v[:2]

    # ---- the World protocol ---------------------------------------------------------------------------------
    def step(self, tau_nm: np.ndarray, gripper_m: float) -> None:
        super().step(tau_nm, gripper_m)
        d = self.data
        t = float(d.time)
        if self._jumps and t >= self._jumps[0][0]:
            _, delta = self._jumps.pop(0)
            self._jump_cubes(delta)
        self._set_belt(t)
        self.progress.update(t, self._cube_z(), gripper_m, float(np.linalg.norm(self.model.geom_surfacevel[self._belt, :2])),
                             float(np.linalg.norm(self.measured_wrench()[:3])))

    def _jump_cubes(self, delta_m: np.ndarray) -> None:
        """The carrier's teleport by ``delta_m``: each cube on it (not lifted in the hand) jumps with it, kept on the
        belt, unless its new place is taken by the robot or by a cube that stays (it stays where it is). A teleport
        into the fingers is no motion a carrier makes: it put a cube inside a closed hand at once (tuning seed 6007,
        jump 0.2 m/s: 30.7 N on the robot from an overlap that no controller could have avoided). The places are
        checked on a scratch copy of the state: the simulation's own contacts and forces stay those of its step."""
        d, scratch = self.data, self._scratch
        scratch.qpos[:] = d.qpos
        moving = set()
        for i, adr in enumerate(self._cube_q):
            if d.qpos[adr + 2] < CUBE_REST_Z_M + 0.005:  # on the carrier
                scratch.qpos[adr:adr + 2] = np.clip(d.qpos[adr:adr + 2] + delta_m[:2], self._on_belt_low,
                                                    self._on_belt_high)
                moving.add(i)
        while moving:  # a cube that stays may take the place of one that would land on it: check again
            blocked = self._overlapping_cubes(scratch) & moving
            if not blocked:
                break
            for i in blocked:
                adr = self._cube_q[i]
                scratch.qpos[adr:adr + 2] = d.qpos[adr:adr + 2]
            moving -= blocked
        for i in moving:
            adr = self._cube_q[i]
            d.qpos[adr:adr + 2] = scratch.qpos[adr:adr + 2]

    def _overlapping_cubes(self, state: mujoco.MjData) -> set[int]:
        """The cubes that overlap a robot geom or another cube in ``state`` (its positions; its contacts are
        recomputed)."""
        m = self.model
        mujoco.mj_kinematics(m, state)
        mujoco.mj_collision(m, state)
        out = set()
        for k in range(state.ncon):
            c = state.contact[k]
            if c.dist >= 0.0:
                continue
            g1, g2 = int(c.geom1), int(c.geom2)
            c1, c2 = self._cube_of_body.get(int(m.geom_bodyid[g1])), self._cube_of_body.get(int(m.geom_bodyid[g2]))
            if c1 is not None and (c2 is not None or self._robot_geom[g2]):
                out.add(c1)
            if c2 is not None and (c1 is not None or self._robot_geom[g1]):
                out.add(c2)
        return out

    def _cube_z(self) -> np.ndarray:
        return np.array([self.data.qpos[a + 2] for a in self._cube_q])

    def target_pos_m(self) -> np.ndarray:
        """The instructed cube's centre now, m."""
        adr = self._cube_q[self.target_index]
        return self.data.qpos[adr:adr + 3].copy()

    def objects_pos_m(self) -> np.ndarray:
        return np.array([self.data.qpos[a:a + 3] for a in self._cube_q])

    def snapshot(self) -> dict:
        d = self.data
        return {"time": float(d.time), "qpos": d.qpos.copy(), "mocap_pos": d.mocap_pos.copy(),
                "mocap_quat": d.mocap_quat.copy()}

    def task_report(self) -> dict:
        """The task's figures of the episode so far (``PickProgress``)."""
        return self.progress.report(self.target_index)


class PickTask:
    """The pick task (see the module)."""

    name = "pick"
    #: the lowest TCP reference, m: the grasp puts the TCP 6 mm above a cube's centre (3.05 cm); the fingertips reach
    #: about 1 cm below the TCP (``FINGERTIP_BELOW_TCP_M``), the belt's top is at 2 mm
    tcp_floor_m = 0.025
    contact = True
    #: the gripper's position gain, N/m: 1000 squeezes a 4.5 cm cube with about 22 N a finger (the Franka Hand holds
    #: up to 70 N; reach's 200 N/m, about 4.5 N, let a cube creep 5 mm in the pads through a 0.5 m/s swing)
    scene_overrides = {"gripper_kp": 1000.0}
    #: the axes the hybrid layer retargets a chunk on (``controllers.retarget.PULL_AXES``)
    pull_axes = "xy"
    #: the hand passes the cubes' top with its fingertips at a guarded move's speed (``StackConfig.descent_band_m``)
    descent_band_m = DESCENT_BAND_M
    #: the gripper starts closing only with the TCP within 8 mm of its grasp height (``StackConfig.close_below_m``)
    close_below_m = CLOSE_BELOW_M
    #: with ``--close-at-grasp``, in a mode that reads the cube: only with the TCP at its grasp height
    #: (``StackConfig.close_below_reading_m``), and the hand stops coming down once they start closing
    #: (``StackConfig.close_stops_descent_m``): a pad that slid down the cube's side wedged it against the belt
    #: (README, Contact, point 14; it costs picks, so it is a switch)
    close_below_reading_m = CLOSE_AT_GRASP_M
    close_stops_descent_m = CLOSE_STOPS_DESCENT_M
    #: the open hand goes down past the cubes' top only with the cube within this of the fingers' axis, in a mode
    #: that reads it (``StackConfig.capture_tol_m``)
    capture_tol_m = CAPTURE_TOL_M
    capture_clear_m = CAPTURE_CLEAR_M
    #: the MPC weighs height 4x (``MPCConfig.w_pos_z_scale``): with the axes alike, a plan catching up 40 cm sideways
    #: went 13 cm under its reference, down to the cubes, and swept the open fingers into one at 1.2 m/s (60 N);
    #: measured on pick at 0.4 m/s (seeds 1000-1019, hybrid): 4x kept success (11/20), 10x cost it (8/20)
    mpc_z_weight = 4.0
    #: the force guard yields 3x faster than by default (``StackConfig.guard_yield_m_s_per_n``): at the default an
    #: open finger that landed on a cube riding the belt was pressed on and dragged for 0.3 s, and the arm wound up past
    #: its joint velocity and position limits (tuning seeds 6000-6049, reversal 0.2 m/s, open loop: 262 ticks in one
    #: episode; none at 3x; in open loop and hybrid at 0.4 m/s, reversal and jump the picks and the episodes over
    #: 30 N unchanged, but for one hybrid pick more on the reversal)
    guard_yield_m_s_per_n = 3.0 * YIELD_M_S_PER_N
    #: a closing that found nothing: the closed hand rises where it is before it goes on, in a mode that reads the
    #: cube (``StackConfig.empty_hand_after_s``): the hybrid layer's correction swept a closed hand that had missed
    #: into the cube at the grasp height (tuning seeds 6000-6049, hybrid: episodes over 30 N, reversal 6 -> 5, jump
    #: 5 -> 2; picks unchanged on linear 0.2 and 0.4 m/s, reversal and jump)
    empty_hand_after_s = EMPTY_HAND_AFTER_S
    #: and at once when the fingers' measured opening can no longer take in a cube beside them
    #: (``StackConfig.empty_hand_beside_m``): see the README (Contact, point 13)
    empty_hand_beside_m = EMPTY_HAND_BESIDE_M
    #: a mode that does not read the cube passes the band no faster than a landing stays under the contact-force
    #: limit (``StackConfig.landing_speed_m_s``)
    landing_speed_m_s = LANDING_SPEED_M_S
    #: fingers closed past this found nothing: a mode that does not read the cube lifts the hand at once
    #: (``StackConfig.empty_grip_below_m``)
    empty_grip_below_m = EMPTY_GRIP_BELOW_M
    #: ``--compliance`` caps only the push into the measured contact (``StackConfig.compliance_caps_pressing``): with
    #: the magnitude capped, an open hand that hit the belt at 0.6 m/s could not lift itself out (20 N up against the
    #: belt dragging its fingers): 620 ticks over 30 N and 199 past the joint position limits (hybrid, 0.4 m/s, seed
    #: 1041); the tuning seeds' figures are in the README (Contact)
    compliance_caps_pressing = True
    world_class = PickWorld

    def add_to_scene(self, spec, config: SceneConfig) -> None:
        add_pick_scene(spec, config)

    def target_spec(self, kind: str, speed_m_s: float, plane_z_m: float = 0.0) -> TargetSpec:
        return pick_target_spec(kind, speed_m_s)

    def make_expert(self, bins: int, horizon: int, dt_s: float, lead: str, world=None):
        from scenarios.world.tasks.pick_expert import make_pick_expert

        return make_pick_expert(bins=bins, horizon=horizon, dt_s=dt_s, lead=lead, world=world)


__all__ = ["CUBE_HALF_M", "HOLD_S", "LIFT_M", "PickTask", "PickWorld", "pick_target_spec"]
