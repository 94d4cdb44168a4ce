"""One request model for every entry point: a plan request, checked, prepared, planned, verified.

:class:`PlanRequest` is a motion as ``nearopt plan`` takes it, as a frozen, typed record: its fields
are the command's long options without dashes, ``-`` written ``_`` (the keys of a batch's motions
file), so the command line, :mod:`nearopt.batch` and Python all build the same record —
``PlanRequest.from_mapping`` from a dict (a JSON line), ``PlanRequest(**fields)`` directly.
:func:`prepare` checks it and loads what it names (robot, task, scene), :func:`solve` plans it,
:func:`check` verifies the plan as the command does before writing it, :func:`run` does all three.

Layers, from the top: :mod:`nearopt.cli` (argparse, outputs, signals) → :mod:`nearopt.batch`
(many motions, pools) → this module → the planner (:func:`~nearopt.plan`,
:func:`~nearopt.plan_task`) and :func:`~nearopt.verify`. Nothing here knows argparse.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import time
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass, fields, replace
from enum import Enum
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .collision import Mesh, Scene
from .cost import Cost, TimeCost, TorqueCost
from .errors import ConfigurationError, SamplingWarning
from .planning import (
    METHODS,
    Iteration,
    PlanResult,
    PlanSettings,
    Task,
    TaskResult,
    plan,
    plan_task,
)
from .planning.ends import check_velocity
from .planning.planner import minimum_duration
from .planning.task import check_targets
from .robot import Robot
from .robot.kinematics import ToolPose
from .validate import MAX_RATE, MAX_SAMPLES, check_rate, check_samples, is_number
from .verify import VerificationReport, verify_plan

if TYPE_CHECKING:
    from numpy.typing import NDArray

__all__ = [
    "PlanRequest",
    "Prepared",
    "Outcome",
    "RobotLoader",
    "prepare",
    "solve",
    "check",
    "run",
    "OUTPUT_OPTIONS",
    "FILE_FIELDS",
    "DISPLAY_OPTIONS",
    "MAX_SAMPLES",
    "MAX_RATE",
]

OUTPUT_OPTIONS = ("json", "csv", "html", "plots", "show", "ros_yaml", "ros_bag", "ros_points")
"""Options of ``nearopt plan`` that write or show the plan: the caller's, not the request's."""
FILE_FIELDS = ("urdf", "srdf", "scene", "task", "joint_limits")
"""The fields that name files (read when the request is prepared)."""
DISPLAY_OPTIONS = ("verify", "quiet")
"""Options of ``nearopt plan`` that only change what it prints (accepted, and ignored, in a
mapping)."""


class _Kind(Enum):
    """How a field's value is read from a mapping."""

    FLAG = "true or false"
    SWITCH = "true, false or null"
    TEXT = "a string"
    TEXTS = "a string or a list of strings"
    NUMBER = "a number"
    INTEGER = "an integer"
    NUMBERS = "a number or a list of numbers"
    POINTS = "a list of lists of numbers (one per point)"


