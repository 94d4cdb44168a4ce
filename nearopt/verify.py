"""Check a motion independently of the planner's bookkeeping, as a controller would run it.

:func:`verify` samples the trajectory at the controller's rate and recomputes everything from the
robot model with Pinocchio directly: the torques by RNEA (+ D θ̇) from the sampled (θ, θ̇, θ̈), the
joint limits, the end states, J, and where the torques u(t) take the arm when integrated with ABA.
It returns a report with the worst value of every check; nothing the planner computed is reused
but the motion itself. Its memory does not grow with the motion's duration: the samples are
checked :data:`CHUNK` at a time and a long motion's simulation is bounded by
:data:`MAX_WINDOWS`.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from operator import attrgetter
from typing import TYPE_CHECKING, Protocol

import numpy as np
import pinocchio as pin

from ._simulation_kernels import advance, stage
from .errors import ConfigurationError, VerificationError
from .validate import check_rate, is_number

if TYPE_CHECKING:
    from numpy.typing import ArrayLike, NDArray

    from .collision import CollisionModel
    from .cost import Cost
    from .robot import Robot
    from .robot.kinematics import ToolPose
    from .trajectory import Motion

__all__ = [
    "Check",
    "VerificationReport",
    "VerificationError",
    "Waypoint",
    "Tolerances",
    "verify",
    "verify_plan",
    "torque_rates",
]


@dataclass(frozen=True)
class Waypoint:
    """A point a motion must reach: at ``time`` [s], the configuration ``q`` [rad or m] and/or
    the frame of ``pose`` at its placement, at rest if ``stop``, at the joint velocity ``qd``
    [rad/s or m/s] if given, and at a ``time`` within ``window`` (earliest, latest) [s] if
    given."""

    time: float
    q: ArrayLike | None = None
    pose: ToolPose | None = None
    stop: bool = False
    qd: ArrayLike | None = None
    window: tuple[float, float] | None = None


CHUNK = 65536
"""Samples (and quadrature nodes) checked at a time: a check's memory does not grow with the
motion's duration."""
RATE_STEP = 1e-6
"""The step [s] of the central differences that give the torque rate u̇ where the robot has
torque-rate limits (rounding ~1e-16·|u|/1e-6, truncation ~1e-12·|u⃛|: both far below 1e-6 of a
limit)."""
MAX_STEP = 1e-2
"""The forward simulation's longest Runge-Kutta step [s] (halved where it is not accurate)."""
STABLE = 3.0
"""Where the joint damping's largest rate ρ exceeds STABLE/:data:`MAX_STEP`, the explicit
method's steps would have to stay below STABLE/ρ (inside its interval of stability on the
negative real axis, about [−3.31, 0]): the forward simulation is then implicit (Radau IIA)."""
NEWTON = 1e-3
"""The implicit forward simulation's Newton iterations stop where the error they leave in a
step is estimated below NEWTON times the simulation's accuracy."""
MAX_HALVINGS = 6
"""How often the forward simulation of a window halves its step at most."""
MAX_NEWTON = 20
"""Newton iterations of a step of the implicit forward simulation at most (then its lanes end
in NaN and the check fails)."""
LANES = 32
"""Windows the forward simulation integrates side by side at most (its memory: their torques at
every Runge-Kutta stage)."""
MAX_WINDOWS = 400
"""The forward simulation's windows at most (100 s of motion at the default window): a longer
motion is simulated on that many windows spread evenly over it, the last one among them."""


@dataclass(frozen=True)
class Check:
    """One check: its worst value over the motion against a tolerance.

    Attributes
    ----------
    name
        What is checked.
    worst
        The worst value found (for limits: the largest excess beyond a limit, negative when every
        sample is inside, relative to the limit where ``unit`` is "relative").
    tolerance
        The largest acceptable ``worst``.
    unit
        Unit of ``worst`` and ``tolerance``.
    where
        Where the worst value occurs (time, joint), in words.
    """

    name: str
    worst: float
    tolerance: float
    unit: str
    where: str

    @property
    def passed(self) -> bool:
        return bool(self.worst <= self.tolerance)


@dataclass(frozen=True)
class VerificationReport:
    """The checks of :func:`verify`, at the rate they were made."""

    checks: tuple[Check, ...]
    rate: float
    samples: int

    @property
    def passed(self) -> bool:
        """True if every check passed."""
        return all(c.passed for c in self.checks)

    def __getitem__(self, name: str) -> Check:
        for check in self.checks:
            if check.name == name:
                return check
        raise KeyError(name)

    def failures(self) -> list[Check]:
        """The checks that failed."""
        return [c for c in self.checks if not c.passed]

    def __str__(self) -> str:
        lines = [f"verification at {self.rate:g} Hz ({self.samples} samples):"]
        for c in self.checks:
            mark = "ok  " if c.passed else "FAIL"
            lines.append(
                f"  {mark} {c.name:<28} worst {c.worst:+.3e} (tolerance {c.tolerance:.1e} "
                f"{c.unit}) {c.where}"
            )
        return "\n".join(lines)

    def raise_if_failed(self) -> None:
        """Raise :class:`VerificationError` naming the failed checks."""
        failed = self.failures()
        if failed:
            worst = "; ".join(
                f"{c.name}: {c.worst:.3g} {c.unit} > {c.tolerance:.1g} {c.where}" for c in failed
            )
            raise VerificationError(f"the motion failed verification: {worst}", self)


def _excess(values: NDArray, lower: NDArray, upper: NDArray, scale: NDArray) -> NDArray:
    """(value beyond the nearer limit) / scale; −inf for joints without that limit."""
    with np.errstate(invalid="ignore"):
        excess = np.maximum(values - upper, lower - values) / scale
    return np.where(np.isnan(excess), -np.inf, excess)


def _where(t: NDArray, joints: list[str], index: tuple[int, int]) -> str:
    k, i = index
    return f"at t = {t[k]:.6g} s, joint {joints[i]!r}"


