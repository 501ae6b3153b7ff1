"""DROID's convention, as openpi's DROID client and DROID's own robot code define it.

Read from (commit in brackets):

- openpi ``examples/droid/main.py`` [Physical-Intelligence/openpi 15a9616a]: ``RobotEnv(action_space=
  "joint_velocity", gripper_action_space="position")``; the request keys ``observation/exterior_image_1_left`` (one
  external camera, ``resize_with_pad`` to 224 x 224), ``observation/wrist_image_left`` (224 x 224),
  ``observation/joint_position`` (7), ``observation/gripper_position`` (1), ``prompt``; the reply "[10, 8] of 10 joint
  velocity actions (7) + gripper position (1)"; each row is one step of ``DROID_CONTROL_FREQUENCY = 15`` Hz; every
  action is clipped to [-1, 1] (``np.clip(action, -1, 1)``) and the gripper binarised at 0.5.
- openpi ``src/openpi/training/config.py`` [15a9616a]: ``pi0_fast_droid`` ``action_horizon=10``, ``pi05_droid``
  ``action_horizon=15``.
- DROID ``droid/robot_ik/robot_ik_solver.py`` [droid-dataset/droid 1548722f]: ``max_joint_delta`` 0.2 rad,
  ``control_hz`` 15; ``joint_velocity_to_delta``: delta = velocity x 0.2 rad. ``droid/franka/robot.py``
  ``create_action_dict``: the joint target is the delta plus the *current* joint positions (rows are successive
  steps: ``delta_from="previous"``); the gripper position is clipped to [0, 1], 1 = closed.

A joint velocity of DROID is written here as a ``joint_delta`` of 0.2 rad per unit (the same thing per 1/15 s step).
The gripper is not binarised (the reaching scenes never close it). The wrist key is a black frame: our scene has no
wrist camera. openpi's full-DROID fine-tuning configs with ``DroidActionSpace.JOINT_POSITION`` answer absolute joint
positions instead: ``examples/presets/droid_joint_position.json`` defines that variant.
"""

from __future__ import annotations

from mmact_ctrl.sources.action_space import ActionSpace
from mmact_ctrl.sources.remote.mapping import ImageKey, KeyMapping, StateKey
from mmact_ctrl.sources.presets.convention import Convention

#: DROID's control rate, Hz
CONTROL_HZ = 15.0
#: DROID's RobotIKSolver.max_joint_delta: one unit of joint velocity is this many rad per step
MAX_JOINT_DELTA_RAD = 0.2

DROID = Convention(
    name="droid",
    mapping=KeyMapping(
        name="droid",
        images=(ImageKey("observation/exterior_image_1_left", "front", (224, 224)),
                ImageKey("observation/wrist_image_left", "wrist", (224, 224))),
        state=(StateKey("observation/joint_position", ("q_rad",)),
               StateKey("observation/gripper_position", ("gripper_close_1",))),
    ),
    action=ActionSpace(kind="joint_delta", gripper="close_1", dt_s=1.0 / CONTROL_HZ, delta_from="previous",
                       scale=MAX_JOINT_DELTA_RAD, clip=(-1.0, 1.0)),
    horizon=10,
    state_rotation="",
    sources=("openpi examples/droid/main.py @15a9616a", "openpi training/config.py pi0_fast_droid / pi05_droid @15a9616a",
             "DROID robot_ik/robot_ik_solver.py, franka/robot.py @1548722f"),
)