@dataclass(frozen=True)
class PlanRequest:
    """A motion to plan, as ``nearopt plan`` takes it (each field is the command's option of the
    same name, ``_`` for ``-``; see ``nearopt plan --help`` for each).

    Attributes
    ----------
    robot, urdf
        The arm: a known name, or a URDF file (exactly one).
    lock, tip, base, srdf, group, lock_at
        Which joints of a URDF are planned for (``lock_at``: ``"JOINT=VALUE"`` strings [rad or m]).
    effort_limit, velocity_limit, acceleration_limit, jerk_limit, torque_rate_limit
        Limits overriding the URDF's: one value or one per joint [N·m or N; rad/s; rad/s²;
        rad/s³; N·m/s or N/s].
    velocity_scale
        A factor on every joint speed limit.
    joint_limits
        A MoveIt ``joint_limits.yaml`` whose limits replace the URDF's
        (:meth:`~nearopt.Robot.with_joint_limits`); the options above replace both.
    q0, qe, goal_pose, frame, via, task, fixed_goal, deg
        Start, goal (joint values, a tool pose x y z [qx qy qz qw] of ``frame``, or a task file),
        via-points, whether inverse kinematics' goal stays fixed, whether joint values are in
        degrees.
    beta, weights, time_optimal
        The cost f0 = 1 + β Σ u², 1 + Σ w_i u_i², or 1 (at most one of them).
    stage1_only, method, grid, max_iterations, time_limit
        The planner: stage 1 only, the path update, grid segments, iteration and wall-time [s]
        budgets.
    duration, max_duration
        t_e exactly, or at most [s] (one or neither; not for a task).
    qd0, qde
        The joint velocities at the start and at the goal [rad/s or m/s; deg/s with ``deg``]
        (None: at rest; not for a task).
    no_velocity_limits, no_position_limits
        Limits switched off.
    scene, margin, self_collision
        Obstacles (a TOML file), the clearance kept [m], whether links are kept apart (None: with
        a scene).
    rate
        The rate [Hz] of the samples that are verified and written.
    joint_order
        The order of the joint vectors given (q0, qe, via and the per-joint limits and weights):
        every joint of the arm by name once, e.g. a controller's order; default the URDF's.
        Outputs keep the URDF's order and name the joints.
    """

    robot: str | None = None
    urdf: str | None = None
    lock: tuple[str, ...] = ()
    tip: str | None = None
    base: str | None = None
    srdf: str | None = None
    group: str | None = None
    lock_at: tuple[str, ...] = ()
    effort_limit: tuple[float, ...] | None = None
    velocity_limit: tuple[float, ...] | None = None
    velocity_scale: float | None = None
    acceleration_limit: tuple[float, ...] | None = None
    jerk_limit: tuple[float, ...] | None = None
    torque_rate_limit: tuple[float, ...] | None = None
    joint_limits: str | None = None
    q0: tuple[float, ...] | None = None
    qe: tuple[float, ...] | None = None
    goal_pose: tuple[float, ...] | None = None
    frame: str | None = None
    via: tuple[tuple[float, ...], ...] = ()
    task: str | None = None
    fixed_goal: bool = False
    deg: bool = False
    beta: float | None = None
    weights: tuple[float, ...] | None = None
    time_optimal: bool = False
    stage1_only: bool = False
    method: str = "scp"
    grid: int = 200
    max_iterations: int = 200
    time_limit: float = 300.0
    duration: float | None = None
    max_duration: float | None = None
    qd0: tuple[float, ...] | None = None
    qde: tuple[float, ...] | None = None
    no_velocity_limits: bool = False
    no_position_limits: bool = False
    scene: str | None = None
    margin: float | None = None
    self_collision: bool | None = None
    rate: float = 1000.0
    joint_order: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        """A file given as a ``Path`` is kept as its text, arrays as (nested) tuples of their
        values: a request compares, copies and travels to a worker as plain data."""
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name in FILE_FIELDS and isinstance(value, os.PathLike):
                object.__setattr__(self, f.name, os.fspath(value))
            elif isinstance(value, np.ndarray):
                plain = value.tolist()
                if isinstance(plain, list):
                    plain = tuple(tuple(v) if isinstance(v, list) else v for v in plain)
                object.__setattr__(self, f.name, plain)

    def _check_kinds(self) -> None:
        """Each field of the kind its annotation says (a request made in Python is not parsed
        as the command line's is): numbers, lists of numbers, via-points as lists of lists,
        names as strings."""

        for f in fields(self):
            value, kind = getattr(self, f.name), str(f.type)
            if value is None or value == f.default:
                continue
            if f.name == "via":
                good = isinstance(value, tuple | list) and all(
                    isinstance(v, tuple | list) and all(is_number(x) for x in v) for v in value
                )
                wants = "a list of via-points, each a list of joint values"
            elif "tuple[float" in kind:
                good = isinstance(value, tuple | list) and all(is_number(x) for x in value)
                wants = "a list of numbers"
            elif "tuple[str" in kind:
                good = isinstance(value, tuple | list) and all(isinstance(x, str) for x in value)
                wants = "a list of names"
            elif kind.startswith("float"):
                good, wants = is_number(value), "a number"
            elif kind.startswith("int"):
                good = is_number(value) and isinstance(value, int | np.integer)
                wants = "an integer"
            elif kind.startswith("str"):
                good = isinstance(value, str)
                wants = (
                    "a known arm's name (e.g. 'panda'; a URDF goes in urdf=PATH)"
                    if f.name == "robot"
                    else "a string"
                )
            elif kind.startswith("bool"):
                good = isinstance(value, bool)
                wants = "true or false"
            else:
                continue
            if not good:
                raise ConfigurationError(
                    f"option {f.name!r} is {wants}, got {type(value).__name__} {value!r:.60}"
                )

    @classmethod
    def from_mapping(cls, mapping: Mapping[str, Any]) -> PlanRequest:
        """A request from a dict of options (a motion of a batch): JSON values, a flag ``true``,
        several values a list, ``via`` a list of lists; ``null`` or ``false`` leaves an option
        at its default. Display options (``verify``, ``quiet``) are ignored.

        Raises
        ------
        ConfigurationError
            An unknown option, an output option, or a value of the wrong kind (naming it).
        """
        if not isinstance(mapping, Mapping):
            raise ConfigurationError(f"a motion's options are an object, got {mapping!r:.80}")
        values: dict[str, Any] = {}
        for key, value in mapping.items():
            if key in OUTPUT_OPTIONS:
                if value not in (False, None):
                    raise ConfigurationError(
                        f"option {key!r}: a request has no outputs (a batch writes every motion "
                        "as DIR/<id>.json itself)"
                    )
                continue
            if key in DISPLAY_OPTIONS:
                continue
            kind = _KINDS.get(key)
            if kind is None:
                raise ConfigurationError(
                    f"unknown option {key!r} (the options of `nearopt plan` without dashes, "
                    f"'-' as '_': {', '.join(sorted(_KINDS))})"
                )
            if value is None or (value is False and kind is not _Kind.SWITCH):
                continue
            values[key] = _read(key, value, kind)
        return cls(**values)

    def check(self) -> None:
        """What can be checked before loading the robot: the options together, numbers and
        optional packages.

        Raises
        ------
        ConfigurationError
            Naming the option and the value.
        """
        self._check_kinds()
        if (self.robot is None) == (self.urdf is None):
            raise ConfigurationError(
                "give the arm as robot (a known name) or as urdf (a file), once"
            )
        if sum((self.beta is not None, self.weights is not None, self.time_optimal)) > 1:
            raise ConfigurationError("give the cost as beta, weights or time_optimal, once")
        if self.method not in METHODS:
            raise ConfigurationError(
                f"method must be one of {', '.join(METHODS)}, got {self.method!r}"
            )
        check_rate(self.rate, "--rate")
        if not self.time_limit > 0:
            raise ConfigurationError(
                "--time-limit must be a positive number of seconds (inf: none), got "
                f"{self.time_limit}"
            )
        self._check_arm()
        self._check_goal()
        if self.margin is not None and not (np.isfinite(self.margin) and self.margin >= 0):
            raise ConfigurationError(f"--margin must be a distance ≥ 0 [m], got {self.margin}")
        if self.margin is not None and not self.scene and not self.self_collision:
            raise ConfigurationError("--margin applies with --scene or --self-collision")
        if self.no_velocity_limits and (
            self.velocity_limit is not None or self.velocity_scale is not None
        ):
            given = "--velocity-limit" if self.velocity_limit is not None else "--velocity-scale"
            raise ConfigurationError(
                f"--no-velocity-limits turns off the speed limits that {given} sets: give one "
                "of them"
            )

    def _check_arm(self) -> None:
        for option in ("lock", "tip", "base", "lock_at"):
            if getattr(self, option) and not self.urdf:
                raise ConfigurationError(
                    f"--{option.replace('_', '-')} applies to --urdf (a named robot chooses its "
                    "own joints)"
                )
        if self.base and not self.tip:
            raise ConfigurationError("--base needs --tip: the chain goes from the base to the tip")
        if self.group and not self.urdf:
            raise ConfigurationError(
                "--group applies to --urdf (a named robot chooses its own joints)"
            )
        if self.group and not self.srdf:
            raise ConfigurationError("--group needs --srdf: the group is read from the SRDF")
        if self.group and self.tip:
            raise ConfigurationError("give the arm as --tip or as an SRDF --group, not both")

    def _check_goal(self) -> None:
        if sum(x is not None for x in (self.qe, self.goal_pose, self.task)) != 1:
            raise ConfigurationError(
                "give the goal as --qe (joint values), as --goal-pose or as a --task file, once"
            )
        if self.task is not None and self.via:
            raise ConfigurationError(
                "--via applies to --qe or --goal-pose (a --task file lists "
                "its targets, stop = false to pass through)"
            )
        if self.task is not None and self.frame:
            raise ConfigurationError(
                "--frame applies to --goal-pose (a --task file gives its frame)"
            )
        if self.task is None and self.q0 is None:
            raise ConfigurationError("give the start configuration, --q0")
        if self.task is not None and self.deg and self.q0 is None:
            raise ConfigurationError(
                '--deg applies to --q0 (a --task file gives its units: units = "deg")'
            )
        if self.goal_pose is not None and len(self.goal_pose) not in (3, 7):
            raise ConfigurationError(
                f"--goal-pose takes x y z [m] or x y z qx qy qz qw, got {len(self.goal_pose)} "
                "numbers"
            )
        if self.frame and self.goal_pose is None and self.task is None:
            raise ConfigurationError("--frame applies to --goal-pose")
        if self.fixed_goal and self.goal_pose is None and self.task is None:
            raise ConfigurationError("--fixed-goal applies to --goal-pose or --task")

    def cost(self) -> Cost:
        """The running cost f0 it asks for (time-optimal unless ``beta`` or ``weights``)."""
        if self.beta is not None:
            return TorqueCost(self.beta)
        if self.weights is not None:
            return TorqueCost(weights=list(self.weights))
        return TimeCost()

    def fingerprint(self) -> str:
        """The request as canonical JSON: the fields that differ from their defaults, and the
        SHA-256 of every file it names (``null`` for one that cannot be read). Two requests with
        the same fingerprint plan the same motion: a batch resumes by comparing them."""
        values = {
            f.name: _json_value(getattr(self, f.name))
            for f in fields(self)
            if getattr(self, f.name) != f.default
        }
        files = {key: _sha256(getattr(self, key)) for key in FILE_FIELDS if getattr(self, key)}
        return json.dumps({**values, "file_sha256": files}, sort_keys=True)

    def with_rate(self, rate: float) -> PlanRequest:
        """The same request at another sampling rate [Hz]."""
        return replace(self, rate=float(rate))