def verify(
    trajectory: Motion,
    robot: Robot,
    *,
    rate: float = 1000.0,
    q0: ArrayLike | None = None,
    qe: ArrayLike | None = None,
    cost: Cost | None = None,
    J: float | None = None,
    velocity_limits: bool = True,
    position_limits: bool = True,
    torque_tolerance: float = 1e-6,
    limit_tolerance: float = 1e-9,
    end_tolerance: float = 1e-8,
    cost_tolerance: float = 1e-4,
    simulation_tolerance: float = 1e-5,
    window: float = 0.25,
    simulate: bool = True,
    collisions: CollisionModel | None = None,
    goal_pose: ToolPose | None = None,
    waypoints: tuple[Waypoint, ...] | list[Waypoint] = (),
    qd0: ArrayLike | None = None,
    qde: ArrayLike | None = None,
    duration: float | None = None,
    max_duration: float | None = None,
) -> VerificationReport:
    """Check a motion at a controller rate, from the robot model alone.

    Parameters
    ----------
    trajectory
        The motion (:attr:`PlanResult.trajectory`, :attr:`TimingResult.trajectory`).
    robot
        The arm, with the limits to check against.
    rate
        Controller rate [Hz]: the motion is sampled from 0 to t_e inclusive at this rate.
    q0, qe
        Expected start and goal [rad]; default: the motion's own ends (then only rest is checked).
    cost, J
        If both are given, J is recomputed as ∫ f0 dt by composite 4-point Gauss-Legendre
        quadrature with RNEA's torques (pieces no longer than 4/rate, at least 2 on every
        interval between the times where the motion's acceleration jumps, the trajectory's knot
        times: across a jump any rule is first-order) and compared with ``J`` (relative
        ``cost_tolerance``).
    velocity_limits, position_limits
        Check the robot's joint speed / position limits.
    torque_tolerance
        Largest acceptable torque beyond a limit, relative to max(|u_min|, |u_max|).
    limit_tolerance
        Largest acceptable speed or acceleration beyond a limit (relative) and position beyond a
        limit [rad]. Joint acceleration limits are checked when the robot has any
        (:meth:`~nearopt.Robot.with_limits`).
    end_tolerance
        Largest acceptable |θ(0) − θ0|, |θ(t_e) − θe| [rad] and end speed [rad/s].
    cost_tolerance
        Relative tolerance of J.
    simulation_tolerance
        Largest acceptable error [rad] of the simulated end position; the end speed may be off by
        ten times that [rad/s].
    window
        The forward simulation restarts from the motion's own state every ``window`` s: open-loop
        integration amplifies any error at the rate of the arm's unstable (gravity) modes, so over
        seconds it would measure that instability, not the motion. The largest mismatch at the end
        of a window is reported as the simulation defect. At most :data:`MAX_WINDOWS` windows
        are simulated (spread over a longer motion, the last one always).
    simulate
        Run the forward simulation (the slowest check); without it, the report holds the checks
        of the samples only.
    goal_pose
        Check that the last sample puts the goal's frame at its placement, to ``end_tolerance``
        [m and rad].
    waypoints
        Points the motion must reach at given times (via-points, a task's targets): the
        configuration and pose there to ``end_tolerance``, at rest (from both sides) where the
        point is a stop.
    collisions
        Check the signed distance of every pair of this model at every sample against its margin
        (the report gives the closest pair, its distance and when) [m].
    qd0, qde
        Expected θ̇(0) and θ̇(t_e) [rad/s] (to ``end_tolerance``; the simulated end speed to ten
        times ``simulation_tolerance``); default: at rest.
    duration, max_duration
        Expected t_e [s], to 1e-9 relative, or its largest value [s] (1e-12 relative over);
        default: any.

    Raises
    ------
    ConfigurationError
        If the rate is not a number of Hz in (0, 1e6]; q0 / qe have the wrong length; the
        trajectory is not a motion (a plan's result instead of its ``trajectory``) or moves
        another number of joints than the robot; J is given without its cost or is not a
        number; the cost is not a :class:`~nearopt.Cost`; the collision model is not one or
        was built for another robot.
    """
    rate = check_rate(rate, "the controller rate")
    _check_motion(trajectory, robot)
    _check_extras(robot, cost, J, collisions)
    tol = Tolerances(
        torque_tolerance,
        limit_tolerance,
        end_tolerance,
        cost_tolerance,
        simulation_tolerance,
        window,
    )
    pool = robot.new_pool()
    ends = _Sampled.at(trajectory, robot, pool, np.array([0.0, trajectory.duration]))
    start = ends.q[0] if q0 is None else robot.check_configuration(q0, "q0")
    goal = ends.q[-1] if qe is None else robot.check_configuration(qe, "qe")
    limits, clearance, count = _sample_checks(
        robot, trajectory, pool, rate, tol, velocity_limits, position_limits, collisions
    )
    checks = [*limits, _end_check(robot, ends, start, goal, tol)]
    if goal_pose is not None:
        checks.append(_goal_pose_check(robot, ends, goal_pose, tol))
    if waypoints:
        _check_waypoints(checks, trajectory, robot, waypoints, end_tolerance)
    v0 = np.zeros(robot.n) if qd0 is None else _velocity(robot, qd0, "qd0")
    ve = np.zeros(robot.n) if qde is None else _velocity(robot, qde, "qde")
    checks.append(_rest_check(robot, ends, tol, v0, ve))
    if duration is not None:
        checks.append(_duration_check(trajectory, duration))
    if max_duration is not None:
        checks.append(_duration_check(trajectory, max_duration, at_most=True))
    if clearance is not None:
        checks.append(clearance)
    if cost is not None and J is not None:
        checks.append(_cost_check(robot, trajectory, pool, cost, J, rate, tol))
    if simulate:
        checks += _simulation_checks(robot, trajectory, goal, tol, ve)
    return VerificationReport(tuple(checks), float(rate), count)


class Planned(Protocol):
    """What :func:`verify_plan` reads of a plan (a :class:`~nearopt.Plan`: a
    :class:`~nearopt.PlanResult` or a :class:`~nearopt.TaskResult`)."""

    @property
    def robot(self) -> Robot: ...

    @property
    def trajectory(self) -> Motion: ...

    @property
    def J(self) -> float: ...  # noqa: N802 - the paper's name

    @property
    def cost(self) -> Cost: ...

    @property
    def goal(self) -> ToolPose | None: ...

    @property
    def collisions(self) -> CollisionModel | None: ...

    @property
    def waypoints(self) -> tuple[Waypoint, ...]: ...


def _check_motion(trajectory: object, robot: object) -> None:
    """That verify was given a motion of this robot (a plan is verified by verify_plan).

    Raises
    ------
    ConfigurationError
        Naming the argument, what it is and what to pass instead.
    """
    from .robot import check_robot
    from .trajectory import Motion

    check_robot(robot)
    if not isinstance(trajectory, Motion):
        hint = (
            ": pass its motion, result.trajectory, or verify_plan(result), which knows q0, qe "
            "and the scene too"
            if hasattr(trajectory, "trajectory")
            else ""
        )
        raise ConfigurationError(
            f"verify checks a motion (a Trajectory), got {type(trajectory).__name__}{hint}"
        )
    joints = trajectory.states(np.zeros(1))[0].shape[1]
    if joints != robot.n:
        raise ConfigurationError(
            f"the motion moves {joints} joints but {robot.name} has {robot.n}: verify a motion "
            "with the robot it was planned for"
        )


