"""What every contact task's world shares: the robot's geoms and the external wrench they feel (in the robot state,
as libfranka's ``O_F_ext_hat_K``), the gripper moved at the Franka Hand's speed, and objects that are physical bodies
(nothing is placed kinematically, as reach's balls are)."""

from __future__ import annotations

import mujoco
import numpy as np

from scenarios.world.sim_world import SimWorld
from scenarios.world.tasks.contact import external_wrench, robot_geom_mask
from scenarios.world.tasks.grip import slew

#: the robot's bodies (their contacts make the external wrench)
ROBOT_BODY_PREFIX = "panda_"


class ContactWorld(SimWorld):
    """A ``SimWorld`` whose robot touches things (see the module). Subclasses set ``_gripper_cmd_m`` at reset."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        m = self.model
        robot = {b for b in range(m.nbody)
                 if (mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b) or "").startswith(ROBOT_BODY_PREFIX)}
        self._robot_geom = robot_geom_mask(m, robot)
        self._gripper_cmd_m = 0.0
        self._wrench_key: tuple | None = None  # the simulated state the cached wrench is of
        self._wrench = np.zeros(6)

    def measured_wrench(self) -> np.ndarray:
        """The wrench (6,) on the robot from its contacts, about the TCP, world frame (``external_wrench``), computed
        once per simulated state: the step's progress and the next tick's robot state read the same one (a copy each)."""
        self._refresh_kinematics()  # the TCP of this state (after a step it is the one the next robot state reads)
        d = self.data
        tcp = d.site_xpos[self._tcp]
        key = (d.time, d.qpos.tobytes(), d.qvel.tobytes(), tcp.tobytes())
        if self._wrench_key != key:
            self._wrench = external_wrench(self.model, d, self._robot_geom, tcp)
            self._wrench_key = key
        return self._wrench.copy()

    def gripper_command_m(self) -> float:
        """The gripper's command after its slew, m (the insert task starts squeezing the peg: 0)."""
        return self._gripper_cmd_m

    def step(self, tau_nm: np.ndarray, gripper_m: float) -> None:
        """One step; the gripper's command is slewed at ``grip.GRIPPER_SPEED_M_S`` (the Franka Hand's fingers move at
        most 0.1 m/s each: an unlimited servo slammed the pads onto a cube, a 37 N spike)."""
        self._gripper_cmd_m = slew(self._gripper_cmd_m, gripper_m, self.dt_s)
        super().step(tau_nm, self._gripper_cmd_m)

    def _place_objects(self, t_s: float, placements) -> None:
        """Nothing to place: the objects are physical (the base class moves reach's mocap balls)."""