_KINDS: dict[str, _Kind] = {
    "robot": _Kind.TEXT,
    "urdf": _Kind.TEXT,
    "lock": _Kind.TEXTS,
    "tip": _Kind.TEXT,
    "base": _Kind.TEXT,
    "srdf": _Kind.TEXT,
    "group": _Kind.TEXT,
    "lock_at": _Kind.TEXTS,
    "joint_order": _Kind.TEXTS,
    "effort_limit": _Kind.NUMBERS,
    "velocity_limit": _Kind.NUMBERS,
    "velocity_scale": _Kind.NUMBER,
    "acceleration_limit": _Kind.NUMBERS,
    "jerk_limit": _Kind.NUMBERS,
    "torque_rate_limit": _Kind.NUMBERS,
    "joint_limits": _Kind.TEXT,
    "q0": _Kind.NUMBERS,
    "qe": _Kind.NUMBERS,
    "goal_pose": _Kind.NUMBERS,
    "frame": _Kind.TEXT,
    "via": _Kind.POINTS,
    "task": _Kind.TEXT,
    "fixed_goal": _Kind.FLAG,
    "deg": _Kind.FLAG,
    "beta": _Kind.NUMBER,
    "weights": _Kind.NUMBERS,
    "time_optimal": _Kind.FLAG,
    "stage1_only": _Kind.FLAG,
    "method": _Kind.TEXT,
    "grid": _Kind.INTEGER,
    "max_iterations": _Kind.INTEGER,
    "time_limit": _Kind.NUMBER,
    "duration": _Kind.NUMBER,
    "max_duration": _Kind.NUMBER,
    "qd0": _Kind.NUMBERS,
    "qde": _Kind.NUMBERS,
    "no_velocity_limits": _Kind.FLAG,
    "no_position_limits": _Kind.FLAG,
    "scene": _Kind.TEXT,
    "margin": _Kind.NUMBER,
    "self_collision": _Kind.SWITCH,
    "rate": _Kind.NUMBER,
}
"""The one table of options: every field of :class:`PlanRequest` and how a mapping gives it."""