def _check_extras(robot: Robot, cost: object, J: object, collisions: object) -> None:  # noqa: N803
    """That J comes with its cost (and is a number), and collisions is this robot's model.

    Raises
    ------
    ConfigurationError
        Naming the argument and what to pass.
    """
    from .collision import CollisionModel
    from .cost import check_cost

    if J is not None:
        if cost is None:
            raise ConfigurationError(
                "J is checked against ∫ f0 dt of its cost: pass cost= too (result.cost)"
            )
        if not is_number(J):
            raise ConfigurationError(f"J must be a number, got {type(J).__name__} {J!r:.40}")
    if cost is not None:
        check_cost(cost)
    if collisions is not None:
        if not isinstance(collisions, CollisionModel):
            raise ConfigurationError(
                "collisions must be a CollisionModel (a plan's result.collisions, or "
                f"CollisionModel(robot, scene)), got {type(collisions).__name__}"
            )
        if collisions.robot.name != robot.name or collisions.robot.n != robot.n:
            raise ConfigurationError(
                f"the collision model was built for {collisions.robot.name}, not for "
                f"{robot.name}: pass the model of the plan being verified"
            )


def verify_plan(
    plan: Planned,
    *,
    rate: float = 1000.0,
    q0: ArrayLike | None = None,
    qe: ArrayLike | None = None,
    velocity_limits: bool = True,
    position_limits: bool = True,
) -> VerificationReport:
    """Check a plan (a :class:`~nearopt.PlanResult` or :class:`~nearopt.TaskResult`) with what
    it carries, as ``nearopt plan`` and ``nearopt batch`` do before writing it: :func:`verify`
    of its motion on its robot at ``rate`` (never more coarsely than 1 kHz), with its goal pose,
    its via-points or targets, its collision model (clearance at every sample) and its J
    recomputed from its cost.

    Parameters
    ----------
    plan
        The plan.
    rate
        Controller rate [Hz]; the check samples at max(rate, 1000 Hz).
    q0, qe
        The start and goal asked for [rad or m], shape (n,); default: the motion's own ends.
    velocity_limits, position_limits
        Whether the plan was asked to keep the joint speed / position limits.

    Raises
    ------
    ConfigurationError
        As :func:`verify`.
    """
    if not all(
        hasattr(plan, name)
        for name in ("trajectory", "robot", "J", "cost", "goal", "collisions", "waypoints")
    ):
        raise ConfigurationError(  # (the planning layer is above this one: duck-typed)
            f"verify_plan checks a plan (a PlanResult or TaskResult), got "
            f"{type(plan).__name__} {plan!r:.60}; a motion alone: verify(motion, robot)"
        )
    return verify(
        plan.trajectory,
        plan.robot,
        rate=max(check_rate(rate, "the controller rate"), 1000.0),
        q0=q0,
        qe=qe,
        goal_pose=plan.goal,
        cost=plan.cost,
        J=plan.J,
        velocity_limits=velocity_limits,
        position_limits=position_limits,
        collisions=plan.collisions,
        waypoints=plan.waypoints,
        **_duration_asked(plan),
        qd0=getattr(plan, "qd0", None),
        qde=getattr(plan, "qde", None),
    )


def _duration_asked(plan: object) -> dict[str, float]:
    """verify's duration keyword of a plan made with one (``duration_asked``: (T, exact))."""
    asked = getattr(plan, "duration_asked", None)
    if asked is None:
        return {}
    return {"duration": asked[0]} if asked[1] else {"max_duration": asked[0]}


@dataclass(frozen=True)
class Tolerances:
    """What :func:`verify` accepts (see its parameters of the same names)."""

    torque: float = 1e-6
    limit: float = 1e-9
    end: float = 1e-8
    cost: float = 1e-4
    simulation: float = 1e-5
    window: float = 0.25


@dataclass(frozen=True)
class _Sampled:
    """The motion at some times, with its torques by RNEA (+ D θ̇)."""

    t: NDArray[np.float64]
    q: NDArray[np.float64]
    qd: NDArray[np.float64]
    qdd: NDArray[np.float64]
    u: NDArray[np.float64]
    qddd: NDArray[np.float64] | None = None  # where the robot has jerk limits and the motion a jerk
    udot: NDArray[np.float64] | None = None  # where the robot has torque-rate limits

    @classmethod
    def at(
        cls, trajectory: Motion, robot: Robot, pool: pin.ModelPool, t: NDArray[np.float64]
    ) -> _Sampled:
        q, qd, qdd = trajectory.states(t)
        jerk = None
        if np.any(np.isfinite(robot.limits.jerk)) and hasattr(trajectory, "jerk"):
            jerk = trajectory.jerk(t)
        u = _torques(robot, pool, q, qd, qdd)
        rate = None
        if np.any(np.isfinite(robot.limits.torque_rate)):
            rate = _torque_rates(trajectory, robot, pool, t, u)
        return cls(t, q, qd, qdd, u, jerk, rate)


def torque_rates(
    robot: Robot, trajectory: Motion, t: ArrayLike, pool: pin.ModelPool | None = None
) -> NDArray[np.float64]:
    """u̇ [N·m/s or N/s] at the times t [s], shape (M, n), from the motion's states alone:
    central differences of RNEA + D θ̇ over ±:data:`RATE_STEP` (one-sided at 0 and t_e; where
    u̇ jumps, at a knot of a C¹ timing, one across lies between the two sides)."""
    t = np.atleast_1d(np.asarray(t, dtype=float))
    pool = robot.new_pool() if pool is None else pool
    ahead = np.minimum(t + RATE_STEP, trajectory.duration)
    behind = np.maximum(t - RATE_STEP, 0.0)
    u1, u0 = (_torques(robot, pool, *trajectory.states(x)) for x in (ahead, behind))
    return (u1 - u0) / np.maximum(ahead - behind, 1e-300)[:, None]


def _torque_rates(
    trajectory: Motion,
    robot: Robot,
    pool: pin.ModelPool,
    t: NDArray[np.float64],
    u: NDArray[np.float64],
) -> NDArray[np.float64]:
    """:func:`torque_rates` at the samples t, or the mean rate over the step to the next
    sample where that is larger (|u̇| ≤ r for all t bounds it too; it catches a jump of u
    between the samples, which a stage-1 timing makes at every knot)."""
    rate = torque_rates(robot, trajectory, t, pool)
    if t.size > 1:
        mean = np.diff(u, axis=0) / np.maximum(np.diff(t), 1e-300)[:, None]
        larger = np.abs(mean) > np.abs(rate[:-1])
        rate[:-1] = np.where(larger, mean, rate[:-1])
    return rate


