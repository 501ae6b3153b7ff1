"""The Panda URDF read for MuJoCo: its text with mesh URIs MuJoCo can load, and the pose of a frame that fixed joints
hold to a link (the TCP site of ``scenarios.world.panda_scene``)."""

from __future__ import annotations

import os
import re
import xml.etree.ElementTree as ET
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")  # headless rendering; must precede the mujoco import

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from controllers.robot_description import panda_urdf_path  # noqa: E402


def panda_urdf_for_mujoco(urdf_path: Path | None = None) -> str:
    """The Panda URDF text, ready for MuJoCo's URDF importer.

    Every ``package://.../meshes/{visual,collision}/X.{dae,stl}`` URI becomes the absolute path of
    ``meshes/collision/X.stl`` (MuJoCo cannot read ``.dae``), and a ``<mujoco><compiler/></mujoco>``
    block keeps the URDF inertias (``balanceinertia="false"``) and drops the visual duplicates.
    """
    path = Path(urdf_path) if urdf_path is not None else panda_urdf_path()
    text = path.read_text()
    mesh_dir = path.parent.parent / "meshes" / "collision"

    def _to_stl(match: re.Match[str]) -> str:
        stl = mesh_dir / f"{match.group(1)}.stl"
        if not stl.is_file():
            raise FileNotFoundError(f"collision mesh {stl} for URDF mesh {match.group(0)!r} not found")
        return str(stl)

    text = re.sub(r"package://[^\"']*?/meshes/(?:visual|collision)/([\w\-]+)\.(?:dae|stl)", _to_stl, text)
    if "package://" in text:
        raise ValueError(f"{path}: a package:// URI was left that this loader does not understand")
    compiler = '<mujoco><compiler balanceinertia="false" discardvisual="true" angle="radian"/></mujoco>'
    text, n = re.subn(r"(<robot\b[^>]*>)", r"\1" + compiler, text, count=1)
    if n != 1:
        raise ValueError(f"{path}: no <robot> element found")
    return text


def _rpy_to_matrix(rpy: np.ndarray) -> np.ndarray:
    """URDF roll-pitch-yaw (fixed axes X, Y, Z) -> rotation matrix R = Rz(y) Ry(p) Rx(r)."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx


def fixed_frame_pose(ancestor_link: str, descendant_link: str, urdf_path: Path | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Pose of URDF link ``descendant_link`` in ``ancestor_link``, through fixed joints only.

    Returns:
        (pos_m (3,), quat_wxyz (4,)).

    Raises:
        ValueError: if the chain is broken or crosses a non-fixed joint.
    """
    root = ET.parse(Path(urdf_path) if urdf_path is not None else panda_urdf_path()).getroot()
    joint_of_child = {j.find("child").get("link"): j for j in root.findall("joint")}
    transform = np.eye(4)
    link = descendant_link
    while link != ancestor_link:
        joint = joint_of_child.get(link)
        if joint is None:
            raise ValueError(f"link {descendant_link!r} is not below {ancestor_link!r} in the URDF")
        if joint.get("type") != "fixed":
            raise ValueError(f"joint {joint.get('name')!r} between {ancestor_link!r} and {descendant_link!r} is not fixed")
        origin = joint.find("origin")
        xyz = np.array([float(v) for v in (origin.get("xyz", "0 0 0") if origin is not None else "0 0 0").split()])
        rpy = np.array([float(v) for v in (origin.get("rpy", "0 0 0") if origin is not None else "0 0 0").split()])
        step = np.eye(4)
        step[:3, :3] = _rpy_to_matrix(rpy)
        step[:3, 3] = xyz
        transform = step @ transform
        link = joint.find("parent").get("link")
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, transform[:3, :3].reshape(-1).copy())
    return transform[:3, 3].copy(), quat
