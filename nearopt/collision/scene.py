"""A work cell's obstacles: boxes, spheres, cylinders, capsules, half-spaces and meshes, placed in
the robot's base frame, built in Python or read from a TOML file.

The file (units metres and radians; ``rpy`` is the URDF's fixed-axis roll-pitch-yaw)::

    margin = 0.02                       # optional [m]
    [[obstacle]]
    name = "table"
    box = [1.2, 0.8, 0.04]              # size x, y, z [m]
    position = [0.4, 0.0, -0.02]        # [m]
    rpy = [0.0, 0.0, 0.0]               # optional [rad]
    [[obstacle]]
    name = "post"
    cylinder = [0.05, 0.6]              # radius, length along z [m]; sphere = r; capsule = [r, l]
    position = [0.45, 0.25, 0.3]
    [[obstacle]]
    name = "floor"
    halfspace = [0.0, 0.0, 1.0, -0.02]  # normal n and offset d: the obstacle is n·x ≤ d
    [[obstacle]]
    name = "fixture"
    mesh = "fixture.stl"                # relative to the scene file; scale = 0.001 for mm
    position = [0.6, -0.3, 0.0]

A mesh is taken as its convex hull (conservative: split a concave object into several obstacles).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..errors import SceneError
from ..inputs import read_toml
from ..validate import is_number

if TYPE_CHECKING:
    from numpy.typing import ArrayLike, NDArray

__all__ = [
    "Box",
    "Sphere",
    "Cylinder",
    "Capsule",
    "HalfSpace",
    "Mesh",
    "Shape",
    "Obstacle",
    "Scene",
    "DEFAULT_MARGIN",
]

DEFAULT_MARGIN = 0.01
"""The clearance kept between every checked pair of bodies by default [m]."""


@dataclass(frozen=True)
class Box:
    """A box centred on its placement; ``size`` its edges along x, y, z [m]."""

    size: tuple[float, float, float]


@dataclass(frozen=True)
class Sphere:
    """A sphere centred on its placement [m]."""

    radius: float


@dataclass(frozen=True)
class Cylinder:
    """A cylinder along the placement's z axis, centred on it [m]."""

    radius: float
    length: float


@dataclass(frozen=True)
class Capsule:
    """A capsule (a cylinder with hemispherical ends) along z, centred; ``length`` of the
    cylinder part [m]."""

    radius: float
    length: float


@dataclass(frozen=True)
class HalfSpace:
    """The half-space n·x ≤ d (a floor, a table top, a wall), in the placement's frame.

    Attributes
    ----------
    normal
        Its outward normal n (normalised on construction), shape (3,).
    offset
        d [m].
    """

    normal: tuple[float, float, float]
    offset: float


@dataclass(frozen=True)
class Mesh:
    """A mesh file (STL, OBJ, DAE, …), taken as its convex hull; ``scale`` multiplies its
    coordinates (0.001 for a file in millimetres)."""

    path: Path
    scale: float = 1.0


Shape = Box | Sphere | Cylinder | Capsule | HalfSpace | Mesh


@dataclass(frozen=True)
class Obstacle:
    """One obstacle: a shape placed in the robot's base frame.

    Attributes
    ----------
    name
        Unique within its scene; messages name it.
    shape
        What it is.
    position
        Its placement's origin in the base frame [m], shape (3,).
    rpy
        Its placement's roll, pitch, yaw (fixed axes x, y, z, as in URDF) [rad], shape (3,).
    """

    name: str
    shape: Shape
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise SceneError(
                f"an obstacle's name is a non-empty string, got {self.name!r}", field="name"
            )
        try:
            _check_shape(self.name, self.shape)
        except (TypeError, ValueError) as exc:
            if isinstance(exc, SceneError):
                raise
            raise SceneError(
                f"obstacle {self.name!r}: a bad {type(self.shape).__name__}: {exc}",
                obstacle=self.name,
                field="shape",
            ) from None
        object.__setattr__(self, "position", _vector(self.name, "position", self.position, 3))
        object.__setattr__(self, "rpy", _vector(self.name, "rpy", self.rpy, 3))

    def rotation(self) -> NDArray[np.float64]:
        """The placement's rotation matrix R = Rz(yaw) Ry(pitch) Rx(roll), shape (3, 3)."""
        r, p, y = self.rpy
        cr, sr, cp, sp_, cy, sy = (
            math.cos(r),
            math.sin(r),
            math.cos(p),
            math.sin(p),
            math.cos(y),
            math.sin(y),
        )
        return np.array(
            [
                [cy * cp, cy * sp_ * sr - sy * cr, cy * sp_ * cr + sy * sr],
                [sy * cp, sy * sp_ * sr + cy * cr, sy * sp_ * cr - cy * sr],
                [-sp_, cp * sr, cp * cr],
            ]
        )