def _json_value(value: object) -> object:
    """A field's value as JSON holds it (tuples as lists)."""
    return [_json_value(v) for v in value] if isinstance(value, tuple) else value


def _sha256(name: str) -> str | None:
    """The SHA-256 of a file's bytes, or None if it cannot be read; taken again only when the
    file's size, modification time or inode changed since (a batch of a million motions names the
    same scene a million times)."""
    try:
        info = os.stat(name)
        key = (name, info.st_ino, info.st_size, info.st_mtime_ns)
        digest = _DIGESTS.get(key)
        if digest is None:
            digest = hashlib.sha256(Path(name).read_bytes()).hexdigest()
            # a file changed in the last seconds may change again within the clock's tick
            if time.time() - info.st_mtime > 2.0:  # (Linux stamps files in jiffies)
                if len(_DIGESTS) >= 256:
                    _DIGESTS.clear()
                _DIGESTS[key] = digest
        return digest
    except OSError:
        return None


_DIGESTS: dict[tuple[str, int, int, int], str] = {}


def _read(key: str, value: object, kind: _Kind) -> object:
    """A mapping's value of option ``key`` as the field holds it."""

    def wrong() -> ConfigurationError:
        return ConfigurationError(
            f"option values are numbers, strings, or lists of them: option {key!r} takes "
            f"{kind.value}, got {value!r:.60}"
        )

    if hasattr(value, "tolist") and callable(value.tolist):  # a NumPy array or scalar
        value = value.tolist()
    if kind in (_Kind.FLAG, _Kind.SWITCH):
        if not isinstance(value, bool):
            raise wrong()
        return value
    if kind is _Kind.TEXT:
        if not isinstance(value, str):
            raise wrong()
        return value
    if kind is _Kind.TEXTS:
        if isinstance(value, Mapping) and key == "lock_at":  # {joint: value}
            return tuple(f"{name}={_number(key, v, wrong)!r}" for name, v in value.items())
        items = [value] if isinstance(value, str) else value
        if not isinstance(items, list | tuple) or not all(isinstance(v, str) for v in items):
            raise wrong()
        return tuple(items)
    if kind is _Kind.NUMBER:
        return _number(key, value, wrong)
    if kind is _Kind.INTEGER:
        number = _number(key, value, wrong)
        if not (math.isfinite(number) and number == int(number)):
            raise wrong()
        return int(number)
    if kind is _Kind.NUMBERS:
        items = value if isinstance(value, list | tuple) else [value]
        if not items:
            raise ConfigurationError(f"option {key!r} takes at least one number, got []")
        if any(isinstance(v, list | tuple) for v in items):
            raise wrong()
        return tuple(_number(key, v, wrong) for v in items)
    # points: a list of lists
    if not isinstance(value, list | tuple) or not all(
        isinstance(v, list | tuple) and v for v in value
    ):
        raise ConfigurationError(
            f"option {key!r} is a list of lists (one per {key} point), got {value!r:.60}"
        )
    return tuple(tuple(_number(key, x, wrong) for x in point) for point in value)


