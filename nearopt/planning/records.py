"""The records of a plan: methods and their options, its iterates and its result.

The bottom of the planning package: every other module of it imports from here, nothing here
imports from them.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, fields
from enum import StrEnum
from typing import TYPE_CHECKING, Any, Literal, Protocol, runtime_checkable

import numpy as np

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from ..collision import Clearance, CollisionModel, Scene
    from ..cost import Cost
    from ..path import Path
    from ..robot import Robot
    from ..robot.kinematics import ToolPose
    from ..timing import JerkTimingResult, SmoothTrajectory, TimingResult
    from ..trajectory import Trajectory
    from ..verify import Waypoint

__all__ = [
    "MAX_CONTROL_POINTS",
    "Segment",
    "Method",
    "StopReason",
    "SCPOptions",
    "PaperOptions",
    "PlanSettings",
    "Iteration",
    "MethodOutcome",
    "PlanResult",
]


MAX_CONTROL_POINTS = 200  # interior B-spline control points; the convex model grows with K·n


class Method(StrEnum):
    """How stage 2 improves the path."""

    SCP = "scp"
    """Sequential convex programming on a B-spline path (the default; see
    :mod:`nearopt.planning.scp`)."""
    PAPER = "paper"
    """The paper's update of Section 6: torque gradient, improved torques, boundary-value problem
    (see :mod:`nearopt.planning.paper`)."""


class StopReason(StrEnum):
    """Why the planner stopped; :attr:`PlanResult.message` says it in words, with figures."""

    CONVERGED = "converged"
    """No better path within the method's tolerance (a stationary point, to first order)."""
    ITERATION_LIMIT = "iteration limit"
    """``max_iterations`` accepted iterates (0: the straight line only)."""
    TIME_LIMIT = "time limit"
    """``time_limit`` seconds spent; the best path so far is returned."""
    NO_PROGRESS = "no progress"
    """The method found no step that lowers J although it is not converged (the paper's update
    at its α and Δt search limits)."""
    SOLVER = "solver failure"
    """A convex subproblem could not be solved; the best path so far is returned."""
    INTERRUPTED = "interrupted"
    """Ctrl-C (KeyboardInterrupt) during planning; the best path so far is returned."""


@dataclass(frozen=True)
class SCPOptions:
    """Options of ``method="scp"``.

    Attributes
    ----------
    control_points
        K, the interior control points of the B-spline path (2 ≤ K ≤ 200).
    knots
        Where the B-spline's interior knots lie: ``"clustered"`` at the rest ends like stage 1's
        grid (σ = ½(1 − cos πx), x uniform: where a motion starts and stops, its path bends most)
        or ``"uniform"``; a moving end (``qd0``, ``qde``) is never clustered
        (:func:`~nearopt.planning.scp.knot_breaks`).
    grid
        Stage 1's grid while the path is optimised (≥ 2); the plan's own grid (``plan(grid=)``)
        times the returned path. Optimising on a coarser grid is several times faster and moves
        the optimum little (J on the two grids differs by O(1/N²)). It is raised to 4 segments
        per control point (at most the plan's grid): with fewer, the grid cannot see what one
        control point changes and stage 2 stalls near the straight line (measured: panda,
        48 control points on 64 segments).
    trust_radius
        The first trust radius ρ: how far θ' may move in one step, a fraction of each joint's
        scale (its motion |θe_i − θ0_i|, at least 10 % of its range and 0.1 rad).
    min_trust_radius
        Stop when ρ falls below this fraction.
    tolerance
        Stop when the convex model predicts a relative decrease of J below this, or J changed by
        less than this in each of the last 3 iterations.
    refinements
        After stage 2 stops (converged), the path's knots are refined this many times — a knot
        in the middle of every other span, the path itself unchanged (knot insertion), K → about
        1.5 K — and stage 2 goes on from it: the path's resolution, not the method, is most of
        what is left to an independent optimum (0.07–0.3 % lower J on ur5 and panda for 15–30 %
        more time). 0 keeps K. Not under jerk or torque-rate limits (a finer path found
        without them fared worse under them; stage 2 under the limits goes on instead).
    continuation
        A second start for a torque cost (f0 = 1 + Σ w u², some w > 0): stage 2 from the
        straight line under the weights times this, coarse (K/2 control points on a 32-segment
        grid, no refinement), at the same time as the first run on another core; where its path
        timed under the cost itself has a lower J than the first run's plan, stage 2 goes on from
        it and the lower J is returned. Heavier weights are the Lagrangian of a longer duration:
        they find the slow motions that hold the arm against gravity less, which stage 2 from
        the line, among the fastest, does not reach (ur5: 4 of 16 seeded motions 7–26 % lower).
        Rest-to-rest joint-space plans without obstacles, via-points, a tool-pose goal, a
        duration or jerk limits; 1 switches it off.
    """

    control_points: int = 16
    knots: Literal["clustered", "uniform"] = "clustered"
    grid: int = 64
    trust_radius: float = 1.0
    min_trust_radius: float = 1e-6
    tolerance: float = 1e-4
    refinements: int = 1
    continuation: float = 3.0


