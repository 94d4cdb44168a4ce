"""Reading a URDF for nearopt: the checks, the arm's chain, the text Pinocchio builds from.

:func:`read_urdf` parses the file with the standard library and checks what urdfdom and
Pinocchio would accept silently or reject with the wrong cause: numbers that are not finite,
negative masses and inertias that are not physical (not positive semi-definite, or principal
moments that break the triangle inequality I1 + I2 ≥ I3) on links that the arm's joints move,
position limits with lower > upper or lower = upper ≠ 0 (a joint that cannot move), negative
effort or velocity limits and negative damping, zero joint axes, duplicate names, joints between
unknown links, links with two parents and kinematic loops. It turns continuous joints into
revolute ones without position limits (θ an angle in ℝ, nq = nv) and decides which joints are
locked: those asked for (duplicates and fixed joints ignored), every moving joint off the chain
from ``base`` to ``tip``, or every moving joint outside an SRDF group. :class:`~nearopt.Robot`
builds the Pinocchio model from the text it returns.
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import URDFError

__all__ = ["read_urdf", "chain_locks", "srdf_group_locks", "ArmDescription", "SUPPORTED_TYPES"]

SUPPORTED_TYPES = ("revolute", "continuous", "prismatic", "fixed")

# numeric attributes by element, checked to be finite
_NUMBERS = {
    "origin": ("xyz", "rpy"),
    "mass": ("value",),
    "inertia": ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"),
    "axis": ("xyz",),
    "limit": ("lower", "upper", "effort", "velocity", "acceleration", "deceleration", "jerk"),
    "dynamics": ("damping", "friction"),
    "mimic": ("multiplier", "offset"),
}


@dataclass(frozen=True)
class ArmDescription:
    """What :func:`read_urdf` found.

    Attributes
    ----------
    name
        The robot's name (``<robot name>``).
    xml
        The URDF text Pinocchio builds the model from (continuous joints made revolute).
    continuous
        The joints that were continuous (no position limits).
    no_effort
        Moving joints, not locked, that declare no effort limit.
    locked
        The moving joints to lock.
    locked_in_xml
        Their names in ``xml`` (a locked joint that shares its name with a link is renamed).
    rates
        URDF 1.2's limits of the moving joints' rates, by joint name: ``<limit acceleration=…
        deceleration=… jerk=…>`` [rad/s², rad/s², rad/s³ or m/s…], inf where not declared.
    """

    name: str
    xml: str
    continuous: tuple[str, ...]
    no_effort: tuple[str, ...]
    locked: tuple[str, ...]
    locked_in_xml: tuple[str, ...]
    rates: dict[str, RateLimits] = field(default_factory=dict)


@dataclass(frozen=True)
class RateLimits:
    """One joint's URDF 1.2 rate limits (inf: none declared).

    Attributes
    ----------
    acceleration, deceleration
        |θ̈| while the joint speeds up / slows down [rad/s² or m/s²].
    jerk
        |θ⃛| [rad/s³ or m/s³].
    """

    acceleration: float = math.inf
    deceleration: float = math.inf
    jerk: float = math.inf


def _error(path: Path, message: str) -> URDFError:
    return URDFError(f"{message} ({path})", path=str(path))


_NUMBER = re.compile(r"\s*[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
"""A number as Pinocchio's URDF reader (urdfdom: a C++ stream that must end with it) reads one:
spaces before it only, no digit separators."""

_VECTORS = {"xyz", "rpy"}  # the attributes of three numbers; the others hold one


def _floats(text: str | None, path: Path, where: str, count: int | None = None) -> list[float]:
    """The numbers of an attribute, read as urdfdom reads them (three split at spaces, or one),
    or a URDFError naming it: urdfdom reports what it cannot read on the console only and goes
    on without the element (a link with ``<mass value=" 5 "/>`` had no mass)."""
    pieces = [x for x in (text or "").split(" ") if x] if count != 1 else [text or ""]
    for piece in pieces:
        if _NUMBER.fullmatch(piece) is None:
            if _NUMBER.fullmatch(piece.strip()) is not None:
                raise _error(
                    path,
                    f"{where} is {text!r}: Pinocchio's URDF reader (urdfdom) reads no number "
                    f"followed by a space, tab or line break; write {piece.strip()!r}",
                )
            several = (text or "").split()
            if count == 1 and len(several) > 1 and all(_NUMBER.fullmatch(x) for x in several):
                raise _error(path, f"{where} is {text!r}: one number expected, not {len(several)}")
            raise _error(path, f"{where} is {text!r}, not a number")
    values = [float(x) for x in pieces]
    if count is not None and len(values) != count:
        raise _error(path, f"{where} is {text!r}: {count} number(s) expected, not {len(values)}")
    bad = [x for x in values if not math.isfinite(x)]
    if bad:
        raise _error(path, f"{where} is {text!r}: not finite")
    return values


def _owner(element: ET.Element, parents: dict[ET.Element, ET.Element]) -> str:
    """'link NAME' or 'joint NAME' for an element inside a link or joint."""
    node = element
    while node is not None and node.tag not in ("link", "joint"):
        node = parents.get(node)
    return "the robot" if node is None else f"{node.tag} {node.get('name')!r}"


def _check_numbers(root: ET.Element, path: Path) -> None:
    parents = {child: parent for parent in root.iter() for child in parent}
    for tag, attributes in _NUMBERS.items():
        for element in root.iter(tag):
            for attribute in attributes:
                if element.get(attribute) is not None:
                    _floats(
                        element.get(attribute),
                        path,
                        f"<{tag} {attribute}> of {_owner(element, parents)}",
                        3 if attribute in _VECTORS else 1,
                    )


def _moved_links(root: ET.Element, locked: tuple[str, ...]) -> set[str]:
    """The links below at least one moving joint that is not locked (their inertia matters)."""
    children: dict[str, list[ET.Element]] = {}
    for joint in root.findall("joint"):
        children.setdefault(joint.find("parent").get("link"), []).append(joint)
    moved: set[str] = set()
    parents = {j.find("child").get("link") for j in root.findall("joint")}
    frontier = [
        (link.get("name"), False)
        for link in root.findall("link")
        if link.get("name") not in parents
    ]
    while frontier:
        link, moving = frontier.pop()
        if moving:
            moved.add(link)
        for joint in children.get(link, []):
            moves = joint.get("type") != "fixed" and joint.get("name") not in locked
            frontier.append((joint.find("child").get("link"), moving or moves))
    return moved


def _check_inertials(root: ET.Element, path: Path, moved: set[str]) -> None:
    for link in root.findall("link"):
        inertial = link.find("inertial")
        if inertial is None or link.get("name") not in moved:
            continue
        name = link.get("name")
        mass = inertial.find("mass")
        if mass is None or mass.get("value") is None:
            raise _error(path, f"link {name!r} has an <inertial> without a <mass value>")
        m = float(mass.get("value"))
        if m < 0.0:
            raise _error(path, f"link {name!r} has a negative mass, {m:g} kg")
        inertia = inertial.find("inertia")
        if inertia is None:
            continue
        missing = [k for k in _NUMBERS["inertia"] if inertia.get(k) is None]
        if missing:  # urdfdom then drops the link's inertia, reporting it on the console only
            raise _error(
                path,
                f"link {name!r} has an <inertia> without {', '.join(missing)}: URDF asks for "
                "all six (ixx ixy ixz iyy iyz izz; write 0 for a product of inertia that is 0)",
            )
        v = {k: float(inertia.get(k)) for k in _NUMBERS["inertia"]}
        matrix = np.array(
            [
                [v["ixx"], v["ixy"], v["ixz"]],
                [v["ixy"], v["iyy"], v["iyz"]],
                [v["ixz"], v["iyz"], v["izz"]],
            ]
        )
        moments = np.linalg.eigvalsh(matrix)
        scale = float(np.max(np.abs(moments)))
        slack = 1e-9 * scale + 1e-12  # [kg·m²] rounding; a point mass has no inertia at all
        if moments[0] < -slack:
            raise _error(
                path,
                f"link {name!r} has an inertia that is not positive "
                f"semi-definite: principal moments {np.round(moments, 9).tolist()}"
                " kg·m²",
            )
        if moments[0] + moments[1] < moments[2] - 1e-6 * scale - 1e-12:
            raise _error(
                path,
                f"link {name!r} has principal moments of inertia "
                f"{np.round(moments, 9).tolist()} kg·m² that break the triangle "
                "inequality I1 + I2 ≥ I3 (no rigid body has them)",
            )


def _check_tree(root: ET.Element, path: Path) -> dict[str, ET.Element]:
    """Unique names, joints between known links, one parent per link, no loops; returns the
    joints by name."""
    links = [link.get("name") for link in root.findall("link")]
    joints = root.findall("joint")
    if not links:
        raise _error(path, "the robot has no <link>")
    for kind, names in (("link", links), ("joint", [j.get("name") for j in joints])):
        if None in names:
            raise _error(path, f"a <{kind}> has no name")
        seen = set()
        for name in names:
            if name in seen:
                raise _error(path, f"two {kind}s are named {name!r}")
            seen.add(name)
    known = set(links)
    parent_of: dict[str, str] = {}
    for joint in joints:
        name = joint.get("name")
        ends = []
        for end in ("parent", "child"):
            element = joint.find(end)
            link = None if element is None else element.get("link")
            if link not in known:
                raise _error(
                    path,
                    f"joint {name!r} has {end} link {link!r}, which is not a <link> of the robot",
                )
            ends.append(link)
        parent, child = ends
        if child in parent_of:
            raise _error(
                path,
                f"link {child!r} is the child of two joints, {parent_of[child]!r} "
                f"and {name!r}: a kinematic loop (URDF describes trees)",
            )
        parent_of[child] = name
    roots = [link for link in links if link not in parent_of]
    if not roots:
        raise _error(path, "every link has a parent joint: the joints form a kinematic loop")
    reached, frontier = set(roots), list(roots)
    children: dict[str, list[str]] = {}
    for joint in joints:
        children.setdefault(joint.find("parent").get("link"), []).append(
            joint.find("child").get("link")
        )
    while frontier:
        for child in children.get(frontier.pop(), []):
            if child not in reached:
                reached.add(child)
                frontier.append(child)
    loop = [link for link in links if link not in reached]
    if loop:
        raise _error(path, f"links {loop} form a kinematic loop: no root link reaches them")
    if len(roots) > 1:
        raise _error(
            path,
            f"the robot has {len(roots)} root links ({', '.join(roots)}): its "
            "links are not connected by joints into one tree",
        )
    return {j.get("name"): j for j in joints}


def chain_locks(root: ET.Element, path: Path, tip: str, base: str | None) -> tuple[str, ...]:
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
    parent_joint = {j.find("child").get("link"): j for j in joints}
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


def srdf_group_locks(root: ET.Element, path: Path, srdf: Path, group: str) -> tuple[str, ...]:
    """The moving joints of the URDF outside an SRDF group (its ``<chain>``, ``<joint>`` and
    nested ``<group>`` elements; ``<link>`` elements add the joint above each link)."""
    try:
        groups = {g.get("name"): g for g in ET.parse(srdf).getroot().findall("group")}
    except (ET.ParseError, OSError) as exc:
        raise URDFError(f"cannot read the SRDF {srdf}: {exc}", path=str(srdf)) from None
    if group not in groups:
        raise URDFError(
            f"the SRDF {srdf} has no group {group!r}; its groups: "
            f"{', '.join(sorted(groups)) or 'none'}",
            path=str(srdf),
        )
    joints = root.findall("joint")
    parent_joint = {j.find("child").get("link"): j.get("name") for j in joints}
    members: set[str] = set()

    def collect(name: str, seen: tuple[str, ...]) -> None:
        if name in seen:
            raise URDFError(f"SRDF group {name!r} of {srdf} contains itself", path=str(srdf))
        element = groups.get(name)
        if element is None:
            raise URDFError(
                f"SRDF group {seen[-1]!r} of {srdf} refers to a group {name!r} it does not define",
                path=str(srdf),
            )
        for item in element:
            if item.tag == "chain":
                off = set(chain_locks(root, path, item.get("tip_link"), item.get("base_link")))
                members.update(j.get("name") for j in joints if j.get("name") not in off)
            elif item.tag == "joint":
                members.add(item.get("name"))
            elif item.tag == "link" and item.get("name") in parent_joint:
                members.add(parent_joint[item.get("name")])
            elif item.tag == "group":
                collect(item.get("name"), (*seen, name))

    collect(group, ())
    moving = [j.get("name") for j in joints if j.get("type") != "fixed"]
    if not members & set(moving):  # (a name the URDF lacks, e.g. a virtual joint, is ignored)
        unknown = sorted(members - {j.get("name") for j in joints})
        raise URDFError(
            f"SRDF group {group!r} of {srdf} holds no moving joint of {path}"
            + (f"; it names joint(s) {unknown} the URDF does not have" if unknown else ""),
            path=str(srdf),
        )
    return tuple(name for name in moving if name not in members)


def read_urdf(
    path: Path,
    locked: tuple[str, ...] = (),
    tip: str | None = None,
    base: str | None = None,
    srdf: Path | None = None,
    group: str | None = None,
) -> ArmDescription:
    """Read and check a URDF (see the module docstring).

    Parameters
    ----------
    path
        The URDF file.
    locked
        Joints to lock by name; duplicates and fixed joints are ignored.
    tip, base
        Keep only the chain from ``base`` (default: the root link) to the link ``tip``.
    srdf, group
        Keep only the joints of this SRDF group.

    Raises
    ------
    URDFError
        Naming the file, the element and what is wrong with it.
    """
    root = _parse(path)
    joints = _check_tree(root, path)
    _check_numbers(root, path)
    unknown = [name for name in locked if name not in joints]
    if unknown:
        links = {link.get("name") for link in root.findall("link")}
        hint = " (a link has that name: lock the joint above it)" if set(unknown) & links else ""
        raise URDFError(
            f"cannot lock joint(s) {unknown}: {path} has no such joint{hint}", path=str(path)
        )
    if tip is not None:
        locked += chain_locks(root, path, tip, base)
    if group is not None:
        locked += srdf_group_locks(root, path, Path(srdf), group)
    locked = tuple(dict.fromkeys(n for n in locked if joints[n].get("type") != "fixed"))
    _check_inertials(root, path, _moved_links(root, locked))
    continuous, no_effort = [], []
    rates: dict[str, RateLimits] = {}
    for name, joint in joints.items():
        _check_joint(name, joint, path, locked, continuous, no_effort)
        if joint.get("type") != "fixed":
            rates[name] = _rate_limits(name, joint, path)
    rates = {name: r for name, r in rates.items() if name not in locked}
    renamed = _rename_locked(root, joints, locked)
    return ArmDescription(
        name=root.get("name", path.stem),
        xml=ET.tostring(root, encoding="unicode"),
        continuous=tuple(continuous),
        no_effort=tuple(no_effort),
        locked=locked,
        locked_in_xml=tuple(renamed.get(name, name) for name in locked),
        rates=rates,
    )


def _rate_limits(name: str, joint: ET.Element, path: Path) -> RateLimits:
    """A moving joint's ``<limit acceleration deceleration jerk>`` (URDF 1.2; numbers checked
    finite by :func:`_check_numbers`), each > 0 where given; removed from the element (the
    text Pinocchio reads is URDF 1.0)."""
    limit = joint.find("limit")
    values = {}
    for attr in ("acceleration", "deceleration", "jerk"):
        text = None if limit is None else limit.attrib.pop(attr, None)
        if text is None:
            continue
        numbers = _floats(text, path, f"<limit {attr}> of joint {name!r}")
        if len(numbers) != 1 or not numbers[0] > 0.0:
            raise _error(
                path,
                f"joint {name!r} has the {attr} limit {text!r}: it must be one number > 0 (leave "
                "the attribute out for none)",
            )
        value = numbers[0]
        values[attr] = value
    return RateLimits(**values)


def _parse(path: Path) -> ET.Element:
    """The URDF's root element, ``<robot>``."""
    if path.is_dir():
        raise URDFError(f"{path} is a directory, not a URDF file", path=str(path))
    if not path.exists():
        raise URDFError(f"URDF file not found: {path}", path=str(path))
    if not path.is_file():
        raise URDFError(f"{path} is not a regular file (a URDF is one)", path=str(path))
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
    return root