def _number(key: str, value: object, wrong: Callable[[], ConfigurationError]) -> float:
    """A JSON number, or a string of one (``"inf"``, ``"-1e-05"``)."""
    if isinstance(value, bool):
        raise wrong()
    if isinstance(value, int | float):
        return float(value)
    if isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            raise wrong() from None
    raise wrong()


RobotLoader = Callable[[tuple[object, ...], Callable[[], Robot]], Robot]
"""``loader(key, load)``: a robot loaded earlier for the same key, or ``load()`` (a batch worker
keeps its robots)."""


@dataclass(frozen=True)
class Prepared:
    """A request checked, with what it names loaded: what to plan."""

    request: PlanRequest
    robot: Robot
    q0: NDArray[np.float64]
    qe: NDArray[np.float64] | ToolPose | None
    task: Task | None
    scene: Scene | None
    cost: Cost
    via: list[NDArray[np.float64]]

    def input_files(self) -> dict[str, Path]:
        """Every file the request reads, by what it is (``"the URDF"``, ``"the scene"``, ``"the
        mesh of obstacle 'box'"``, …): no output may be one of them
        (:func:`~nearopt.outputs.refuse_inputs`)."""
        request = self.request
        files = {
            "the URDF": request.urdf,
            "the SRDF": request.srdf,
            "the task": request.task,
            "the scene": request.scene,
            "the joint limits file": request.joint_limits,
        }
        out = {what: Path(path) for what, path in files.items() if path is not None}
        # a robot named (--robot) is read from its own URDF and SRDF: inputs as much as given ones
        robot_files = {"the URDF": self.robot.urdf_path, "the SRDF": self.robot.srdf}
        for what, path in robot_files.items():
            if path is not None and what not in out:
                out[f"{what} of {self.robot.name}" if request.robot else what] = Path(path)
        for mesh in _urdf_meshes(self.robot):  # by its name, or its path where names repeat
            what = f"a mesh of the URDF ({mesh.name})"
            out[f"a mesh of the URDF ({mesh})" if what in out else what] = mesh
        if self.scene is not None:
            for obstacle in self.scene.obstacles:
                if isinstance(obstacle.shape, Mesh):
                    out[f"the mesh of obstacle {obstacle.name!r}"] = Path(obstacle.shape.path)
        return out