@dataclass(frozen=True)
class PaperOptions:
    """Options of ``method="paper"`` (Section 6's update).

    Attributes
    ----------
    gamma
        γ of eq. (33), the weight of the terminal penalty F in the gradient.
    alpha
        The first α of eq. (22); it is searched from there.
    delta_t
        The first Δt of eq. (27), a fraction of t_e.
    trials
        Trials of α and Δt per iteration before it stops.
    tolerance
        Stop when an iteration lowers J by less than this fraction.
    """

    gamma: float = 0.1
    alpha: float = 0.3
    delta_t: float = 0.1
    trials: int = 8
    tolerance: float = 1e-7


@dataclass(frozen=True)
class Segment:
    """One rest-to-rest plan, its arguments checked (the goal configuration found, the
    collision model built): what each phase of :func:`~nearopt.plan` reads (the first path,
    stage 2, the result)."""

    robot: Robot
    q0: NDArray[np.float64]
    qe: NDArray[np.float64]
    goal: ToolPose | None
    cost: Cost
    method: Method
    options: SCPOptions | PaperOptions
    grid: int
    max_iterations: int
    velocity_limits: bool
    position_limits: bool
    collisions: CollisionModel | None
    vias: list[NDArray[np.float64]]
    optimise_goal: bool
    t_start: float
    deadline: float
    duration: tuple[float, bool] | None = None  # (T, exact): t_e = T, or t_e ≤ T
    ends: tuple[NDArray[np.float64] | None, NDArray[np.float64] | None] = (None, None)
    via_poses: tuple[ToolPose | None, ...] = ()  # per via-point: the tool pose it was given as


