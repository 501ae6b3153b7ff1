"""LIBERO's convention, as openpi's LIBERO client and robosuite's OSC_POSE controller define it.

Read from (commit or release in brackets):

- openpi ``examples/libero/main.py`` [Physical-Intelligence/openpi 15a9616a]: the observation keys
  ``observation/image`` (the agent-view camera) and ``observation/wrist_image``, each ``resize_with_pad`` to
  224 x 224 x 3 uint8 after ``[::-1, ::-1]`` ("rotate 180 degrees to match train preprocessing": robosuite renders
  come out upside down, the policy was trained on upright frames); ``observation/state`` = ``robot0_eef_pos`` (3)
  + ``_quat2axisangle(robot0_eef_quat)`` (3) + ``robot0_gripper_qpos`` (2); ``prompt``. Each reply row is one
  environment step (``env.step(action)`` per row, replanning every ``replan_steps`` = 5 rows).
- openpi ``src/openpi/training/config.py`` [15a9616a]: ``pi05_libero`` has ``action_horizon=10`` (``pi0_libero``
  keeps the model default of 50).
- robosuite 1.4.1 (the release LIBERO pins) ``controllers/config/osc_pose.json``: ``input_max`` 1, ``input_min``
  -1, ``output_max`` [0.05, 0.05, 0.05, 0.5, 0.5, 0.5], ``control_delta`` true; ``controllers/base_controller.py``
  ``scale_action``: clip to [-1, 1], then multiply by (output_max - output_min) / (input_max - input_min) = 0.05 m and
  0.5 rad per unit; ``utils/control_utils.py`` ``set_goal_orientation``: the rotation delta is an axis-angle applied
  on the left (world frame) of the current orientation; the goal is the *current* pose plus the step's delta, so the
  rows of a chunk are successive steps (``delta_from="previous"``). The gripper: -1 open, +1 closed.
- robosuite 1.4.1 ``robots/single_arm.py``: ``eef_quat`` is MuJoCo's ``xquat`` of the hand (continuous along the
  kinematic chain) and ``utils/transform_utils.py`` ``quat2axisangle`` does not fold the angle (``2 acos(w)`` in
  [0, 2 pi]): LIBERO's state rotation is continuous. Ours is the quaternion in the nominal grasp's hemisphere, turned
  the same way (``controllers.rotations.axis_angle_in_hemisphere``).
- LIBERO ``libero/libero/envs/bddl_base_domain.py`` [Lifelong-Robot-Learning/LIBERO 4f0dd188]: ``control_freq=20``:
  one step is 0.05 s.

Our frames come out upright (MuJoCo's renderer flips OpenGL's rows; a test holds it), so this preset sends them as
they are (``rotate_deg`` 0): what openpi's client sends after its rotation. The wrist key is a black frame: our scene
has no wrist camera. Positions are in our world frame (the robot base at the origin), not LIBERO's.
"""

from __future__ import annotations

from mmact_ctrl.sources.action_space import ActionSpace
from mmact_ctrl.sources.remote.mapping import ImageKey, KeyMapping, StateKey
from mmact_ctrl.sources.presets.convention import Convention

#: robosuite OSC_POSE (1.4.1): one unit of input is 0.05 m / 0.5 rad per step
OSC_POSE_SCALE: tuple[float, ...] = (0.05, 0.05, 0.05, 0.5, 0.5, 0.5)
#: LIBERO's control rate, Hz
CONTROL_HZ = 20.0

LIBERO = Convention(
    name="libero",
    mapping=KeyMapping(
        name="libero",
        images=(ImageKey("observation/image", "front", (224, 224)),
                ImageKey("observation/wrist_image", "wrist", (224, 224))),
        state=(StateKey("observation/state", ("ee_pos_m", "ee_axis_angle_rad", "gripper_fingers_m")),),
    ),
    action=ActionSpace(kind="tcp_delta", gripper="sign", dt_s=1.0 / CONTROL_HZ, delta_from="previous",
                       scale=OSC_POSE_SCALE, clip=(-1.0, 1.0)),
    horizon=10,
    state_rotation="axis-angle of the quaternion in the nominal grasp's hemisphere, angle in [0, 2 pi] (continuous, "
                   "as robosuite's quat2axisangle of MuJoCo's xquat)",
    sources=("openpi examples/libero/main.py @15a9616a", "openpi training/config.py pi05_libero @15a9616a",
             "robosuite 1.4.1 controllers/config/osc_pose.json, base_controller.scale_action, "
             "control_utils.set_goal_orientation", "LIBERO envs/bddl_base_domain.py control_freq=20 @4f0dd188"),
)