def _urdf_meshes(robot: Robot) -> list[Path]:
    """The mesh files a robot's URDF names (``<mesh filename=…>``: relative to the URDF's folder,
    ``file://``, or ``package://`` in :meth:`~nearopt.Robot.package_dirs`), those that exist."""
    import xml.etree.ElementTree as ET

    if robot.urdf_xml is None:
        return []
    try:
        root = ET.fromstring(robot.urdf_xml)
    except ET.ParseError:
        return []
    folder = Path(robot.urdf_path).parent if robot.urdf_path is not None else Path.cwd()
    found: dict[Path, None] = {}
    for mesh in root.iter("mesh"):
        name = mesh.get("filename") or ""
        if name.startswith("package://"):
            candidates = [d / name.removeprefix("package://") for d in robot.package_dirs()]
        else:
            candidates = [folder / name.removeprefix("file://")]
        for path in candidates:
            if path.is_file():
                found[path] = None
                break
    return list(found)


@dataclass(frozen=True)
class Outcome:
    """A request planned and verified (see :func:`run`).

    Attributes
    ----------
    result
        The plan.
    report
        Its verification (passed: :func:`run` raises otherwise).
    warnings
        What the planner or the check of the sampling rate warned about, once each.
    prepared
        The request as prepared (its robot, start, goal).
    """

    result: PlanResult | TaskResult
    report: VerificationReport
    warnings: tuple[str, ...]
    prepared: Prepared


def prepare(request: PlanRequest, robot_loader: RobotLoader | None = None) -> Prepared:
    """Check a request and load what it names (robot, task, scene) before any planning.

    Raises
    ------
    NearoptError
        On anything the request gets wrong (naming the option, joint, value and limit).
    """
    if not isinstance(request, PlanRequest):
        raise ConfigurationError(
            f"a request is a PlanRequest (PlanRequest.from_mapping(options) for a dict), got "
            f"{type(request).__name__} {request!r:.60}"
        )
    request.check()
    loaded = _load_robot(request, robot_loader)
    request = _in_urdf_order(request, loaded)
    robot = _with_limits(loaded, request)
    if request.weights is not None and len(request.weights) != robot.n:
        raise ConfigurationError(
            f"--weights needs one weight per joint of {robot.name} ({robot.n}), "
            f"got {len(request.weights)}"
        )
    task = Task.from_file(request.task).for_robot(robot) if request.task is not None else None
    if request.q0 is not None:
        q0 = _joint_values(request.q0, request.deg, robot)
    elif task is not None and task.start is not None:
        q0 = robot.check_configuration(task.start, f"{request.task}: start")
    else:
        raise ConfigurationError(
            f"give the start configuration: --q0, or start = [...] in {request.task}"
        )
    qe: NDArray[np.float64] | ToolPose | None = None
    if request.goal_pose is not None:
        pose = request.goal_pose
        qe = ToolPose(list(pose[:3]), list(pose[3:]) or None, request.frame)
        robot.frame_id(request.frame)  # an unknown frame is named before any work
    elif request.qe is not None:
        qe = _joint_values(request.qe, request.deg, robot)
    else:  # every target is checked before any work
        check_targets(
            robot,
            task.targets,  # type: ignore[union-attr]
            q0,
            where=str(task.source),  # type: ignore[union-attr]
            velocity_limits=not request.no_velocity_limits,
        )
    scene = Scene.from_file(request.scene) if request.scene is not None else None
    via = [_joint_values(v, request.deg, robot) for v in request.via]
    if request.deg:  # said in the request's units (the planner would say rad)
        _check_in_degrees(robot, request, q0, qe, via)
    whole = (robot.n,)
    if isinstance(qe, np.ndarray) and qe.shape == whole and q0.shape == whole:  # too slow: now
        shortest = minimum_duration(robot, q0, qe, not request.no_velocity_limits)[0]
        check_samples(request.rate, shortest, "--rate", at_least=True)
    return Prepared(request, robot, q0, qe, task, scene, request.cost(), via)


def _joint_values(values: tuple[float, ...], deg: bool, robot: Robot) -> NDArray[np.float64]:
    """Joint values (positions or velocities) in rad (rad/s) or m (m/s): a ``--deg`` request's
    revolute joints' converted from degrees, its prismatic joints' as given (m, m/s). A wrong
    count is left to the planner's checks, which name it."""
    q = np.asarray(values, dtype=float)
    if not deg:
        return q
    if q.shape != (robot.n,):
        return np.deg2rad(q)
    return np.where(robot.prismatic, q, np.deg2rad(q))


