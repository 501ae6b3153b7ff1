"""The pick task's scene: a conveyor on the table and two cubes on it, the colour naming the instructed one.

The carrier is a conveyor surface (MuJoCo >= 3.11 ``geom surfacevel``, set at run time): a static box whose contacts
move what rests on it at the belt's velocity, which the world sets every step to the velocity of the episode's motion
family (``scenarios.world.targets``). Chosen over a tray welded to a mocap body because a conveyor has no body that
can be bumped, tipped or lifted with the cube, its velocity is set exactly, and a contact with a mocap body lacks the
relative-velocity term (MuJoCo's docs); FACTS.md measured a cube riding a 0.3 m/s belt at 0.300 m/s. It moves every
object on it alike: the distractor rides the same course beside the instructed cube.
"""

from __future__ import annotations

import mujoco

from scenarios.world.panda_scene import SceneConfig, TARGET_RGBA
from scenarios.world.tasks.grip import (ENV_CONAFFINITY, ENV_CONTYPE, OBJECT_CONAFFINITY, OBJECT_CONTYPE,
                                        add_contact_settings, add_finger_pads)

#: the belt: centre and half-sizes, m (its top is BELT_TOP_M, 2 mm above the table top)
BELT_CENTRE_M = (0.5, 0.0, -0.003)
BELT_HALF_M = (0.3, 0.42, 0.005)
BELT_TOP_M = BELT_CENTRE_M[2] + BELT_HALF_M[2]
#: the cubes: half the side (4.5 cm cubes), mass, friction
CUBE_HALF_M = 0.0225
CUBE_MASS_KG = 0.1
CUBE_FRICTION = (1.0, 0.005, 0.0001)
#: the height of a cube's centre at rest on the belt, m
CUBE_REST_Z_M = BELT_TOP_M + CUBE_HALF_M
CUBE_BODIES: tuple[str, ...] = ("cube0", "cube1")
BELT_GEOM = "belt"
#: MuJoCo only moves contacts on a geom whose compiled surfacevel is non-zero: a negligible spin (1e-12 rad/s) turns
#: it on, and the world sets the belt's velocity at run time (measured: a velocity set at run time on a geom compiled
#: with zero surfacevel moves nothing)
BELT_ENABLE_SURFACEVEL = [0.0, 0.0, 0.0, 0.0, 0.0, 1e-12]


def add_pick_scene(spec: mujoco.MjSpec, config: SceneConfig) -> None:
    """The belt, ``config.n_objects`` cubes with free joints, the pads and the contact settings."""
    add_contact_settings(spec)
    add_finger_pads(spec)
    world = spec.worldbody
    world.add_geom(name=BELT_GEOM, type=mujoco.mjtGeom.mjGEOM_BOX, pos=list(BELT_CENTRE_M), size=list(BELT_HALF_M),
                   rgba=[0.22, 0.22, 0.24, 1.0], condim=4, friction=[1.0, 0.005, 0.0001], contype=ENV_CONTYPE,
                   conaffinity=ENV_CONAFFINITY | OBJECT_CONTYPE, surfacevel=BELT_ENABLE_SURFACEVEL)
    for i in range(config.n_objects):
        body = world.add_body(name=CUBE_BODIES[i], pos=[0.5, -0.15 + 0.3 * i, CUBE_REST_Z_M])
        body.add_freejoint(name=f"{CUBE_BODIES[i]}_free")
        body.add_geom(name=f"{CUBE_BODIES[i]}_geom", type=mujoco.mjtGeom.mjGEOM_BOX, size=[CUBE_HALF_M] * 3,
                      mass=CUBE_MASS_KG, rgba=list(TARGET_RGBA[i]), condim=4, friction=list(CUBE_FRICTION),
                      contype=OBJECT_CONTYPE, conaffinity=OBJECT_CONAFFINITY)
