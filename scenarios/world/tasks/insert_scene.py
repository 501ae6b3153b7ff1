"""The insert task's scene: a square peg held in the fingers and a fixture on the table with a square hole.

The hole is ``PEG_SIDE_M + 2 clearance`` wide (``--clearance-mm`` per side), ``HOLE_DEPTH_M`` (25 mm) deep from the top
of its chamfer to the table, which is its bottom. The chamfer is a 45-degree bevel ``CHAMFER_M`` (3 mm) high round the
mouth: four long boxes turned 45 degrees about their axes, one along each inner top edge, their inner vertices on the
hole's edge. The fixture is a mocap body (moved kinematically by the episode's motion family: static, or slow at
0.02-0.1 m/s; a contact with a mocap body lacks the relative-velocity term, which at these speeds is small: MuJoCo's
docs); its geoms are rigid. The peg (a 2 cm square, 8 cm long, 50 g box) is a free body the fingers hold by friction
(fingertip pads, ``grip``), its bottom ``PEG_BELOW_TCP_M`` under the TCP at the start; the fingers' contacts are stiff
(``grip.stiffen_fingers``) so that it stays there.
"""

from __future__ import annotations

import math

import mujoco

from scenarios.world.panda_scene import SceneConfig
from scenarios.world.tasks.grip import (ENV_CONAFFINITY, ENV_CONTYPE, OBJECT_CONAFFINITY, OBJECT_CONTYPE,
                                        add_contact_settings, add_finger_pads, stiffen_fingers)

#: the peg: its side, length and mass; its bottom under the TCP when held
PEG_SIDE_M = 0.02
PEG_LENGTH_M = 0.08
PEG_MASS_KG = 0.05
PEG_BELOW_TCP_M = 0.06
PEG_FRICTION = (0.8, 0.005, 0.0001)
#: the hole: depth from the chamfer's top to the table, the chamfer's height, the walls' thickness
HOLE_DEPTH_M = 0.025
CHAMFER_M = 0.003
WALL_M = 0.02
#: the fixture's surfaces: smooth (steel on steel, lubricated: friction 0.3)
FIXTURE_FRICTION = (0.3, 0.005, 0.0001)
FIXTURE_BODY, PEG_BODY = "fixture", "peg"
#: where the fixture's mocap body starts (the hole's centre on the table), m
FIXTURE_START_M = (0.5, 0.0, 0.0)


def hole_half_m(clearance_mm: float) -> float:
    """Half the hole's width, m."""
    return PEG_SIDE_M / 2.0 + clearance_mm / 1000.0


def add_insert_scene(spec: mujoco.MjSpec, config: SceneConfig) -> None:
    """The fixture (walls, chamfer), the peg, the pads and the contact settings."""
    add_contact_settings(spec)
    add_finger_pads(spec)
    stiffen_fingers(spec)  # the peg must not slide in the fingers on the way (``stiffen_fingers``)
    fixture = spec.worldbody.add_body(name=FIXTURE_BODY, mocap=True, pos=list(FIXTURE_START_M))
    _walls(fixture, hole_half_m(config.clearance_mm))
    peg = spec.worldbody.add_body(name=PEG_BODY, pos=[0.5, 0.3, PEG_LENGTH_M / 2])
    peg.add_freejoint(name=f"{PEG_BODY}_free")
    peg.add_geom(name=f"{PEG_BODY}_geom", type=mujoco.mjtGeom.mjGEOM_BOX,
                 size=[PEG_SIDE_M / 2, PEG_SIDE_M / 2, PEG_LENGTH_M / 2], mass=PEG_MASS_KG, condim=4,
                 friction=list(PEG_FRICTION), contype=OBJECT_CONTYPE, conaffinity=OBJECT_CONAFFINITY,
                 rgba=[0.8, 0.6, 0.2, 1.0])


def _walls(fixture, half: float) -> None:
    """Four walls round a square hole of half-width ``half`` (their tops ``CHAMFER_M`` under the mouth), and the
    chamfer on their inner top edges."""
    wall_h = HOLE_DEPTH_M - CHAMFER_M
    outer = half + WALL_M
    common = dict(type=mujoco.mjtGeom.mjGEOM_BOX, condim=4, friction=list(FIXTURE_FRICTION), contype=ENV_CONTYPE,
                  conaffinity=ENV_CONAFFINITY | OBJECT_CONTYPE, rgba=[0.55, 0.57, 0.6, 1.0])
    # +x / -x walls span the full outer width; +y / -y walls fit between them
    for sign in (1.0, -1.0):
        fixture.add_geom(name=f"wall_x{'+' if sign > 0 else '-'}", pos=[sign * (half + WALL_M / 2), 0, wall_h / 2],
                         size=[WALL_M / 2, outer, wall_h / 2], **common)
        fixture.add_geom(name=f"wall_y{'+' if sign > 0 else '-'}", pos=[0, sign * (half + WALL_M / 2), wall_h / 2],
                         size=[half, WALL_M / 2, wall_h / 2], **common)
    # the chamfer: a box of half-side a turned 45 degrees about the edge, its inner vertex on the hole's edge at the
    # wall's top, its upper face rising outward at 45 degrees to CHAMFER_M above the wall
    a = CHAMFER_M / math.sqrt(2.0)
    d = a * math.sqrt(2.0)  # centre to vertex
    c, s = math.cos(math.pi / 8), math.sin(math.pi / 8)  # quaternion of 45 degrees: (cos 22.5, sin 22.5 axis)
    for sign in (1.0, -1.0):
        fixture.add_geom(name=f"chamfer_x{'+' if sign > 0 else '-'}", pos=[sign * (half + d), 0, wall_h],
                         size=[a, outer, a], quat=[c, 0, s, 0], **common)
        fixture.add_geom(name=f"chamfer_y{'+' if sign > 0 else '-'}", pos=[0, sign * (half + d), wall_h],
                         size=[outer, a, a], quat=[c, s, 0, 0], **common)