@dataclass(frozen=True)
class PlanSettings:
    """How to plan, as one record: the keywords of :func:`~nearopt.plan` (see there for each)
    that every rest-to-rest plan shares; :func:`~nearopt.plan_task` takes it for all its
    segments (``max_iterations`` then per segment, ``time_limit`` [s] for the whole task).
    """

    method: Method | str | None = None
    options: SCPOptions | PaperOptions | None = None
    grid: int = 200
    max_iterations: int = 200
    time_limit: float = 300.0
    velocity_limits: bool = True
    position_limits: bool = True
    scene: Scene | CollisionModel | None = None
    margin: float | None = None
    self_collision: bool | None = None
    optimise_goal: bool = True

    def keywords(self) -> dict[str, Any]:
        """The settings as :func:`~nearopt.plan`'s keyword arguments."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


@dataclass(frozen=True)
class Iteration:
    """One accepted iterate j of the planner (a row of the paper's Table 2).

    Attributes
    ----------
    index
        j; 0 is the straight line.
    J
        Stage 1's optimal cost of the iterate's path on the grid (the discretised J^j). With
        jerk or torque-rate limits, the iterates from the second with ``alpha`` None on are
        stage 2 under those limits (:func:`~nearopt.planning.smooth_iterations`): J (and t_e)
        under them, its first the path it starts from.
    alpha
        The step that produced it: α of eq. (22) for ``"paper"``; for ``"scp"`` the largest
        control-point move [rad]. None for j = 0 (and where stage 2 under jerk limits starts).
    duration
        t_e of the iterate's optimal timing [s].
    wall_time
        Seconds since the planner started.
    path
        The iterate's path θ^j(s) (from θ0 to θe exactly).
    """

    index: int
    J: float
    alpha: float | None
    duration: float
    wall_time: float
    path: Path


@dataclass(frozen=True)
class MethodOutcome:
    """Where a path update stopped.

    Attributes
    ----------
    timing
        Stage 1 on the best path (the last accepted iterate).
    reason
        Why it stopped.
    message
        The same in words, with the figures.
    evaluations
        Stage-1 solves spent (the straight line's included).
    """

    timing: TimingResult
    reason: StopReason
    message: str
    evaluations: int


@dataclass(frozen=True)
class PlanResult:
    """A planned motion and how it was found.

    Attributes
    ----------
    robot
        The arm it was planned for (with the limits that were enforced).
    timing
        Stage 1 on the returned path: the motion, its J and t_e.
    initial
        Stage 1 on the straight line (the paper's J^0).
    history
        The accepted iterates, the straight line first.
    method
        The path update used.
    status
        Why it stopped.
    message
        The same in words, with the figures.
    evaluations
        Stage-1 solves spent.
    wall_time
        Seconds spent in total.
    collisions
        The bodies kept apart and the margin, when collisions were checked.
    clearance
        The certified clearance of the returned path (the closest pair, where), when checked.
    goal
        The tool pose the goal configuration was found for, when the goal was one.
    via
        The via-points passed through [rad or m], each (n,): a tool-pose via-point's the
        configuration the returned path has there (it moves along the pose in stage 2).
    via_s
        The path parameters where the path passes them.
    jerk_timing
        Where the robot has jerk or torque-rate limits: the returned path timed under them
        (C¹, θ̈ = 0 at rest; :func:`~nearopt.timing.time_with_jerk_limits`). It is the
        motion, J and t_e of the plan; ``timing`` is then stage 1's timing of the same path
        without them.
    duration_asked
        The duration asked for [s] and whether exactly (t_e = T) or at most (t_e ≤ T); None.
    qd0, qde
        The joint velocities asked for at the start and the end [rad/s or m/s]; None: at rest.
    via_poses
        Per via-point, the tool pose it was given as (None: a joint vector); verified as a pose.
    """

    robot: Robot
    timing: TimingResult
    initial: TimingResult
    history: tuple[Iteration, ...]
    method: Method
    status: StopReason
    message: str
    evaluations: int
    wall_time: float
    collisions: CollisionModel | None = None
    clearance: Clearance | None = None
    goal: ToolPose | None = None
    via: tuple[NDArray[np.float64], ...] = ()
    via_s: tuple[float, ...] = ()
    jerk_timing: JerkTimingResult | None = None
    duration_asked: tuple[float, bool] | None = None
    qd0: NDArray[np.float64] | None = None
    qde: NDArray[np.float64] | None = None
    via_poses: tuple[ToolPose | None, ...] = ()

    @property
    def final(self) -> TimingResult | JerkTimingResult:
        """The returned timing: the jerk-limited one where there is one, else stage 1's."""
        return self.timing if self.jerk_timing is None else self.jerk_timing

    @property
    def via_times(self) -> NDArray[np.float64]:
        """When the motion passes each via-point [s], shape (len(via),)."""
        return self.trajectory.time_at(np.asarray(self.via_s, dtype=float))

    @property
    def waypoints(self) -> tuple[Waypoint, ...]:
        """The via-points as :func:`~nearopt.verify` checks them (passed, not stopped at)."""
        from ..verify import Waypoint

        poses = self.via_poses or (None,) * len(self.via)
        return tuple(
            Waypoint(float(t), q, pose=pose)
            for t, q, pose in zip(self.via_times, self.via, poses, strict=True)
        )

    @property
    def initial_trajectory(self) -> Trajectory:
        """The first path (the straight line, or OMPL's) timed by stage 1."""
        return self.initial.trajectory

    @property
    def parts(self) -> tuple[PlanResult, ...]:
        """The rest-to-rest plans it is made of: itself."""
        return (self,)

    @property
    def iterations(self) -> int:
        """Stage-2 iterations accepted (the first path not counted)."""
        return len(self.history) - 1

    @property
    def initial_J(self) -> float:  # noqa: N802 - the paper's name
        """J of :attr:`initial_trajectory` (the paper's J^0)."""
        return self.initial.J

    @property
    def trajectory(self) -> Trajectory | SmoothTrajectory:
        """The motion: θ(t), θ̇(t), θ̈(t), u(t) on [0, t_e], from rest at θ0 to rest at θe."""
        return self.final.trajectory

    @property
    def path(self) -> Path:
        """Its spatial path θ(s)."""
        return self.timing.trajectory.path

    @property
    def cost(self) -> Cost:
        """The running cost f0 that was minimised."""
        return self.timing.cost

    @property
    def J(self) -> float:  # noqa: N802 - the paper's name
        """∫ f0 dt of the returned motion (adaptive Gauss-Kronrod over the exact timing)."""
        return self.final.J

    @property
    def duration(self) -> float:
        """t_e [s]."""
        return self.final.duration


@runtime_checkable
class Plan(Protocol):
    """What a single plan (:class:`PlanResult`) and a task (:class:`~nearopt.TaskResult`) both
    are: a verified motion of a robot, its cost, how planning stopped, its targets on the way."""

    @property
    def robot(self) -> Robot: ...

    @property
    def trajectory(self) -> Trajectory: ...

    @property
    def J(self) -> float: ...  # noqa: N802 - the paper's name

    @property
    def duration(self) -> float: ...

    @property
    def cost(self) -> Cost: ...

    @property
    def status(self) -> StopReason: ...

    @property
    def collisions(self) -> CollisionModel | None: ...

    @property
    def clearance(self) -> Clearance | None: ...

    @property
    def goal(self) -> ToolPose | None: ...

    @property
    def waypoints(self) -> tuple[Waypoint, ...]: ...

    @property
    def initial_J(self) -> float: ...  # noqa: N802

    @property
    def parts(self) -> tuple[PlanResult, ...]: ...

    @property
    def iterations(self) -> int: ...


@dataclass(frozen=True)
class Run:
    """A stage-2 loop's budget and where its iterates go (both loops take one).

    Attributes
    ----------
    max_iterations
        Accepted iterates at most.
    deadline
        ``time.perf_counter()`` value after which no new iteration starts [s].
    t_start
        When planning started (for the iterates' wall times) [s].
    accept
        Called with every accepted iterate and its timing, iterate 0 first.
    """

    max_iterations: int
    deadline: float
    t_start: float
    accept: Callable[[Iteration, TimingResult], None]

    def out_of_time(self) -> bool:
        """Whether the deadline has passed."""
        return time.perf_counter() > self.deadline

    def report(self, index: int, timing: TimingResult, step: float | None, path: Path) -> None:
        """Accept iterate ``index``: its J (the discretised objective), step, t_e, wall time."""
        self.accept(
            Iteration(
                index,
                timing.objective,
                step,
                timing.duration,
                time.perf_counter() - self.t_start,
                path,
            ),
            timing,
        )
