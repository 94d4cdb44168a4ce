"""Reading a URDF for nearopt: the checks, the arm's chain, the text Pinocchio builds from.

:func:`read_urdf` parses the file with the standard library, checks it, turns continuous joints
into revolute ones without position limits (θ an angle in ℝ, nq = nv) and decides which joints
are locked; :class:`~nearopt.Robot` builds the Pinocchio model from the text it returns.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from typing import TYPE_CHECKING

from .errors import URDFError

if TYPE_CHECKING:
    from pathlib import Path

__all__ = ["read_urdf", "chain_locks", "SUPPORTED_TYPES"]

SUPPORTED_TYPES = ("revolute", "continuous", "prismatic", "fixed")


def chain_locks(
    root: ET.Element, path: Path, tip: str, base: str | None
) -> tuple[str, ...]:
    """The moving joints that are not on the kinematic chain from ``base`` (default: the root
    link) to ``tip``."""
    links = [link.get("name") for link in root.findall("link")]
    for what, name in (("tip", tip), ("base", base)):
        if name is not None and name not in links:
            raise URDFError(
                f"{path} has no link {name!r} (the {what}); its links: {', '.join(links)}",
                path=str(path),
            )
    joints = root.findall("joint")
    parent_joint = {j.find("child").get("link"): j for j in joints if j.find("child") is not None}
    chain, link = set(), tip
    while link != base and link in parent_joint:
        chain.add(parent_joint[link].get("name"))
        link = parent_joint[link].find("parent").get("link")
    if base is not None and link != base:
        raise URDFError(
            f"link {base!r} of {path} is not above link {tip!r}: no chain joins them",
            path=str(path),
        )
    return tuple(
        j.get("name") for j in joints if j.get("type") != "fixed" and j.get("name") not in chain
    )


def read_urdf(
    path: Path, locked: tuple[str, ...], tip: str | None = None, base: str | None = None
) -> tuple[str, str, list[str], list[str], tuple[str, ...]]:
    """Read and check a URDF.

    Returns the robot's name, the XML text for Pinocchio, the continuous joints, the joints that
    declare no effort limit and the joints to lock (``locked`` and, with a ``tip``, every moving
    joint off the chain from ``base`` to ``tip``). Continuous joints become revolute joints
    without position limits, so that θ is an angle in ℝ (Pinocchio would otherwise use
    (cos θ, sin θ), nq ≠ nv). A ``<limit>`` missing an attribute gets 0 (= undeclared) so that
    urdfdom accepts it and nearopt decides.
    """
    if path.is_dir():
        raise URDFError(f"{path} is a directory, not a URDF file", path=str(path))
    if not path.is_file():
        raise URDFError(f"URDF file not found: {path}", path=str(path))
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise URDFError(f"malformed URDF {path}: {exc}", path=str(path)) from exc
    except OSError as exc:
        raise URDFError(f"cannot read URDF {path}: {exc}", path=str(path)) from exc
    if root.tag != "robot":
        raise URDFError(
            f"{path} is not a URDF: its root element is <{root.tag}>, not <robot>", path=str(path)
        )
    joints = {j.get("name"): j for j in root.findall("joint")}
    if tip is not None:
        off_chain = chain_locks(root, path, tip, base)
        locked = tuple(dict.fromkeys(locked + off_chain))
    unknown = [name for name in locked if name not in joints]
    if unknown:
        raise URDFError(
            f"cannot lock joint(s) {unknown}: {path} has no such joint", path=str(path)
        )
    continuous, no_effort = [], []
    for name, joint in joints.items():
        jtype = joint.get("type")
        if jtype in ("floating", "planar"):
            raise URDFError(
                f"joint {name!r} of {path} is of type {jtype!r}: floating-base robots are not "
                "supported, nearopt plans for fixed-base arms",
                path=str(path),
            )
        if jtype not in SUPPORTED_TYPES:
            raise URDFError(
                f"joint {name!r} of {path} has unsupported type {jtype!r} "
                f"(supported: {', '.join(SUPPORTED_TYPES)})",
                path=str(path),
            )
        mimic = joint.find("mimic")
        if mimic is not None and name not in locked:
            raise URDFError(
                f"joint {name!r} of {path} mimics joint {mimic.get('joint')!r}: mimic joints are "
                "not supported; lock it (locked_joints=...) to plan for the rest of the arm",
                path=str(path),
            )
        if jtype == "fixed":
            continue
        limit = joint.find("limit")
        if limit is None:
            limit = ET.SubElement(joint, "limit")
        if jtype == "continuous":
            joint.set("type", "revolute")
            limit.set("lower", "0")
            limit.set("upper", "0")
            continuous.append(name)
        if float(limit.get("effort", "0")) <= 0.0 and name not in locked:
            no_effort.append(name)
        for attr in ("effort", "velocity", "lower", "upper"):
            limit.set(attr, limit.get(attr, "0"))
    name = root.get("name", path.stem)
    return name, ET.tostring(root, encoding="unicode"), continuous, no_effort, locked
