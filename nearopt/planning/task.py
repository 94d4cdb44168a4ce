"""Tasks: a sequence of targets (joint vectors or tool poses), passed through or stopped at.

A task is planned as segments: a segment ends at every target the arm stops at or passes at a
given velocity, and the targets it passes through on the way are the segment's via-points
(:func:`~nearopt.plan`'s ``via``, exact at every iterate). Segments are independent given the
state where they meet (θ there, and θ̇ = 0 or the target's velocity), so the task's J is the sum
of the segments' and each segment is planned in turn from where the previous one ended (the last
target, if a tool pose, optimised along its pose; the stops before it at inverse kinematics'
configurations), within its last target's time window if it has one.

A task file (TOML; joint values in ``units``, poses in metres and a quaternion (x, y, z, w) in
the base frame)::

    start = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]   # optional: θ0 (the CLI's --q0)
    units = "rad"                      # or "deg": of start, every q and velocity (a
                                       # prismatic joint's in m and m/s either way)
    frame = "panda_hand_tcp"           # optional: the frame the poses place (default: the tip)
    [[target]]
    name = "approach"
    pose = [0.5, -0.3, 0.25, 1.0, 0.0, 0.0, 0.0]   # x y z [m] (position only) or x y z qx qy qz qw
    stop = false                       # pass through (default: stop)
    velocity = [0.1, 0.0, 0.0, 0.2, 0.0, 0.1, 0.0]   # optional: at this joint velocity [/s]
    [[target]]
    name = "pick"
    window = [1.0, 2.0]                # optional: arrive between 1 s and 2 s after the start
    pose = [0.5, -0.3, 0.12, 1.0, 0.0, 0.0, 0.0]
    [[target]]
    name = "home"
    q = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..collision import Clearance, CollisionModel, collisions_for
from ..cost import Cost, TimeCost
from ..errors import ConfigurationError, InfeasiblePathError, NearoptError, TaskError
from ..inputs import read_toml
from ..robot import Robot
from ..robot.kinematics import ToolPose
from ..trajectory import ChainedTrajectory
from ..validate import is_number, real_array
from ..verify import Waypoint
from .ends import check_at_limits, check_velocity
from .planner import plan
from .records import Iteration, PlanResult, PlanSettings, StopReason

if TYPE_CHECKING:
    from numpy.typing import ArrayLike, NDArray

__all__ = ["Target", "Task", "TaskResult", "plan_task", "check_targets", "check_plan"]


@dataclass(frozen=True)
class Target:
    """One target of a task.

    Attributes
    ----------
    goal
        A joint vector [rad or m], shape (n,), or a :class:`~nearopt.ToolPose` (inverse
        kinematics from the previous target).
    stop
        The arm comes to rest there (a segment ends); False: it passes through without stopping.
        The last target of a task is always a stop (False there is refused).
    name
        A label for reports and files (default ``target <k>``, from 1).
    velocity
        Pass through at this joint velocity [rad/s or m/s], shape (n,) (``stop`` must be
        False). A segment ends there, and the next one starts there moving
        (:func:`~nearopt.plan`'s ``qde`` and ``qd0``): given θ and θ̇ at the target, the two
        are independent, so the task's J is still the sum of its segments' optima.
    window
        (earliest, latest): when the motion must reach the target [s from the task's start];
        ``latest`` may be inf. Only for a target that ends a segment (a stop, or one with a
        velocity): the segment is planned under t_e ≤ latest − its start (``max_duration``),
        and again under t_e = earliest − its start (``duration``) if it arrives earlier. The
        segments are planned in order: a window is met by the segment that reaches it, not
        prepared for by those before.
    """

    goal: ArrayLike | ToolPose
    stop: bool = True
    name: str | None = None
    velocity: ArrayLike | None = None
    window: tuple[float, float] | None = None


@dataclass(frozen=True)
class Task:
    """A sequence of targets for one robot, and optionally where it starts.

    Attributes
    ----------
    targets
        The targets in order.
    start
        θ0 [rad or m], shape (n,), or None (given to :func:`plan_task` instead).
    source
        The file it was read from, if any.
    """

    targets: tuple[Target, ...]
    start: tuple[float, ...] | None = None
    source: Path | None = None
    degrees: bool = False
    """Read with ``units = "deg"``: every joint value was converted from degrees, so a prismatic
    joint's (given in m and m/s) is put back by :meth:`for_robot`."""

    def for_robot(self, robot: Robot) -> Task:
        """This task in the robot's units: a ``units = "deg"`` file's prismatic joints' values
        (start, q, velocity) as given, in m and m/s, not converted as degrees (the file is read
        without the robot); the task itself otherwise, or where a vector's length is not the
        robot's (the checks after this name it)."""
        linear = robot.prismatic
        if not self.degrees or not np.any(linear):
            return self

        def back(values: ArrayLike | None) -> ArrayLike | None:
            if values is None or np.shape(values) != (robot.n,):
                return values
            return np.where(linear, np.rad2deg(values), values)

        targets = tuple(
            replace(
                t,
                goal=t.goal if isinstance(t.goal, ToolPose) else back(t.goal),
                velocity=back(t.velocity),
            )
            for t in self.targets
        )
        start = back(self.start)
        start = None if start is None else tuple(float(x) for x in start)  # type: ignore[union-attr]
        return replace(self, targets=targets, start=start, degrees=False)

    @classmethod
    def from_file(cls, path: str | Path) -> Task:
        """Read a task from a TOML file (see the module docstring).

        Raises
        ------
        TaskError
            A missing or malformed file, an unknown field, a bad value; the message names the
            file, the target and the field.
        """
        path, data = read_toml(path, TaskError, "task")
        fields = {"start", "units", "frame", "target"}
        unknown = sorted(set(data) - fields)
        if unknown:
            raise TaskError(
                f"{path}: unknown field {unknown[0]!r} (the fields are start, units, "
                "frame and [[target]] tables)",
                field=unknown[0],
            )
        units = data.get("units", "rad")
        if units not in ("rad", "deg"):
            raise TaskError(f"{path}: units must be 'rad' or 'deg', got {units!r}", field="units")
        scale = math.pi / 180.0 if units == "deg" else 1.0
        frame = data.get("frame")
        if frame is not None and not (isinstance(frame, str) and frame):
            raise TaskError(f"{path}: frame must be a frame's name, got {frame!r}", field="frame")
        start = None
        if "start" in data:
            start = tuple(x * scale for x in _numbers(data["start"], path, "start", None, None))
        entries = data.get("target", [])
        if not isinstance(entries, list) or not all(isinstance(e, dict) for e in entries):
            raise TaskError(f"{path}: targets are [[target]] tables", field="target")
        if not entries:
            raise TaskError(f"{path}: the task has no [[target]]", field="target")
        targets = []
        for number, entry in enumerate(entries, start=1):
            name = entry.get("name", f"target {number}")
            if not isinstance(name, str) or not name:
                raise TaskError(
                    f"{path}: target {number}: name must be a non-empty string, got {name!r}",
                    target=f"target {number}",
                    field="name",
                )
            unknown = sorted(
                set(entry) - {"name", "q", "pose", "stop", "frame", "velocity", "window"}
            )
            if unknown:
                raise TaskError(
                    f"{path}: target {name!r}: unknown field {unknown[0]!r} (the "
                    "fields are name, q or pose, frame, stop, velocity, window)",
                    target=name,
                    field=unknown[0],
                )
            kinds = [k for k in ("q", "pose") if k in entry]
            if len(kinds) != 1:
                raise TaskError(
                    f"{path}: target {name!r}: give its joint values q or its pose, "
                    f"once (got {', '.join(kinds) or 'neither'})",
                    target=name,
                    field="q",
                )
            stop = entry.get("stop", True)
            if not isinstance(stop, bool):
                raise TaskError(
                    f"{path}: target {name!r}: stop must be true or false, got {stop!r}",
                    target=name,
                    field="stop",
                )
            target_frame = entry.get("frame", frame)
            if target_frame is not None and not (isinstance(target_frame, str) and target_frame):
                raise TaskError(
                    f"{path}: target {name!r}: frame must be a frame's name, got {target_frame!r}",
                    target=name,
                    field="frame",
                )
            if "q" in entry:
                if "frame" in entry:
                    raise TaskError(
                        f"{path}: target {name!r}: frame applies to a pose",
                        target=name,
                        field="frame",
                    )
                goal: object = np.array(_numbers(entry["q"], path, "q", name, None)) * scale
            else:
                values = _numbers(entry["pose"], path, "pose", name, (3, 7))
                try:
                    goal = ToolPose(values[:3], values[3:] or None, target_frame)
                except ConfigurationError as exc:
                    raise TaskError(
                        f"{path}: target {name!r}: {exc}", target=name, field="pose"
                    ) from None
            velocity = None
            if "velocity" in entry:
                velocity = np.array(_numbers(entry["velocity"], path, "velocity", name, None))
                velocity = velocity * scale
            window = None
            if "window" in entry:
                window = _window(entry["window"], path, name)
            targets.append(Target(goal, stop, name, velocity, window))  # type: ignore[arg-type]
        return cls(tuple(targets), start, path, units == "deg")


def _window(value: object, path: Path, target: str) -> tuple[float, float]:
    """A task file's window = [earliest, latest] [s] (latest may be inf), else a TaskError."""
    ok = (
        isinstance(value, list)
        and len(value) == 2
        and all(isinstance(x, int | float) and not isinstance(x, bool) for x in value)
    )
    if not ok:
        raise TaskError(
            f"{path}: target {target!r}: window must be [earliest, latest] in seconds from the "
            f"task's start, got {value!r:.80}",
            target=target,
            field="window",
        )
    return (float(value[0]), float(value[1]))  # type: ignore[index]


def _numbers(
    value: object, path: Path, field: str, target: str | None, sizes: tuple[int, ...] | None
) -> list[float]:
    """A TOML array of finite numbers (of one of ``sizes``), else a TaskError."""
    where = f"{path}: " + (f"target {target!r}: " if target else "")
    if (
        not isinstance(value, list)
        or not all(
            isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x)
            for x in value
        )
        or not value
    ):
        raise TaskError(
            f"{where}{field} must be an array of finite numbers, got {value!r:.80}",
            target=target,
            field=field,
        )
    if sizes is not None and len(value) not in sizes:
        raise TaskError(
            f"{where}{field} takes x y z [m] or x y z qx qy qz qw, got {len(value)} numbers",
            target=target,
            field=field,
        )
    return [float(x) for x in value]


@dataclass(frozen=True)
class TaskResult:
    """A planned task: its segments one after another.

    Attributes
    ----------
    robot
        The arm.
    targets
        The task's targets, as given (names filled in).
    segments
        One plan per segment, in order.
    trajectory
        The whole motion: the segments' trajectories one after another.
    status
        :attr:`StopReason.INTERRUPTED` if a segment was interrupted, else the least settled of
        the segments' reasons.
    message
        Every segment's message.
    wall_time
        Seconds spent in total.
    """

    robot: Robot
    targets: tuple[Target, ...]
    segments: tuple[PlanResult, ...]
    trajectory: ChainedTrajectory
    status: StopReason
    message: str
    wall_time: float

    @property
    def J(self) -> float:  # noqa: N802 - the paper's name
        """∫ f0 dt of the whole motion: the sum over the segments."""
        return float(sum(s.J for s in self.segments))

    @property
    def duration(self) -> float:
        """t_e of the whole motion [s]."""
        return self.trajectory.duration

    @property
    def cost(self) -> Cost:
        """The running cost f0 that was minimised."""
        return self.segments[0].cost

    @property
    def collisions(self) -> CollisionModel | None:
        """The bodies kept apart and the margin, when collisions were checked."""
        return self.segments[0].collisions

    @property
    def clearance(self) -> Clearance | None:
        """The closest certified clearance over the segments, when checked."""
        found = [s.clearance for s in self.segments if s.clearance is not None]
        return min(found, key=lambda c: c.closest.distance) if found else None

    @property
    def initial_trajectory(self) -> ChainedTrajectory:
        """The segments' first paths (straight lines, or OMPL's), timed by stage 1, one after
        another (each from where the previous segment's plan ended: where a goal moved along its
        pose, they do not join)."""
        return ChainedTrajectory([s.initial.trajectory for s in self.segments], joined=False)

    @property
    def initial_J(self) -> float:  # noqa: N802 - the paper's name
        """J of :attr:`initial_trajectory`."""
        return float(sum(s.initial.J for s in self.segments))

    @property
    def segment_targets(self) -> tuple[tuple[Target, ...], ...]:
        """The targets each segment reaches, in order (its via-points, then its stop)."""
        out, k = [], 0
        for segment in self.segments:
            size = len(segment.via) + 1
            out.append(self.targets[k : k + size])
            k += size
        return tuple(out)

    @property
    def target_configurations(self) -> tuple[NDArray[np.float64], ...]:
        """Where the arm is at each target [rad or m] (a tool pose: the configuration the plan
        reached it with), each (n,)."""
        out: list[NDArray[np.float64]] = []
        for segment in self.segments:
            out.extend(segment.via)
            out.append(segment.trajectory(segment.duration, 0)[0])
        return tuple(out)

    @property
    def target_times(self) -> NDArray[np.float64]:
        """When the motion reaches each target [s], shape (len(targets),)."""
        times: list[float] = []
        for start, segment in zip(self.trajectory.starts, self.segments, strict=True):
            times.extend(start + segment.via_times)
            times.append(start + segment.duration)
        return np.array(times)

    @property
    def waypoints(self) -> tuple[Waypoint, ...]:
        """Every target but the last as :func:`~nearopt.verify` checks it: the configuration
        reached, the pose if it is one, at rest where it is a stop, at its velocity and within
        its window where it has them; the last target's window, if any, as one more."""
        out = [
            Waypoint(
                float(t),
                q,
                target.goal if isinstance(target.goal, ToolPose) else None,
                target.stop,
                target.velocity,
                target.window,
            )
            for t, q, target in zip(
                self.target_times[:-1],
                self.target_configurations[:-1],
                self.targets[:-1],
                strict=True,
            )
        ]
        if self.targets[-1].window is not None:
            out.append(Waypoint(self.duration, window=self.targets[-1].window))
        return tuple(out)

    @property
    def parts(self) -> tuple[PlanResult, ...]:
        """Its segments, in order."""
        return self.segments

    @property
    def iterations(self) -> int:
        """Stage-2 iterations accepted, over all its segments."""
        return sum(segment.iterations for segment in self.segments)

    @property
    def goal(self) -> ToolPose | None:
        """The last target, when it is a tool pose."""
        last = self.targets[-1].goal
        return last if isinstance(last, ToolPose) else None


def plan_task(
    robot: Robot,
    q0: ArrayLike,
    targets: Task | Sequence[Target | ArrayLike | ToolPose],
    cost: Cost | None = None,
    settings: PlanSettings | None = None,
    *,
    callback: Callable[[int, Iteration], None] | None = None,
) -> TaskResult:
    """Plan a task: from rest at θ0 through its targets in order, stopping where they say.

    Parameters
    ----------
    robot, q0, cost
        As :func:`~nearopt.plan`.
    targets
        A :class:`Task`, or :class:`Target` records; a bare joint vector or
        :class:`~nearopt.ToolPose` is a target the arm stops at. The last target is always a stop.
    settings
        How every segment is planned (:class:`~nearopt.planning.PlanSettings`, one collision
        model for all; default: its defaults). ``max_iterations`` is the budget of each segment;
        ``time_limit`` [s] that of the whole task, shared by the segments still to plan (time a
        segment leaves is passed on). With ``optimise_goal`` the last target, when it is a tool
        pose, moves along its pose with the last segment's path to lower J
        (:func:`~nearopt.plan`); the targets stopped at before it keep inverse kinematics'
        configurations: moving one changes the segment after it too, and moving each for its own
        segment alone was measured to raise the task's J (up to +41 % on a seeded panda task).
    callback
        Called with (segment index, :class:`Iteration`) for every accepted iterate.

    Returns
    -------
    TaskResult
        The segments and the whole motion. A Ctrl-C (KeyboardInterrupt) ends the segment being
        planned with its best plan so far; the rest are then timed on their first paths
        (``max_iterations`` 0), status :attr:`StopReason.INTERRUPTED`.

    Raises
    ------
    ConfigurationError
        No targets, a bad target (naming it), or a bad setting as :func:`~nearopt.plan`.
    InfeasiblePathError, UnreachablePoseError, CollisionError, SolverError
        As :func:`~nearopt.plan`, for a segment (the message names it and its targets).
    """
    t_start = time.perf_counter()
    if not isinstance(robot, Robot):
        raise ConfigurationError(
            f"robot must be a nearopt.Robot, got {type(robot).__name__} {robot!r:.60}"
        )
    settings = PlanSettings() if settings is None else settings
    if not isinstance(settings, PlanSettings):
        raise ConfigurationError(
            f"settings must be a nearopt.PlanSettings, got {type(settings).__name__} "
            f"{settings!r:.60}"
        )
    if isinstance(targets, Task):
        targets = targets.for_robot(robot)
    try:
        records = _targets(targets.targets if isinstance(targets, Task) else targets)
    except ConfigurationError as exc:  # a task file's: named
        if not isinstance(targets, Task) or targets.source is None:
            raise
        raise ConfigurationError(f"{targets.source}: {exc}") from None
    if callback is not None and not callable(callback):
        raise ConfigurationError(
            f"callback must be a function of (segment, Iteration), got {type(callback).__name__}"
        )
    what = "q0"
    if q0 is None and isinstance(targets, Task) and targets.start is not None:
        q0 = targets.start
        what = f"{targets.source or 'the task'}: start"
    if q0 is None:
        raise ConfigurationError("give the start configuration q0 (the task has no start)")
    cost = TimeCost() if cost is None else cost
    time_limit = settings.time_limit
    if not is_number(time_limit) or not (time_limit > 0):
        raise ConfigurationError(
            f"time_limit must be a positive number of seconds, got {time_limit!r}"
        )
    q0 = robot.check_configuration(q0, what)
    check_targets(
        robot,
        records,
        q0,
        position_limits=settings.position_limits,
        velocity_limits=settings.velocity_limits,
        where=None
        if not isinstance(targets, Task) or targets.source is None
        else str(targets.source),
    )
    collisions = collisions_for(robot, settings.scene, settings.margin, settings.self_collision)
    moving = next((t for t in records if t.velocity is not None), None)
    if collisions is not None and moving is not None:  # said before any segment is planned
        raise ConfigurationError(
            f"target {moving.name!r} is passed at a velocity: a segment that starts or ends "
            "moving is not planned with obstacles or self-collision checks yet; stop there, or "
            "pass it without a velocity (a via-point)"
        )
    segments, interrupted = _plan_segments(
        robot,
        _stop_groups(records),
        q0,
        cost,
        replace(settings, scene=collisions, margin=None, self_collision=None),
        callback,
        t_start,
    )
    trajectory = ChainedTrajectory([s.trajectory for s in segments])
    message = "; ".join(f"segment {k + 1}: {s.status}, {s.message}" for k, s in enumerate(segments))
    return TaskResult(
        robot=robot,
        targets=records,
        segments=tuple(segments),
        trajectory=trajectory,
        status=StopReason.INTERRUPTED if interrupted else _least_settled(segments),
        message=message,
        wall_time=time.perf_counter() - t_start,
    )


def _stop_groups(records: tuple[Target, ...]) -> list[list[Target]]:
    """The targets as segments: each group ends at a target stopped at or passed at a
    velocity."""
    groups: list[list[Target]] = [[]]
    for target in records:
        groups[-1].append(target)
        if target.stop or target.velocity is not None:
            groups.append([])
    return [g for g in groups if g]


def _plan_segments(
    robot: Robot,
    groups: list[list[Target]],
    q0: NDArray[np.float64],
    cost: Cost,
    settings: PlanSettings,
    callback: Callable[[int, Iteration], None] | None,
    t_start: float,
) -> tuple[list[PlanResult], bool]:
    """Every segment planned from where the last one ended (its via-points passed through), the
    time left shared by the segments still to plan; after a Ctrl-C the rest are timed on their
    first paths. Returns the segments and whether it was interrupted."""
    segments: list[PlanResult] = []
    start, moving, begins = q0, None, 0.0
    interrupted = False
    for k, group in enumerate(groups):
        left = settings.time_limit - (time.perf_counter() - t_start)
        names = ", ".join(repr(t.name) for t in group)

        def forward(entry: Iteration, k: int = k) -> None:
            if callback is not None:
                callback(k, entry)

        same = replace(
            settings,
            time_limit=max(left / (len(groups) - k), 1e-3),
            optimise_goal=settings.optimise_goal and k == len(groups) - 1,
            max_iterations=0 if interrupted else settings.max_iterations,
        )
        begin = (start, moving, begins)
        try:
            segment = _segment(robot, group, begin, cost, {**same.keywords(), "callback": forward})
        except KeyboardInterrupt:  # before the segment had a plan: time its first path only
            interrupted = True
            first = replace(same, max_iterations=0).keywords()
            segment = _segment(robot, group, begin, cost, first)
        except NearoptError as exc:  # the same error, saying which segment
            exc.args = (f"segment {k + 1} (to {names}): {exc}", *exc.args[1:])
            raise
        interrupted = interrupted or segment.status == StopReason.INTERRUPTED
        segments.append(segment)
        start = segment.trajectory(segment.duration, 0)[0]
        moving, begins = group[-1].velocity, begins + segment.duration
    return segments, interrupted


def _segment(
    robot: Robot,
    group: list[Target],
    begin: tuple[NDArray[np.float64], ArrayLike | None, float],
    cost: Cost,
    keywords: dict,
) -> PlanResult:
    """One segment: from ``begin`` = (θ, θ̇ or None at rest, the time it starts [s]) through
    the group's via-points to its last target — at rest or at its velocity, and within its
    window if it has one (t_e ≤ latest − start, then t_e = earliest − start if it arrived
    earlier)."""
    start, moving, begins = begin
    last = group[-1]
    kw = {**keywords, "via": [t.goal for t in group[:-1]], "qd0": moving, "qde": last.velocity}
    if last.window is None:
        return plan(robot, start, last.goal, cost, **kw)  # type: ignore[arg-type]
    lo, hi = (w - begins for w in last.window)
    window = f"the window [{last.window[0]:.6g}, {last.window[1]:.6g}] s of {last.name!r}"
    if hi <= 0.0:
        raise InfeasiblePathError(
            f"the segment starts at t = {begins:.6g} s, after {window} has closed"
        )
    try:
        if math.isfinite(hi) and hi - lo <= 1e-12 * hi:  # an instant
            return plan(robot, start, last.goal, cost, duration=hi, **kw)  # type: ignore[arg-type]
        bound = hi if math.isfinite(hi) else None
        result = plan(robot, start, last.goal, cost, max_duration=bound, **kw)  # type: ignore[arg-type]
        if result.duration < lo:
            result = plan(robot, start, last.goal, cost, duration=lo, **kw)  # type: ignore[arg-type]
    except NearoptError as exc:
        exc.args = (f"{exc} (to meet {window}, from t = {begins:.6g} s)", *exc.args[1:])
        raise
    return result


def check_targets(
    robot: Robot,
    targets: Sequence[Target],
    q0: NDArray[np.float64],
    *,
    position_limits: bool = True,
    where: str | None = None,
    velocity_limits: bool = True,
) -> None:
    """Check a task's targets against the robot before any planning: joint vectors of the right
    length, finite and within the position limits, frames the robot has, velocities of the right
    length within the speed limits, and no stop where the arm already is (the start, or the
    previous stop).

    Raises
    ------
    TaskError
        Naming the task file (``where``), the target and the field.
    """
    prefix = f"{where}: " if where else ""
    previous: object = q0
    previous_name = "the start"
    lim = robot.limits
    for target in targets:
        name = target.name
        if target.velocity is not None:
            _check_velocity(robot, target, prefix, velocity_limits)
        if isinstance(target.goal, ToolPose):
            try:
                robot.frame_id(target.goal.frame)
            except NearoptError as exc:
                raise TaskError(
                    f"{prefix}target {name!r}: {exc}", target=name, field="frame"
                ) from None
            same = isinstance(previous, ToolPose) and previous == target.goal
        else:
            try:
                q = robot.check_configuration(target.goal, "q")
            except ConfigurationError as exc:
                raise TaskError(f"{prefix}target {name!r}: {exc}", target=name, field="q") from None
            if position_limits:
                outside = np.flatnonzero((q < lim.position_lower) | (q > lim.position_upper))
                if outside.size:
                    i = int(outside[0])
                    raise TaskError(
                        f"{prefix}target {name!r}: q[{i}] = {q[i]:.6g} is outside the position "
                        f"limits [{lim.position_lower[i]:.6g}, {lim.position_upper[i]:.6g}] of "
                        f"joint {robot.joint_names[i]!r}",
                        target=name,
                        field="q",
                    )
            same = not isinstance(previous, ToolPose) and np.array_equal(previous, q)
            if position_limits and target.velocity is not None:
                try:
                    check_at_limits(robot, q, real_array(target.velocity), "velocity")
                except ConfigurationError as exc:
                    raise TaskError(
                        f"{prefix}target {name!r}: {exc}", target=name, field="velocity"
                    ) from None
            target = Target(q, target.stop, name)
        if same:
            raise TaskError(
                f"{prefix}target {name!r} is where the arm already is ({previous_name}): a "
                "target must differ from the one before it",
                target=name,
                field="pose" if isinstance(target.goal, ToolPose) else "q",
            )
        previous, previous_name = target.goal, f"target {name!r}"


def _check_velocity(robot: Robot, target: Target, prefix: str, velocity_limits: bool) -> None:
    """A target's velocity (:func:`~nearopt.planning.ends.check_velocity`); TaskError naming
    the target (and the joint)."""
    try:
        check_velocity(robot, target.velocity, "velocity", velocity_limits)
    except ConfigurationError as exc:
        raise TaskError(
            f"{prefix}target {target.name!r}: {exc}", target=target.name, field="velocity"
        ) from None


_ORDER = (
    StopReason.INTERRUPTED,
    StopReason.SOLVER,
    StopReason.TIME_LIMIT,
    StopReason.ITERATION_LIMIT,
    StopReason.NO_PROGRESS,
    StopReason.CONVERGED,
)


def _least_settled(segments: list[PlanResult]) -> StopReason:
    return min((s.status for s in segments), key=_ORDER.index)


def _targets(targets: Sequence[Target | ArrayLike | ToolPose]) -> tuple[Target, ...]:
    """The targets as records with names; the last one a stop."""
    if isinstance(targets, str | bytes | ToolPose | Target) or not isinstance(
        targets, Sequence | np.ndarray
    ):
        raise ConfigurationError(
            f"targets is a list of targets (Target, joint vectors or ToolPose), got {targets!r:.80}"
        )
    if isinstance(targets, np.ndarray) and targets.ndim != 2:
        raise ConfigurationError(
            f"targets as an array has one row per target, got shape {targets.shape}"
        )
    if len(targets) == 0:
        raise ConfigurationError("a task needs at least one target")
    out = []
    for k, target in enumerate(targets, start=1):
        if not isinstance(target, Target):
            if isinstance(target, int | float | np.number):
                raise ConfigurationError(
                    f"target {k} is the number {target!r}: a target is a joint vector, a "
                    "ToolPose or a Target (a flat list of numbers is one configuration, not a "
                    "task)"
                )
            target = Target(target)
        if target.goal is None:
            raise ConfigurationError(f"target {k} has no goal: give a joint vector or a ToolPose")
        if not isinstance(target.stop, bool | np.bool_):
            raise ConfigurationError(f"target {k}: stop must be true or false, got {target.stop!r}")
        if target.name is not None and not (isinstance(target.name, str) and target.name):
            raise ConfigurationError(
                f"target {k}: name must be a non-empty string, got {target.name!r}"
            )
        name = target.name or f"target {k}"
        if k == len(targets) and not target.stop:
            raise ConfigurationError(
                f"target {k} ({name}) is the last: the motion ends there at rest, so it cannot "
                "be passed through (stop = false); remove stop = false, or add a target after it"
            )
        if target.velocity is not None and target.stop:
            raise ConfigurationError(
                f"target {k} ({name}) is a stop with a velocity: the arm is at rest at a stop; "
                "give stop = false to pass through it at that velocity"
            )
        window = None if target.window is None else _checked_window(target, name)
        out.append(Target(target.goal, bool(target.stop), name, target.velocity, window))
    _check_segments(out)
    return tuple(out)


def _checked_window(target: Target, name: str) -> tuple[float, float]:
    """A target's window as (earliest, latest) [s]; ConfigurationError naming the target."""
    window = target.window
    if (
        isinstance(window, str | bytes)
        or not isinstance(window, Sequence | np.ndarray)
        or len(window) != 2
        or not all(is_number(x) for x in window)
    ):
        raise ConfigurationError(
            f"target {name!r}: window must be (earliest, latest) in seconds, got {window!r:.80}"
        )
    lo, hi = float(window[0]), float(window[1])
    if not (math.isfinite(lo) and lo >= 0.0 and hi >= lo and hi > 0.0) or math.isnan(hi):
        raise ConfigurationError(
            f"target {name!r}: window ({lo:.6g}, {hi:.6g}) s is not a time window: 0 ≤ "
            "earliest ≤ latest, earliest finite (latest may be inf), latest > 0"
        )
    if not target.stop and target.velocity is None:
        raise ConfigurationError(
            f"target {name!r}: a window needs the target to end a segment: stop there, or "
            "give it a velocity to pass through at (a via-point's time is not planned for)"
        )
    return lo, hi


def _check_segments(targets: list[Target]) -> None:
    """A target passed through without a velocity must not lie in a segment that starts or ends
    moving (moving ends are not planned with via-points yet); ConfigurationError naming it."""
    moving_start = False
    group: list[Target] = []
    for target in targets:
        group.append(target)
        if target.stop or target.velocity is not None:
            if len(group) > 1 and (moving_start or target.velocity is not None):
                raise ConfigurationError(
                    f"target {group[0].name!r} is passed through on the way to "
                    f"{target.name!r} in a segment that starts or ends moving: give it a "
                    "velocity too, or stop there (a segment with a moving end has no "
                    "via-points yet)"
                )
            moving_start, group = target.velocity is not None, []


def check_plan(result: object, what: str = "result") -> None:
    """That ``result`` is a plan (a :class:`~nearopt.PlanResult` or :class:`TaskResult`).

    Raises
    ------
    ConfigurationError
        Naming the argument and what it got (a motion alone: what to pass instead).
    """
    if not isinstance(result, PlanResult | TaskResult):
        hint = (
            ": a motion alone is not enough, pass the plan it belongs to (what nearopt.plan or "
            "plan_task returned)"
            if hasattr(result, "states")
            else ""
        )
        raise ConfigurationError(
            f"{what} must be a plan (a PlanResult or TaskResult), got {type(result).__name__}"
            + hint
        )
