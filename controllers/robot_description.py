"""Where the one robot description lives, and the Panda's published limits.

The Franka Panda URDF of the ``example-robot-data`` package feeds both Pinocchio
(here) and MuJoCo (``scenarios``), so the two models cannot drift apart.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import metadata
from pathlib import Path

import numpy as np

ARM_JOINTS: tuple[str, ...] = tuple(f"panda_joint{i}" for i in range(1, 8))
FINGER_JOINTS: tuple[str, ...] = ("panda_finger_joint1", "panda_finger_joint2")
TCP_FRAME = "panda_hand_tcp"
#: "ready" pose of the Panda (rad): hand pointing down in front of the base.
HOME_Q_RAD: tuple[float, ...] = (0.0, -0.785398, 0.0, -2.356194, 0.0, 1.570796, 0.785398)


def panda_description_dir() -> Path:
    """Folder ``panda_description`` of the installed ``example-robot-data`` package."""
    try:
        dist = metadata.distribution("example-robot-data")
    except metadata.PackageNotFoundError as exc:  # pragma: no cover - install problem
        raise RuntimeError("example-robot-data is not installed: pip install example-robot-data") from exc
    path = Path(dist.locate_file("cmeel.prefix/share/example-robot-data/robots/panda_description"))
    if not (path / "urdf" / "panda.urdf").is_file():  # pragma: no cover - install problem
        raise RuntimeError(f"panda.urdf not found under {path}; reinstall example-robot-data")
    return path


def panda_urdf_path() -> Path:
    """Path of the Panda URDF (visual meshes ``.dae``, collision meshes ``.stl``)."""
    return panda_description_dir() / "urdf" / "panda.urdf"


@dataclass(frozen=True)
class JointLimits:
    """Arm joint limits (7 joints). Position/velocity/effort come from the URDF; acceleration
    and jerk from Franka's control_parameters documentation.

    Attributes:
        q_min_rad, q_max_rad: position limits, rad.
        v_max_rad_s: velocity limits, rad/s.
        a_max_rad_s2: acceleration limits, rad/s^2.
        j_max_rad_s3: jerk limits, rad/s^3.
        tau_max_nm: effort limits, N*m.
    """

    q_min_rad: tuple[float, ...] = (-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973)
    q_max_rad: tuple[float, ...] = (2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973)
    v_max_rad_s: tuple[float, ...] = (2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61)
    a_max_rad_s2: tuple[float, ...] = (15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0)
    j_max_rad_s3: tuple[float, ...] = (7500.0, 3750.0, 5000.0, 6250.0, 7500.0, 10000.0, 10000.0)
    tau_max_nm: tuple[float, ...] = (87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0)

    def arrays(self) -> dict[str, np.ndarray]:
        return {k: np.asarray(getattr(self, k), dtype=np.float64) for k in self.__dataclass_fields__}