@dataclass(frozen=True)
class Scene:
    """The obstacles of a work cell and the clearance kept from them.

    Attributes
    ----------
    obstacles
        The obstacles, names unique.
    margin
        The least signed distance kept between every checked pair of bodies, robot links with
        obstacles and with each other [m]; default :data:`DEFAULT_MARGIN`.
    """

    obstacles: tuple[Obstacle, ...] = ()
    margin: float = DEFAULT_MARGIN
    source: Path | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        if isinstance(self.obstacles, Obstacle) or not isinstance(self.obstacles, tuple | list):
            raise SceneError(
                f"a scene's obstacles are a tuple of Obstacle records, got "
                f"{type(self.obstacles).__name__}"
            )
        object.__setattr__(self, "obstacles", tuple(self.obstacles))
        seen: set[str] = set()
        for ob in self.obstacles:
            if not isinstance(ob, Obstacle):
                raise SceneError(f"a scene holds Obstacle records, got {type(ob).__name__}")
            if ob.name in seen:
                raise SceneError(
                    f"two obstacles are named {ob.name!r}: names must be unique",
                    obstacle=ob.name,
                    field="name",
                )
            seen.add(ob.name)
        if not (is_number(self.margin) and math.isfinite(self.margin) and self.margin >= 0.0):
            raise SceneError(
                f"margin must be a distance ≥ 0 [m], got {self.margin!r}", field="margin"
            )
        object.__setattr__(self, "margin", float(self.margin))  # numpy's floats as Python's

    def with_margin(self, margin: float) -> Scene:
        """This scene with another margin [m]."""
        return Scene(self.obstacles, margin, self.source)

    @classmethod
    def from_file(cls, path: str | Path) -> Scene:
        """Read a scene from a TOML file (see the module docstring).

        Raises
        ------
        SceneError
            A missing or malformed file, an unknown field, a bad value; the message names the
            file, the obstacle and the field.
        """
        path, data = read_toml(path, SceneError, "scene")
        unknown = sorted(set(data) - {"margin", "obstacle"})
        if unknown:
            raise SceneError(
                f"{path}: unknown field {unknown[0]!r} (the fields are 'margin' and "
                "[[obstacle]] tables)",
                field=unknown[0],
            )
        entries = data.get("obstacle", [])
        if not isinstance(entries, list) or not all(isinstance(e, dict) for e in entries):
            raise SceneError(f"{path}: obstacles are [[obstacle]] tables", field="obstacle")
        obstacles = []
        for number, entry in enumerate(entries, start=1):
            try:
                obstacles.append(_obstacle(entry, number, path.parent))
            except SceneError as exc:
                raise SceneError(f"{path}: {exc}", obstacle=exc.obstacle, field=exc.field) from None
        margin = data.get("margin", DEFAULT_MARGIN)
        if isinstance(margin, bool) or not isinstance(margin, int | float):
            raise SceneError(f"{path}: margin must be a number [m], got {margin!r}", field="margin")
        try:
            return cls(tuple(obstacles), float(margin), path)
        except SceneError as exc:
            raise SceneError(f"{path}: {exc}", obstacle=exc.obstacle, field=exc.field) from None


_SHAPES = ("box", "sphere", "cylinder", "capsule", "halfspace", "mesh")


def _obstacle(entry: dict[str, object], number: int, folder: Path) -> Obstacle:
    name = entry.get("name", f"obstacle {number}")
    if not isinstance(name, str) or not name:
        raise SceneError(
            f"obstacle {number}: name must be a non-empty string, got {name!r}", field="name"
        )
    unknown = sorted(set(entry) - {"name", "position", "rpy", "scale", *_SHAPES})
    if unknown:
        raise SceneError(
            f"obstacle {name!r}: unknown field {unknown[0]!r} (a shape is one of "
            f"{', '.join(_SHAPES)}; then position, rpy, scale)",
            obstacle=name,
            field=unknown[0],
        )
    kinds = [k for k in _SHAPES if k in entry]
    if len(kinds) != 1:
        raise SceneError(
            f"obstacle {name!r}: give exactly one shape ({', '.join(_SHAPES)}), got "
            f"{', '.join(kinds) or 'none'}",
            obstacle=name,
            field="shape",
        )
    kind = kinds[0]
    value = entry[kind]
    if "scale" in entry and kind != "mesh":
        raise SceneError(
            f"obstacle {name!r}: scale applies to a mesh only", obstacle=name, field="scale"
        )
    shape: Shape
    if kind == "box":
        shape = Box(_vector(name, "box", value, 3))  # type: ignore[arg-type]
    elif kind == "sphere":
        shape = Sphere(_number(name, "sphere", value))
    elif kind in ("cylinder", "capsule"):
        r, length = _vector(name, kind, value, 2)
        shape = Cylinder(r, length) if kind == "cylinder" else Capsule(r, length)
    elif kind == "halfspace":
        v = _vector(name, "halfspace", value, 4)
        shape = HalfSpace(v[:3], v[3])  # type: ignore[arg-type]
    else:
        if not isinstance(value, str) or not value:
            raise SceneError(
                f"obstacle {name!r}: mesh must be a file name, got {value!r}",
                obstacle=name,
                field="mesh",
            )
        scale = _number(name, "scale", entry.get("scale", 1.0))
        shape = Mesh((folder / value).resolve(), scale)
    return Obstacle(
        name,
        shape,
        entry.get("position", (0.0, 0.0, 0.0)),  # type: ignore[arg-type]
        entry.get("rpy", (0.0, 0.0, 0.0)),
    )  # type: ignore[arg-type]