def _torques(
    robot: Robot, pool: pin.ModelPool, q: NDArray, qd: NDArray, qdd: NDArray
) -> NDArray[np.float64]:
    """u = RNEA(θ, θ̇, θ̈) + D θ̇ at every sample, from Pinocchio directly (its C++ loop over
    the samples, ``rneaInParallel`` on one thread: the same numbers as ``rnea`` one by one)."""
    tau = np.zeros((robot.n, q.shape[0]), order="F")
    if q.shape[0]:
        pin.rneaInParallel(
            1, pool, np.asfortranarray(q.T), np.asfortranarray(qd.T), np.asfortranarray(qdd.T), tau
        )
    return tau.T + robot.damping * qd


def _sample_times(duration: float, rate: float) -> Iterator[NDArray[np.float64]]:
    """The times of the samples at ``rate`` from 0 to t_e inclusive (the last step shorter, as
    :meth:`~nearopt.Motion.sample`), :data:`CHUNK` at a time."""
    count = int(np.floor(duration * rate + 1e-9)) + 1
    for first in range(0, count, CHUNK):
        t = np.arange(first, min(first + CHUNK, count)) / rate
        if first + CHUNK >= count and t[-1] < duration:
            t = np.append(t, duration)
        yield t


_WORST = attrgetter(
    "worst"
)  # of two checks of one quantity, max keeps the worse (the first of equals)


def _sample_checks(
    robot: Robot,
    trajectory: Motion,
    pool: pin.ModelPool,
    rate: float,
    tol: Tolerances,
    velocity_limits: bool,
    position_limits: bool,
    collisions: CollisionModel | None,
) -> tuple[list[Check], Check | None, int]:
    """The limit checks and the clearance over every sample, :data:`CHUNK` samples at a time
    (the worst of each check over the chunks); also the number of samples."""
    limits: list[Check] = []
    clearance: Check | None = None
    count = 0
    for t in _sample_times(trajectory.duration, rate):
        motion = _Sampled.at(trajectory, robot, pool, t)
        count += t.size
        chunk = _limit_checks(robot, motion, tol, velocity_limits, position_limits)
        limits = (
            [max(a, b, key=_WORST) for a, b in zip(limits, chunk, strict=True)] if limits else chunk
        )
        if collisions is not None and collisions.pairs:
            closest = _clearance_check(collisions, motion)
            clearance = closest if clearance is None else max(clearance, closest, key=_WORST)
    return limits, clearance, count


def _limit_checks(
    robot: Robot, motion: _Sampled, tol: Tolerances, velocity_limits: bool, position_limits: bool
) -> list[Check]:
    """Torques, and (as asked, or where the robot has them) speeds, positions, accelerations."""
    n, names, lim = robot.n, list(robot.joint_names), robot.limits
    t = motion.t
    rows = [
        (
            "torque limits (RNEA)",
            motion.u,
            lim.effort_lower,
            lim.effort_upper,
            np.maximum(np.abs(lim.effort_lower), np.abs(lim.effort_upper)),
            tol.torque,
            "relative",
        )
    ]
    if velocity_limits:
        rows.append(
            (
                "joint speed limits",
                motion.qd,
                -lim.velocity,
                lim.velocity,
                lim.velocity,
                tol.limit,
                "relative",
            )
        )
    if position_limits:
        rows.append(
            (
                "joint position limits",
                motion.q,
                lim.position_lower,
                lim.position_upper,
                np.ones(n),
                tol.limit,
                "rad",
            )
        )
    if np.any(np.isfinite(lim.acceleration)):
        rows.append(
            (
                "joint acceleration limits",
                motion.qdd,
                -lim.acceleration,
                lim.acceleration,
                lim.acceleration,
                tol.limit,
                "relative",
            )
        )
    if np.any(np.isfinite(lim.jerk)):
        jerk = motion.qddd  # none: θ̈ jumps at the knots of a stage-1 timing, θ⃛ is unbounded
        rows.append(
            (
                "joint jerk limits",
                np.full_like(motion.qdd, np.inf) if jerk is None else jerk,
                -lim.jerk,
                lim.jerk,
                lim.jerk,
                tol.limit,
                "relative",
            )
        )
    if np.any(np.isfinite(lim.torque_rate)):
        rows.append(
            (
                "torque-rate limits (RNEA, central differences)",
                motion.udot,
                -lim.torque_rate,
                lim.torque_rate,
                lim.torque_rate,
                tol.torque,
                "relative",
            )
        )
    checks = []
    for name, values, lower, upper, scale, tolerance, unit in rows:
        excess = _excess(values, lower, upper, scale)
        worst = np.unravel_index(np.argmax(excess), excess.shape)
        checks.append(Check(name, float(excess[worst]), tolerance, unit, _where(t, names, worst)))
    return checks


def _end_check(
    robot: Robot, motion: _Sampled, start: NDArray, goal: NDArray, tol: Tolerances
) -> Check:
    q, names = motion.q, list(robot.joint_names)
    ends = np.abs(np.vstack([q[0] - start, q[-1] - goal]))
    k, i = np.unravel_index(np.argmax(ends), ends.shape)
    return Check(
        "end positions",
        float(ends[k, i]),
        tol.end,
        "rad",
        f"at the {'start' if k == 0 else 'goal'}, joint {names[i]!r}",
    )


def _goal_pose_check(robot: Robot, motion: _Sampled, goal_pose: ToolPose, tol: Tolerances) -> Check:
    from .robot.kinematics import pose_error

    distance, angle = pose_error(robot, motion.q[-1], goal_pose)
    return Check(
        "goal pose",
        max(distance, angle),
        tol.end,
        "m or rad",
        f"{goal_pose.frame or robot.tip!r}: {distance:.2e} m, {angle:.2e} rad "
        "from the target at t = te",
    )


def _rest_check(robot: Robot, motion: _Sampled, tol: Tolerances, v0: NDArray, ve: NDArray) -> Check:
    """θ̇ at both ends against v0 and ve (at rest: both 0)."""
    rest = np.abs(motion.qd[[0, -1]] - np.stack([v0, ve]))
    k, i = np.unravel_index(np.argmax(rest), rest.shape)
    moving = bool(np.any(v0) or np.any(ve))
    return Check(
        "end velocities" if moving else "rest at both ends",
        float(rest[k, i]),
        tol.end,
        "rad/s",
        f"at the {'start' if k == 0 else 'goal'}, joint {robot.joint_names[i]!r}",
    )