def _check_in_degrees(
    robot: Robot,
    request: PlanRequest,
    q0: NDArray[np.float64],
    qe: NDArray[np.float64] | ToolPose | None,
    via: list[NDArray[np.float64]],
) -> None:
    """A ``--deg`` request's configurations within the position limits and its boundary
    velocities within the speed limits (where those hold), by the planner's own checks, said in
    degrees (deg, deg/s) before the planner would say them in rad."""
    if not request.no_position_limits:
        points = [("q0", q0), *((f"via[{k}]", v) for k, v in enumerate(via))]
        if isinstance(qe, np.ndarray):
            points.append(("qe", qe))
        for what, q in points:
            if q.shape == (robot.n,):
                robot.limits.check_within(q, what, degrees=True, prismatic=robot.prismatic)
    for what, given in (("qd0", request.qd0), ("qde", request.qde)):
        if given is not None and not request.no_velocity_limits and len(given) == robot.n:
            check_velocity(robot, _joint_values(given, True, robot), what, True, degrees=True)


def solve(
    prepared: Prepared,
    callback: Callable[[Iteration], None] | None = None,
    segment_callback: Callable[[int, Iteration], None] | None = None,
) -> PlanResult | TaskResult:
    """Plan a prepared request: :func:`~nearopt.plan`, or :func:`~nearopt.plan_task` for a task
    (``segment_callback(k, iteration)`` then)."""
    request = prepared.request
    settings = PlanSettings(
        method=request.method,
        grid=request.grid,
        max_iterations=0 if request.stage1_only else request.max_iterations,
        time_limit=request.time_limit,
        velocity_limits=not request.no_velocity_limits,
        position_limits=not request.no_position_limits,
        scene=prepared.scene,
        margin=request.margin,
        self_collision=request.self_collision,
        optimise_goal=not request.fixed_goal,
    )
    if prepared.task is not None:
        if request.duration is not None or request.max_duration is not None:
            raise ConfigurationError(
                "a task's duration is not set yet: --duration and --max-duration plan one motion"
            )
        if request.qd0 is not None or request.qde is not None:
            raise ConfigurationError(
                "a task starts and ends at rest: --qd0 and --qde plan one motion"
            )
        return plan_task(
            prepared.robot,
            prepared.q0,
            prepared.task,
            prepared.cost,
            settings,
            callback=segment_callback,
        )
    qd0, qde = (
        None if v is None else _joint_values(v, request.deg, prepared.robot)
        for v in (request.qd0, request.qde)
    )
    return plan(
        prepared.robot,
        prepared.q0,
        prepared.qe,
        prepared.cost,
        callback=callback,
        via=prepared.via,
        duration=request.duration,
        max_duration=request.max_duration,
        qd0=qd0,
        qde=qde,
        **settings.keywords(),
    )  # type: ignore[arg-type]


def check(result: PlanResult | TaskResult, prepared: Prepared) -> VerificationReport:
    """Verify a plan as the command does before writing it: at the request's rate (never more
    coarsely than 1 kHz), its start, goal (or goal pose), targets, limits, clearance, J.

    Raises
    ------
    ConfigurationError
        If the rate over the motion's duration gives more than :data:`MAX_SAMPLES` samples.
    """
    request = prepared.request
    check_samples(request.rate, result.duration, "--rate")
    qe = prepared.qe
    if prepared.task is not None:
        last = prepared.task.targets[-1].goal
        qe = last if isinstance(last, ToolPose) else np.asarray(last)
    return verify_plan(
        result,
        rate=request.rate,
        q0=prepared.q0,
        qe=None if isinstance(qe, ToolPose) else qe,
        velocity_limits=not request.no_velocity_limits,
        position_limits=not request.no_position_limits,
    )


def run(request: PlanRequest, robot_loader: RobotLoader | None = None) -> Outcome:
    """Prepare, plan and verify a request (no output written, nothing printed).

    Raises
    ------
    NearoptError
        On a bad request or an infeasible one; :class:`~nearopt.VerificationError` if the plan
        fails its verification.
    """
    from .export import check_sampling

    prepared = prepare(request, robot_loader)
    result = solve(prepared)
    report = check(result, prepared)
    report.raise_if_failed()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", SamplingWarning)
        check_sampling(result, request.rate)
    notes = tuple(dict.fromkeys(str(w.message) for w in caught))
    return Outcome(result, report, notes, prepared)