def _check_joint(
    name: str,
    joint: ET.Element,
    path: Path,
    locked: tuple[str, ...],
    continuous: list[str],
    no_effort: list[str],
) -> None:
    """Check one joint (type, mimic, axis, limits) and normalise its ``<limit>`` for Pinocchio
    (a continuous joint becomes revolute without position limits: named in ``continuous``; a
    moving joint without an effort limit is named in ``no_effort``)."""
    jtype = joint.get("type")
    if jtype in ("floating", "planar"):
        raise URDFError(
            f"joint {name!r} of {path} is of type {jtype!r}: a moving base is not "
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
    if mimic is not None and jtype == "fixed":  # a fixed joint follows nothing
        joint.remove(mimic)
    elif mimic is not None and name not in locked:
        raise URDFError(
            f"joint {name!r} of {path} mimics joint {mimic.get('joint')!r}: mimic joints are "
            "not supported; lock it (locked_joints=..., --lock) to plan for the rest of the "
            "arm",
            path=str(path),
        )
    if jtype == "fixed":
        return
    axis = joint.find("axis")
    if axis is not None and not any(_floats(axis.get("xyz", "1 0 0"), path, "axis")):
        raise _error(path, f"joint {name!r} has the zero axis {axis.get('xyz')!r}")
    limit = joint.find("limit")
    if limit is None:
        limit = ET.SubElement(joint, "limit")
    for attr in ("effort", "velocity"):
        if float(limit.get(attr, "0")) < 0.0:
            raise _error(
                path,
                f"joint {name!r} has a negative {attr} limit "
                f"{limit.get(attr)}: limits are magnitudes",
            )
    if jtype == "continuous":
        joint.set("type", "revolute")
        limit.set("lower", "0")
        limit.set("upper", "0")
        continuous.append(name)
    elif float(limit.get("lower", "0")) > float(limit.get("upper", "0")):
        raise _error(
            path,
            f"joint {name!r} has position limits lower {limit.get('lower', '0 (not given)')} > "
            f"upper {limit.get('upper', '0 (not given)')}",
        )
    elif float(limit.get("lower", "0")) == float(limit.get("upper", "0")) != 0.0 and (
        name not in locked
    ):  # (lower = upper = 0: undeclared, no limit)
        raise _error(
            path,
            f"joint {name!r} has position limits lower = upper = {limit.get('lower')}: it cannot "
            "move; lock it there (locked_joints=..., --lock, --lock-at) or give it a range",
        )
    dynamics = joint.find("dynamics")
    if dynamics is not None and float(dynamics.get("damping", "0")) < 0.0:
        raise _error(
            path,
            f"joint {name!r} has a negative damping {dynamics.get('damping')} N·m·s/rad: a "
            "damper takes energy out, never in",
        )
    if dynamics is not None and float(dynamics.get("friction", "0")) < 0.0:
        raise _error(
            path,
            f"joint {name!r} has a negative friction {dynamics.get('friction')} N·m: friction "
            "is a magnitude (nearopt does not model it, but Pinocchio reads it)",
        )
    if float(limit.get("effort", "0")) == 0.0 and name not in locked:
        no_effort.append(name)
    for attr in ("effort", "velocity", "lower", "upper"):
        limit.set(attr, limit.get(attr, "0"))


def _rename_locked(
    root: ET.Element, joints: dict[str, ET.Element], locked: tuple[str, ...]
) -> dict[str, str]:
    """Rename the locked joints that share a link's name; returns the new names."""
    # Pinocchio mixes up a joint and a link of the same name when it removes the joint: a locked
    # joint is renamed first (it leaves the model anyway)
    links = {link.get("name") for link in root.findall("link")}
    renamed = {name: f"{name}__locked_joint" for name in locked if name in links}
    for name, new in renamed.items():
        joints[name].set("name", new)
    for mimic in root.iter("mimic"):
        if mimic.get("joint") in renamed:
            mimic.set("joint", renamed[mimic.get("joint")])
    return renamed