def _velocity(robot: Robot, value: ArrayLike, name: str) -> NDArray:
    """A joint velocity of the robot's length as floats; ConfigurationError else."""
    try:
        v = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ConfigurationError(f"{name} must be {robot.n} joint velocities [rad/s]") from None
    if v.shape != (robot.n,) or not np.all(np.isfinite(v)):
        raise ConfigurationError(
            f"{name} must be {robot.n} finite joint velocities [rad/s], got {v.tolist()!r:.80}"
        )
    return v


def _duration_check(trajectory: Motion, duration: object, at_most: bool = False) -> Check:
    """t_e against the duration asked for (relative), or against its largest value."""
    name = "max_duration" if at_most else "duration"
    if not is_number(duration) or not float(duration) > 0.0:
        raise ConfigurationError(f"{name} must be a positive number of seconds, got {duration!r}")
    t = float(duration)
    excess = (trajectory.duration - t) / t
    return Check(
        "duration at most" if at_most else "duration",
        excess if at_most else abs(excess),
        1e-12 if at_most else 1e-9,
        "relative",
        f"t_e = {trajectory.duration:.12g} s against {t:.12g} s",
    )


def _clearance_check(collisions: CollisionModel, motion: _Sampled) -> Check:
    k_t, k_p, closest = collisions.closest_along(motion.q)
    return Check(
        "clearance (coal)",
        collisions.margin - closest,
        0.0,
        "m",
        f"{collisions.pairs[k_p]} {closest * 1e3:.2f} mm apart at t = "
        f"{motion.t[k_t]:.4f} s (margin {collisions.margin * 1e3:.1f} mm)",
    )


def _cost_check(
    robot: Robot,
    trajectory: Motion,
    pool: pin.ModelPool,
    cost: Cost,
    J: float,
    rate: float,  # noqa: N803
    tol: Tolerances,
) -> Check:
    """J recomputed by composite 4-point Gauss-Legendre quadrature (exact for polynomials of
    degree 7) on pieces no longer than 4/rate [s] (at least :data:`MIN_PIECES` per interval
    between the knots,
    where the motion's acceleration jumps), the torques by RNEA, :data:`CHUNK` nodes at a time."""
    total = 0.0
    for nodes, weights in _gauss_nodes(trajectory.t, rate):
        q, qd, qdd = trajectory.states(nodes)
        total += float(weights @ cost(q, qd, _torques(robot, pool, q, qd, qdd)))
    return Check(
        "J recomputed",
        abs(total - J) / max(abs(J), 1e-12),
        tol.cost,
        "relative",
        f"(∫ f0 dt = {total:.8g}, J = {J:.8g})",
    )


def _simulation_checks(
    robot: Robot, trajectory: Motion, goal: NDArray, tol: Tolerances, ve: NDArray
) -> list[Check]:
    """Where u(t), integrated with ABA window by window, takes the arm."""
    n = robot.n
    x_end, defect = _simulate(robot, trajectory, tol.window, 0.01 * tol.simulation)
    what = "forward simulation of u(t) with ABA"
    return [
        Check(
            "simulated end position",
            float(np.max(np.abs(x_end[:n] - goal))),
            tol.simulation,
            "rad",
            what,
        ),
        Check(
            "simulated end speed",
            float(np.max(np.abs(x_end[n:] - ve))),
            10 * tol.simulation,
            "rad/s",
            what,
        ),
        Check(
            "simulation window defect",
            defect,
            10 * tol.simulation,
            "rad or rad/s",
            f"largest mismatch at the end of a {tol.window:g} s window",
        ),
    ]


def _check_waypoints(
    checks: list[Check],
    trajectory: Motion,
    robot: Robot,
    waypoints: tuple[Waypoint, ...] | list[Waypoint],
    tolerance: float,
) -> None:
    """Append the waypoint checks: configuration, pose and rest at each waypoint's time."""
    from .robot.kinematics import pose_error

    names = list(robot.joint_names)
    t = np.array([w.time for w in waypoints], dtype=float)
    q_at, qd_at, _ = trajectory.states(t)
    # θ̇ just before: a few ulps of t earlier (the piece that ends there; 1e-12 of t_e was a
    # nanosecond at 1000 s, where a braking arm still moves by θ̈·1e-9)
    before = t - 8.0 * np.spacing(np.maximum(np.abs(t), 1.0))
    qd_before = trajectory.states(np.maximum(before, 0.0))[1]
    misses = [
        (float(np.max(np.abs(q_at[k] - robot.check_configuration(w.q, "waypoint")))), k)
        for k, w in enumerate(waypoints)
        if w.q is not None
    ]
    if misses:
        worst, k = max(misses)
        checks.append(
            Check(
                "via-point positions",
                worst,
                tolerance,
                "rad",
                f"waypoint {k + 1} at t = {t[k]:.6g} s",
            )
        )
    poses = [
        (max(pose_error(robot, q_at[k], w.pose)), k)
        for k, w in enumerate(waypoints)
        if w.pose is not None
    ]
    if poses:
        worst, k = max(poses)
        checks.append(
            Check(
                "via-point poses",
                worst,
                tolerance,
                "m or rad",
                f"waypoint {k + 1} at t = {t[k]:.6g} s",
            )
        )
    _check_passing(checks, robot, waypoints, t, (qd_at, qd_before), tolerance)
    stops = [k for k, w in enumerate(waypoints) if w.stop]
    if stops:
        speed = np.maximum(np.abs(qd_at[stops]), np.abs(qd_before[stops]))
        checks.append(_worst_joint("rest at stops", speed, stops, t, names, tolerance))


def _worst_joint(
    name: str,
    values: NDArray[np.float64],
    which: list[int],
    t: NDArray[np.float64],
    names: list[str],
    tolerance: float,
) -> Check:
    """The check of the largest of ``values`` [rad/s], shape (len(which), n): one row per
    waypoint ``which[k]`` (at ``t[which[k]]``), one column per joint."""
    k, i = np.unravel_index(np.argmax(values), values.shape)
    return Check(
        name,
        float(values[k, i]),
        tolerance,
        "rad/s",
        f"waypoint {which[k] + 1} at t = {t[which[k]]:.6g} s, joint {names[i]!r}",
    )


