"""Robots known by name: the arms bundled in ``robots/`` and those of example-robot-data.

example-robot-data 6.x on PyPI ships its URDFs and meshes under ``cmeel.prefix/share`` but no Python
loader; they are found here through the installed distribution's file list
(:mod:`importlib.metadata`), never through a hard-coded interpreter path.
"""

from __future__ import annotations

import importlib.metadata
import importlib.resources
from dataclasses import dataclass
from pathlib import Path

from .errors import RobotNotFoundError, URDFError

__all__ = ["RobotEntry", "available_robots", "robot_entry", "package_dirs"]

_ERD = "example-robot-data"
_ERD_ROBOTS = f"cmeel.prefix/share/{_ERD}/robots/"


@dataclass(frozen=True)
class RobotEntry:
    """Where a named robot's URDF lives and how it is reduced to an arm.

    Attributes
    ----------
    name
        The name the robot is loaded by.
    urdf
        Absolute path of the URDF file.
    tip
        The frame whose path the figures and the viewer trace (the end effector).
    locked_joints
        Joints held fixed at their reference value (e.g. gripper fingers), so that the arm is left.
    srdf
        The SRDF shipped with the URDF (its ``<disable_collisions>`` pairs), if any.
    """

    name: str
    urdf: Path
    tip: str
    locked_joints: tuple[str, ...] = ()
    srdf: Path | None = None


# name -> (path below example-robot-data's robots/ folder, tip frame, joints to lock, SRDF)
_ERD_ARMS: dict[str, tuple[str, str, tuple[str, ...], str | None]] = {
    "ur5": ("ur_description/urdf/ur5_robot.urdf", "tool0", (), "ur_description/srdf/ur5.srdf"),
    "panda": (
        "panda_description/urdf/panda.urdf",
        "panda_hand_tcp",
        ("panda_finger_joint1", "panda_finger_joint2"),
        "panda_description/srdf/panda.srdf",
    ),
    "xarm7": (
        "xarm_description/urdf/xarm7.urdf",
        "link_eef",
        (),
        "xarm_description/srdf/xarm7.srdf",
    ),
    "z1": (
        "z1_description/urdf/z1.urdf",
        "gripperStator",
        ("jointGripper",),
        "z1_description/srdf/z1.srdf",
    ),
    "kinova": (
        "kinova_description/robots/kinova.urdf",
        "j2s6s200_end_effector",
        (),
        "kinova_description/srdf/kinova.srdf",
    ),
    "so101": ("so_arm_description/urdf/so101.urdf", "gripper_frame_link", ("gripper",), None),
}

# name -> tip frame of the arms in robots/
_BUNDLED: dict[str, str] = {"two_link": "tip"}


def available_robots() -> list[str]:
    """Names accepted by :meth:`nearopt.Robot.from_name`, bundled arms first."""
    return list(_BUNDLED) + sorted(_ERD_ARMS)


def _bundled_dir() -> Path:
    return Path(str(importlib.resources.files("nearopt.bundled_robots")))


def _erd_share() -> Path:
    """The ``share`` folder of the installed example-robot-data (holds ``example-robot-data/``)."""
    try:
        dist = importlib.metadata.distribution(_ERD)
    except importlib.metadata.PackageNotFoundError as exc:
        raise URDFError(
            f"the package {_ERD!r} is not installed; `pip install {_ERD}` provides its arms"
        ) from exc
    if not any(f.as_posix().startswith(_ERD_ROBOTS) for f in dist.files or ()):
        raise URDFError(f"the installed {_ERD!r} ships no file under {_ERD_ROBOTS}")
    return Path(str(dist.locate_file("cmeel.prefix/share")))


def package_dirs() -> list[Path]:
    """Folders in which ``package://NAME/...`` mesh URIs of the known robots are resolved."""
    return [_erd_share()]


def robot_entry(name: str) -> RobotEntry:
    """Look a robot up by name.

    Parameters
    ----------
    name
        One of :func:`available_robots`.

    Raises
    ------
    RobotNotFoundError
        If the name is unknown; the message lists the known names.
    """
    if not isinstance(name, str):  # a list or an array: unknown, not unhashable
        raise RobotNotFoundError(f"{name!r:.60}", available_robots())
    if name in _BUNDLED:
        return RobotEntry(name, _bundled_dir() / f"{name}.urdf", _BUNDLED[name])
    if name in _ERD_ARMS:
        rel, tip, locked, srdf = _ERD_ARMS[name]
        root = _erd_share() / _ERD / "robots"
        return RobotEntry(name, root / rel, tip, locked, None if srdf is None else root / srdf)
    raise RobotNotFoundError(name, available_robots())