def _per_joint(values: tuple[float, ...], robot: Robot, option: str) -> float | list[float]:
    """One value for every joint, or one per joint."""
    if len(values) == 1:
        return values[0]
    if len(values) != robot.n:
        raise ConfigurationError(
            f"{option} takes one value or one per joint of {robot.name} ({robot.n}: "
            f"{', '.join(robot.joint_names)}), got {len(values)}"
        )
    return list(values)


def _lock_values(pairs: tuple[str, ...]) -> dict[str, float]:
    """``JOINT=VALUE`` strings as a dict."""
    values = {}
    for pair in pairs:
        name, sep, value = pair.rpartition("=")  # (a joint's name may hold "=")
        try:
            values[name] = float(value)
        except ValueError:
            sep = ""
        if not sep or not name:
            raise ConfigurationError(f"--lock-at takes JOINT=VALUE pairs, got {pair!r}")
    return values


PER_JOINT = (
    "q0",
    "qe",
    "qd0",
    "qde",
    "weights",
    "effort_limit",
    "velocity_limit",
    "acceleration_limit",
    "jerk_limit",
    "torque_rate_limit",
)
"""The request's fields that hold one value per joint (and ``via``, several such vectors)."""


def _in_urdf_order(request: PlanRequest, robot: Robot) -> PlanRequest:
    """The request with every joint vector in the URDF's order (``joint_order`` then empty).

    Raises
    ------
    ConfigurationError
        A ``joint_order`` that does not name every joint of the arm exactly once.
    """
    order = request.joint_order
    if not order:
        return request
    names = list(robot.joint_names)
    unknown = [name for name in order if name not in names]
    twice = sorted({name for name in order if order.count(name) > 1})
    missing = [name for name in names if name not in order]
    if unknown or twice or missing:
        said = [
            f"{label}: {', '.join(items)}"
            for label, items in (("unknown", unknown), ("twice", twice), ("missing", missing))
            if items
        ]
        raise ConfigurationError(
            f"--joint-order must name every joint of {robot.name} once ({', '.join(names)}); "
            + "; ".join(said)
        )
    index = [order.index(name) for name in names]

    def mapped(values: tuple[float, ...] | None) -> tuple[float, ...] | None:
        if values is None or len(values) != len(names):
            return values  # (one value for every joint, or a count the checks will name)
        return tuple(values[k] for k in index)

    changes = {field: mapped(getattr(request, field)) for field in PER_JOINT}
    changes["via"] = tuple(mapped(v) for v in request.via)
    return replace(request, **changes, joint_order=())


def _load_robot(request: PlanRequest, loader: RobotLoader | None = None) -> Robot:
    """The arm the request names (its URDF's limits; a single ``--effort-limit`` of a URDF
    applied as the URDF is read)."""
    limit = request.effort_limit
    single_effort = limit[0] if limit and len(limit) == 1 else None

    def load() -> Robot:
        if request.robot:
            return Robot.from_name(
                request.robot, **({"srdf": request.srdf} if request.srdf else {})
            )
        return Robot.from_urdf(
            request.urdf,
            locked_joints=request.lock,
            tip=request.tip,
            base=request.base,
            lock_at=_lock_values(request.lock_at),
            srdf=request.srdf,
            group=request.group,
            effort_limit=single_effort,
        )

    key = (
        request.robot,
        request.urdf,
        request.lock,
        request.tip,
        request.base,
        request.srdf,
        request.group,
        request.lock_at,
        None if request.robot else single_effort,
    )
    return load() if loader is None else loader(key, load)


def _with_limits(robot: Robot, request: PlanRequest) -> Robot:
    """The arm with the limits the request overrides (its vectors in the URDF's order)."""
    if request.joint_limits is not None:
        robot = robot.with_joint_limits(request.joint_limits)
    overrides: dict[str, Any] = {}
    for option, name in (
        ("effort_limit", "effort"),
        ("velocity_limit", "velocity"),
        ("acceleration_limit", "acceleration"),
        ("jerk_limit", "jerk"),
        ("torque_rate_limit", "torque_rate"),
    ):
        values = getattr(request, option)
        if values is not None:
            overrides[name] = _per_joint(values, robot, f"--{option.replace('_', '-')}")
    if request.velocity_scale is not None:
        if not (np.isfinite(request.velocity_scale) and request.velocity_scale > 0):
            raise ConfigurationError(
                f"--velocity-scale must be a positive number, got {request.velocity_scale}"
            )
        base = np.asarray(overrides.get("velocity", robot.limits.velocity), dtype=float)
        overrides["velocity"] = base * request.velocity_scale
    return robot.with_limits(**overrides) if overrides else robot