def _check_passing(
    checks: list[Check],
    robot: Robot,
    waypoints: tuple[Waypoint, ...] | list[Waypoint],
    t: NDArray[np.float64],
    speeds: tuple[NDArray[np.float64], NDArray[np.float64]],
    tolerance: float,
) -> None:
    """Append the checks of the waypoints' velocities (θ̇ on both sides of the time, against
    ``qd``) and of their times (within ``window``, to 1e-9 of the latest time or 1e-9 s)."""
    moving = [k for k, w in enumerate(waypoints) if w.qd is not None]
    if moving:
        wanted = np.stack([_velocity(robot, waypoints[k].qd, "a waypoint's qd") for k in moving])
        gap = np.maximum(*(np.abs(v[moving] - wanted) for v in speeds))
        names = list(robot.joint_names)
        checks.append(_worst_joint("velocities at targets", gap, moving, t, names, tolerance))
    timed = [k for k, w in enumerate(waypoints) if w.window is not None]
    if timed:
        late = [
            (max(waypoints[k].window[0] - t[k], t[k] - waypoints[k].window[1]), k)  # type: ignore[index]
            for k in timed
        ]
        worst, k = max(late)
        lo, hi = waypoints[k].window  # type: ignore[misc]
        checks.append(
            Check(
                "arrival windows",
                float(worst),
                1e-9 * max(1.0, float(np.max(t))),  # a duration is met to 1e-9 relative
                "s",
                f"waypoint {k + 1} at t = {t[k]:.9g} s, window [{lo:.9g}, {hi:.9g}] s",
            )
        )


_GAUSS_X, _GAUSS_W = np.polynomial.legendre.leggauss(4)
MIN_PIECES = 2
"""Pieces of the 4-point Gauss-Legendre rule per interval between knots at least (J of seven
plans on two_link, ur5, panda and xarm7 was the same to 1e-15 relative with 1, 2, 4 and 10)."""


def _gauss_nodes(
    knots: NDArray[np.float64], rate: float
) -> Iterator[tuple[NDArray[np.float64], NDArray[np.float64]]]:
    """Nodes and weights of composite 4-point Gauss-Legendre rules on every interval between
    ``knots`` [s], in pieces no longer than 4/rate and at least :data:`MIN_PIECES` per
    interval, about :data:`CHUNK` nodes at a time (never a node on a knot: the acceleration
    jumps there)."""
    dt = np.diff(knots)
    pieces = np.maximum(MIN_PIECES, np.ceil(dt * rate / 4.0)).astype(np.int64)
    first = 0
    while first < dt.size:  # whole intervals, about CHUNK nodes together
        last = first + 1 + int(np.searchsorted(np.cumsum(4 * pieces[first:]), CHUNK))
        last = min(max(last, first + 1), dt.size)
        m = pieces[first:last]
        seg = np.repeat(np.arange(first, last), m)
        j = np.arange(seg.size) - np.repeat(np.cumsum(m) - m, m)
        width = dt[seg] / pieces[seg]
        left = knots[seg] + j * width
        nodes = (left[:, None] + 0.5 * width[:, None] * (1.0 + _GAUSS_X[None, :])).ravel()
        weights = (0.5 * width[:, None] * _GAUSS_W[None, :]).ravel()
        yield nodes, weights
        first = last


def _simulate(
    robot: Robot, trajectory: Motion, window: float, accuracy: float
) -> tuple[NDArray[np.float64], float]:
    """Integrate θ̈ = ABA(θ, θ̇, u(t) − Dθ̇) under the motion's torques, in restarted windows.

    Dormand and Prince's fifth-order Runge-Kutta method in equal steps: the torque jumps where
    the path acceleration changes (the knots), so each window is also cut there. Where the joint
    damping is stiff (ρ = |eig H⁻¹D| along the motion above :data:`STABLE` / :data:`MAX_STEP`,
    e.g. xarm7's wrist: 1.5e4 1/s), the explicit method would need steps below 3/ρ; the
    three-stage Radau IIA collocation method (implicit, of order 5, 3 on stiff problems,
    :class:`_Collocation`) is used instead. Each window is integrated with steps no longer than
    :data:`MAX_STEP`, then again with every step halved, until two results differ by at most
    (2ᵖ − 1) × ``accuracy``, p = 5 (3 where stiff: the finer one's error is then about
    ``accuracy``, by Richardson's estimate) or :data:`MAX_HALVINGS` times. At most
    :data:`MAX_WINDOWS` windows are simulated, spread evenly over the motion with the last one
    always among them (a bounded cost however long the motion). The windows (and the first two
    step sizes of each) are integrated side by side, one batched ABA per Runge-Kutta stage
    (:class:`_Integrator`).
    Returns the simulated end state and the largest window defect.
    """
    te, knots = trajectory.duration, trajectory.t
    stiff = _damping_rate(robot, trajectory) * MAX_STEP > STABLE
    order = STIFF_ORDER if stiff else ORDER  # (Richardson's estimate)
    starts = np.arange(0.0, te, window)
    if starts.size > MAX_WINDOWS:
        starts = starts[np.unique(np.linspace(0, starts.size - 1, MAX_WINDOWS).round().astype(int))]
    ends = np.minimum(starts + window, te)
    cuts = [
        np.concatenate([[w0], knots[(knots > w0) & (knots < w1)], [w1]])
        for w0, w1 in zip(starts, ends, strict=True)
    ]
    first = _states(trajectory, starts)
    integrate = (
        _Collocation(robot, trajectory, MAX_STEP, NEWTON * accuracy)
        if stiff
        else _Integrator(robot, trajectory, MAX_STEP)
    )
    both = integrate([*cuts, *cuts], np.vstack([first, first]), [1] * len(cuts) + [2] * len(cuts))
    x, finer = both[: len(cuts)], both[len(cuts) :]
    open_ = np.arange(len(cuts))  # the windows whose last two results still differ
    for halving in range(1, MAX_HALVINGS + 1):
        close = np.max(np.abs(finer - x[open_]), axis=1) <= (2**order - 1) * accuracy
        x[open_] = finer
        open_ = open_[~close]
        if not open_.size or halving == MAX_HALVINGS:
            break
        finer = integrate([cuts[w] for w in open_], first[open_], [2 ** (halving + 1)] * open_.size)
    inner = np.flatnonzero(ends < te)
    defect = float(np.max(np.abs(x[inner] - _states(trajectory, ends[inner])), initial=0.0))
    return x[-1], defect


def _states(trajectory: Motion, t: NDArray[np.float64]) -> NDArray[np.float64]:
    """x = (θ, θ̇) of the motion at the times t, shape (len(t), 2n)."""
    if not t.size:
        return np.zeros((0, 2 * trajectory.states(np.zeros(1))[0].shape[1]))
    q, qd = trajectory.states(t)[:2]
    return np.hstack([q, qd])


