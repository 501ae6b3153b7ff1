"""What every contact task adds to the scene: contact settings that hold, and fingertip pads.

MuJoCo's modelling guide ("Preventing slip") asks for a grip force times friction well above the weight, condim 4 or 6,
and elliptic friction cones with a large ``impratio`` (solved by the Newton solver, our default). menagerie's Panda
(``fingertip_pad_collision_1``: half-size 0.0085 x 0.004 x 0.0085 m at 0 0.0055 0.0445 in the finger's frame) and
robosuite's gripper (fingertip boxes with condim 4, friction 2) put boxes on the fingertips; so do we, one per finger,
in the finger frames of the example-robot-data URDF (the closing axis is the frames' y; the right finger's joint
axis is -y, so its pad sits at -y). Objects collide with the robot, the table and each other (``OBJECT_*`` bits).
"""

from __future__ import annotations

import mujoco
import numpy as np

#: collision bits of the objects a task adds: they collide with the robot (1), the environment (2) and each other (4)
OBJECT_CONTYPE, OBJECT_CONAFFINITY = 4, 7
#: the robot's collision bits (``scenarios.world.panda_scene``)
ROBOT_CONTYPE, ROBOT_CONAFFINITY = 1, 2
#: the environment's (table, carrier, fixture)
ENV_CONTYPE, ENV_CONAFFINITY = 2, 1
#: fingertip pads: half-sizes and centre in each finger's frame (menagerie's values), m
PAD_HALF_M = (0.0085, 0.004, 0.0085)
PAD_CENTRE_M = (0.0, 0.0055, 0.0445)
#: pad friction (sliding, torsional, rolling): robosuite's fingertips use 2, menagerie's Panda 1
PAD_FRICTION = (1.5, 0.005, 0.0001)
#: the cone's ratio of frictional to normal impedance (MuJoCo: a large value stops slip)
IMPRATIO = 20.0
#: stiff fingertip contacts (``stiffen_fingers``): ``solref`` time constant and damping ratio, and the priority that
#: makes them the contact's
STIFF_FINGER_SOLREF = (0.004, 1.0)
STIFF_FINGER_PRIORITY = 1
FINGER_BODIES: tuple[tuple[str, float], ...] = (("panda_leftfinger", 1.0), ("panda_rightfinger", -1.0))


def add_contact_settings(spec: mujoco.MjSpec) -> None:
    """Elliptic friction cones with a large impratio (the Newton solver is MuJoCo's default)."""
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.option.impratio = IMPRATIO


def add_finger_pads(spec: mujoco.MjSpec) -> None:
    """One box pad on the inner face of each fingertip, condim 4 (torsional friction too). The fingers' own collision
    hulls still touch objects (measured: with the pads alone a held peg tilted more and insert succeeded less)."""
    for body_name, side in FINGER_BODIES:
        x, y, z = PAD_CENTRE_M
        spec.body(body_name).add_geom(
            name=f"{body_name}_pad", type=mujoco.mjtGeom.mjGEOM_BOX, size=list(PAD_HALF_M), pos=[x, side * y, z],
            condim=4, friction=list(PAD_FRICTION), solref=[0.01, 1.0], contype=ROBOT_CONTYPE,
            conaffinity=ROBOT_CONAFFINITY | OBJECT_CONTYPE, rgba=[0.15, 0.15, 0.15, 1.0])


def stiffen_fingers(spec: mujoco.MjSpec) -> None:
    """Every finger geom's contacts stiff (``STIFF_FINGER_SOLREF``, by priority; condim 4 and the geoms' own friction
    are what MuJoCo's max rule gave against condim-4 objects of friction 0.8-1 before). For a held object that must
    not move in the fingers (insert's peg): with MuJoCo's default 20 ms the 40 N squeeze sank the peg 2.8 mm into
    each finger and it slid 3 mm along them in a 1 s arm move (10 ms: 1.7 mm; 4 ms: 0.6 mm; 2 ms: 0.2 mm; the noslip
    solver, 3 iterations: 2.5 mm). 4 ms is twice MuJoCo's advised minimum (2 physics steps). Not for pick: the
    fingers that land on a cube that turned away hit it harder (reversal at 0.2 m/s, seeds 5000-5029: episodes over
    30 N 9 -> 13, peak 106 -> 283 N)."""
    for body_name, _ in FINGER_BODIES:
        for geom in spec.body(body_name).geoms:
            geom.solref, geom.priority, geom.condim = list(STIFF_FINGER_SOLREF), STIFF_FINGER_PRIORITY, 4


#: how fast the gripper's opening may change, m/s (the Franka Hand moves each finger at up to 0.1 m/s: the opening at
#: 0.2 m/s); an unlimited position servo slammed the pads onto a cube (a 37 N spike on the robot)
GRIPPER_SPEED_M_S = 0.2


def slew(current_m: float, target_m: float, dt_s: float) -> float:
    """The gripper command after one step of ``dt_s`` toward ``target_m`` at ``GRIPPER_SPEED_M_S``, m."""
    step = GRIPPER_SPEED_M_S * dt_s
    return float(np.clip(target_m, current_m - step, current_m + step))