def _vector(name: str, what: str, value: ArrayLike, size: int) -> tuple[float, ...]:
    bad = SceneError(
        f"obstacle {name!r}: {what} must be {size} finite numbers, got {value!r}",
        obstacle=name,
        field=what,
    )
    if isinstance(value, str | bytes) or isinstance(value, bool):
        raise bad
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise bad from None
    if a.shape != (size,) or not np.all(np.isfinite(a)):
        raise bad
    return tuple(float(x) for x in a)


def _number(name: str, what: str, value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise SceneError(
            f"obstacle {name!r}: {what} must be a finite number, got {value!r}",
            obstacle=name,
            field=what,
        )
    return float(value)


def _check_shape(name: str, shape: Shape) -> None:
    def positive(field_: str, *values: float) -> None:
        for v in values:
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0.0):
                raise SceneError(
                    f"obstacle {name!r}: {field_} must be > 0 [m], got {v!r}",
                    obstacle=name,
                    field=field_,
                )

    if isinstance(shape, Box):
        if np.shape(shape.size) != (3,):
            raise SceneError(
                f"obstacle {name!r}: box is 3 sizes x, y, z [m], got {shape.size!r}",
                obstacle=name,
                field="box",
            )
        positive("box", *shape.size)
    elif isinstance(shape, Sphere):
        positive("sphere", shape.radius)
    elif isinstance(shape, Cylinder | Capsule):
        kind = "cylinder" if isinstance(shape, Cylinder) else "capsule"
        positive(f"{kind} radius", shape.radius)
        if isinstance(shape, Cylinder):
            positive("cylinder length", shape.length)
        elif not (math.isfinite(shape.length) and shape.length >= 0.0):
            raise SceneError(
                f"obstacle {name!r}: capsule length must be ≥ 0 [m], got {shape.length!r}",
                obstacle=name,
                field="capsule",
            )
    elif isinstance(shape, HalfSpace):
        n = np.asarray(shape.normal, dtype=float)
        if n.shape != (3,) or not np.all(np.isfinite(n)) or np.linalg.norm(n) < 1e-9:
            raise SceneError(
                f"obstacle {name!r}: the half-space's normal must be a non-zero "
                f"vector of 3 numbers, got {shape.normal!r}",
                obstacle=name,
                field="halfspace",
            )
        if not math.isfinite(shape.offset):
            raise SceneError(
                f"obstacle {name!r}: the half-space's offset must be finite",
                obstacle=name,
                field="halfspace",
            )
        scale = float(np.linalg.norm(n))
        object.__setattr__(shape, "normal", tuple(float(x) for x in n / scale))
        object.__setattr__(shape, "offset", float(shape.offset) / scale)
    elif isinstance(shape, Mesh):
        path = Path(shape.path)
        if not path.is_file():
            state = "is not a file" if path.exists() else "does not exist"
            raise SceneError(
                f"obstacle {name!r}: the mesh file {shape.path} {state}",
                obstacle=name,
                field="mesh",
            )
        positive("scale", shape.scale)
        if not 1e-6 <= shape.scale <= 1e6:
            raise SceneError(
                f"obstacle {name!r}: scale must be within [1e-6, 1e6], got {shape.scale!r}",
                obstacle=name,
                field="scale",
            )
    else:
        raise SceneError(
            f"obstacle {name!r}: unknown shape {type(shape).__name__} (Box, "
            "Sphere, Cylinder, Capsule, HalfSpace, Mesh)",
            obstacle=name,
            field="shape",
        )