# Dormand and Prince's fifth-order method (the fifth-order solution of DOPRI5; Hairer, Nørsett
# and Wanner, *Solving Ordinary Differential Equations I*, table II.5.2): the stages' nodes and
# coefficients, and the weights of the step
_NODES = np.array([0.0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1.0])
_COEFFICIENTS = np.array(
    [
        [0.0, 0.0, 0.0, 0.0, 0.0],
        [1 / 5, 0.0, 0.0, 0.0, 0.0],
        [3 / 40, 9 / 40, 0.0, 0.0, 0.0],
        [44 / 45, -56 / 15, 32 / 9, 0.0, 0.0],
        [19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729, 0.0],
        [9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656],
    ]
)
_WEIGHTS = np.array([35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84])
ORDER = 5
"""The order of the forward simulation's Runge-Kutta method."""
STIFF_ORDER = 3
"""The order Richardson's estimate assumes of Radau IIA where the damping is stiff: its stage
order (its classical order 5 drops towards it on stiff problems; measured ~3.3 on xarm7 with
stronger damping)."""


class _Integrator:
    """Runge-Kutta (Dormand-Prince, order 5) of several windows side by side
    (:meth:`__call__`), by Pinocchio's batched ABA."""

    def __init__(self, robot: Robot, trajectory: Motion, step: float) -> None:
        self.pool = robot.new_pool()
        self.damping = np.asarray(robot.damping, dtype=float)
        self.trajectory, self.step = trajectory, step

    def _steps(
        self, cuts: list[NDArray[np.float64]], splits: list[int]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Every lane's steps: their lengths (steps, lanes) and the times of their stages
        (steps, lanes, stages); a lane that has taken all its steps waits with steps of length
        0 (no torque is evaluated for them)."""
        lengths, starts = [], []
        for c, split in zip(cuts, splits, strict=True):
            inside = 1e-12 * np.maximum(1.0, c)  # a time just beyond a knot may round onto
            a, b = c[:-1] + inside[:-1], c[1:] - inside[1:]  # its other side
            m = split * np.maximum(1, np.ceil((b - a) / self.step)).astype(np.int64)
            h = np.repeat((b - a) / m, m)
            index = np.arange(m.sum()) - np.repeat(np.cumsum(m) - m, m)
            lengths.append(h)
            starts.append(np.repeat(a, m) + index * h)
        count = max(h.size for h in lengths)
        h_all = np.zeros((count, len(cuts)))
        t_all = np.zeros((count, len(cuts)))
        for lane, (h, t0) in enumerate(zip(lengths, starts, strict=True)):
            h_all[: h.size, lane], t_all[: h.size, lane] = h, t0
        return h_all, t_all[:, :, None] + h_all[:, :, None] * _NODES[None, None, :]

    def __call__(
        self, cuts: list[NDArray[np.float64]], x: NDArray[np.float64], splits: list[int]
    ) -> NDArray[np.float64]:
        """Every lane from the state x[l] at cuts[l][0] to cuts[l][-1], on every piece between
        the cuts (each started and ended just inside, where the torque may jump) in
        ``splits[l]`` times as many equal steps as keep them no longer than the step; the
        torques at every stage time from one batched call. At most :data:`LANES` lanes at a
        time (the torques of every stage of every lane are held together). Returns the end
        states (lanes, 2n)."""
        if len(cuts) > LANES:
            return np.vstack(
                [
                    self(cuts[i : i + LANES], x[i : i + LANES], splits[i : i + LANES])
                    for i in range(0, len(cuts), LANES)
                ]
            )
        n, lanes = x.shape[1] // 2, len(cuts)
        h_all, times = self._steps(cuts, splits)
        stages = _NODES.size
        # (steps, stages, n, lanes): ABA takes joints along the first axis, lanes along the second
        u = np.zeros((*times.shape, n))
        u[h_all > 0.0] = self.trajectory.torque(times[h_all > 0.0].ravel()).reshape(-1, stages, n)
        u = u.transpose(0, 2, 3, 1)
        state = np.ascontiguousarray(x.T)  # (2n, lanes): θ over θ̇
        slopes = np.zeros((stages, 2 * n, lanes))  # θ̇ over θ̈ at each stage
        at, tau = np.zeros((2 * n, lanes)), np.zeros((n, lanes))
        acceleration = np.zeros((n, lanes))
        damping, pool, aba = self.damping, self.pool, pin.abaInParallel
        q, v = at[:n], at[n:]
        for k in range(h_all.shape[0]):
            h, uk = h_all[k], u[k]
            for i in range(stages):
                stage(state, slopes, _COEFFICIENTS, i, h, uk[i], damping, acceleration, at, tau)
                acceleration = aba(1, pool, q, v, tau).reshape(n, lanes)
            advance(state, slopes, _WEIGHTS, h, acceleration)
        return state.T


# the three-stage Radau IIA method (order 5; Hairer and Wanner, *Solving Ordinary Differential
# Equations II*, table IV.5.6): its nodes, behind the step's start, and coefficients
_RADAU_NODES = np.array([0.0, (4 - np.sqrt(6)) / 10, (4 + np.sqrt(6)) / 10, 1.0])
_RADAU = np.array(
    [
        [(88 - 7 * np.sqrt(6)) / 360, (296 - 169 * np.sqrt(6)) / 1800, (-2 + 3 * np.sqrt(6)) / 225],
        [(296 + 169 * np.sqrt(6)) / 1800, (88 + 7 * np.sqrt(6)) / 360, (-2 - 3 * np.sqrt(6)) / 225],
        [(16 - np.sqrt(6)) / 36, (16 + np.sqrt(6)) / 36, 1 / 9],
    ]
)
JACOBIAN_EVERY = 4
"""Steps of the implicit forward simulation between two evaluations of its Newton matrix's
damping part H⁻¹D (H changes little over a few steps; Newton's convergence is measured)."""


class _Collocation(_Integrator):
    """The three-stage Radau IIA method (implicit, order 5, L-stable) of several windows side
    by side, for an arm whose joint damping is stiff: a step's stage increments Z_i = x(t₀ +
    c_i h) − x(t₀) solve Z = h (A ⊗ I) f(x₀ + Z) by simplified Newton iterations, whose matrix
    holds the stiff part of ∂f/∂x, the damping's ∂θ̈/∂θ̇ = −H⁻¹D (evaluated every
    :data:`JACOBIAN_EVERY` steps by ABA). The iterations start from the motion's own states at
    the stages (where the arm should be; the fixed point they converge to does not depend on
    it) and stop where the error they leave, estimated from their rate of contraction
    (Hairer and Wanner's rule), is below ``tolerance`` [rad, rad/s]; a lane that does not
    contract ends in NaN (its check fails)."""

    def __init__(self, robot: Robot, trajectory: Motion, step: float, tolerance: float) -> None:
        super().__init__(robot, trajectory, step)
        self.tolerance = tolerance

    def __call__(
        self, cuts: list[NDArray[np.float64]], x: NDArray[np.float64], splits: list[int]
    ) -> NDArray[np.float64]:
        """As :meth:`_Integrator.__call__`, by Radau IIA."""
        if len(cuts) > LANES:
            return np.vstack(
                [
                    self(cuts[i : i + LANES], x[i : i + LANES], splits[i : i + LANES])
                    for i in range(0, len(cuts), LANES)
                ]
            )
        n = x.shape[1] // 2
        h_all, times = self._steps(cuts, splits)
        times = times[..., :1] + h_all[..., None] * _RADAU_NODES  # (steps, lanes, 4)
        live = h_all > 0.0
        planned = np.zeros((*times.shape, 2 * n))  # the motion's states: the iterations' start
        planned[live] = np.hstack(self.trajectory.states(times[live].ravel())[:2]).reshape(
            -1, 4, 2 * n
        )
        u = np.zeros((*times.shape[:2], 3, n))
        u[live] = self.trajectory.torque(times[live][:, 1:].ravel()).reshape(-1, 3, n)
        state, rate = x.copy(), np.zeros((x.shape[0], n, n))
        contraction = np.ones(x.shape[0])  # each lane's last η = θ/(1 − θ) (Hairer, Wanner)
        for k in range(h_all.shape[0]):
            lanes = np.flatnonzero(live[k] & np.isfinite(contraction))  # (NaN: failed)
            if not lanes.size:
                continue
            if k % JACOBIAN_EVERY == 0:
                rate[lanes] = self._damping_rates(state[lanes, :n])
            z = planned[k, lanes, 1:] - planned[k, lanes, :1]
            z, contraction[lanes] = self._newton(
                state[lanes], z, h_all[k, lanes], u[k, lanes], rate[lanes], contraction[lanes]
            )
            state[lanes] += z[:, 2]
        return state

    def _damping_rates(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """H(θ)⁻¹D at each θ of ``q`` (lanes, n): ∂θ̈/∂θ̇'s damping part is its negative; from
        one batched ABA, H⁻¹ (D e_j − g) − H⁻¹(−g) at θ̇ = 0 [1/s], shape (lanes, n, n)."""
        lanes, n = q.shape
        torques = np.zeros((lanes, n + 1, n))
        torques[:, 1:] = np.diag(self.damping)
        at = np.ascontiguousarray(np.repeat(q, n + 1, axis=0).T)
        a = pin.abaInParallel(
            1, self.pool, at, np.zeros_like(at), np.ascontiguousarray(torques.reshape(-1, n).T)
        )
        a = a.T.reshape(lanes, n + 1, n)
        return (a[:, 1:] - a[:, :1]).transpose(0, 2, 1)

    def _newton(
        self,
        x0: NDArray[np.float64],
        z: NDArray[np.float64],
        h: NDArray[np.float64],
        u: NDArray[np.float64],
        rate: NDArray[np.float64],
        contraction: NDArray[np.float64],
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The stage increments Z (lanes, 3, 2n) of one step from x0 (lanes, 2n), Z's start
        ``z``, the steps h, the stages' torques u (lanes, 3, n) and the damping's H⁻¹D; and
        each lane's estimated contraction for its next step (from its last one's, ``contraction``;
        NaN for a lane that did not contract). The Newton matrix I − h A ⊗ ∂f/∂x, with ∂f/∂x =
        [[0, I], [0, −H⁻¹D]], is solved for the θ̇ parts (I + h A ⊗ H⁻¹D, 3n × 3n) and the θ
        parts follow: Δθ = −r_θ + h (A ⊗ I) Δθ̇. Each lane stops on its own."""
        lanes, n = u.shape[0], u.shape[2]
        ha = h[:, None, None] * _RADAU  # (lanes, 3, 3)
        matrix = np.eye(3 * n) + (ha[:, :, None, :, None] * rate[:, None, :, None, :]).reshape(
            lanes, 3 * n, 3 * n
        )
        inverse = np.linalg.inv(matrix)
        # the last step's η, a little more cautious (Hairer and Wanner: max(η, uround)^0.8)
        eta = np.maximum(contraction, np.finfo(float).eps) ** 0.8
        last = np.full(lanes, np.inf)
        going = np.arange(lanes)  # the lanes still iterating
        for _ in range(MAX_NEWTON):
            g = going
            at = x0[g, None, :] + z[g]  # (lanes, 3, 2n)
            q, v = at[..., :n].reshape(-1, n), at[..., n:].reshape(-1, n)
            tau = u[g].reshape(-1, n) - self.damping * v
            a = pin.abaInParallel(
                1, self.pool, np.ascontiguousarray(q.T), np.ascontiguousarray(v.T),
                np.ascontiguousarray(tau.T),
            ).T.reshape(g.size, 3, n)  # fmt: skip
            r_q = z[g, :, :n] - np.einsum("lij,ljb->lib", ha[g], at[..., n:])
            r_v = z[g, :, n:] - np.einsum("lij,ljb->lib", ha[g], a)
            dv = -np.einsum("lab,lb->la", inverse[g], r_v.reshape(g.size, -1))
            dv = dv.reshape(g.size, 3, n)
            dq = -r_q + np.einsum("lij,ljb->lib", ha[g], dv)
            z[g, :, :n] += dq
            z[g, :, n:] += dv
            size = np.maximum(np.abs(dq).max(axis=(1, 2)), np.abs(dv).max(axis=(1, 2)))
            theta = size / last[g]  # (inf before the second iteration: 0)
            failed = ~np.isfinite(size) | ~(theta < 1.0)  # no contraction, or NaN
            measured = np.isfinite(last[g]) & ~failed
            eta[g[measured]] = theta[measured] / (1.0 - theta[measured])
            done = ~failed & ((eta[g] * size <= self.tolerance) | (size == 0.0))
            z[g[failed]] = np.nan
            eta[g[failed]] = np.nan
            last[g] = size
            going = g[~failed & ~done]
            if not going.size:
                return z, eta
        z[going] = np.nan
        eta[going] = np.nan
        return z, eta


def _damping_rate(robot: Robot, trajectory: Motion) -> float:
    """ρ = max |eig(H⁻¹D)| [1/s] over 9 configurations along the motion (0: no damping)."""
    if not np.any(robot.damping):
        return 0.0
    damping = np.diag(robot.damping)
    configurations = trajectory.states(np.linspace(0.0, trajectory.duration, 9))[0]
    return max(
        float(np.max(np.abs(np.linalg.eigvals(np.linalg.solve(robot.mass_matrix(q), damping)))))
        for q in configurations
    )
