"""The planner of Section 6: from the straight joint line, improve the path until it converges.

Every iterate is a path from θ0 to θe exactly, timed optimally by stage 1 (so it is feasible, at
rest at both ends, and the computation can stop at any time with the best plan so far). The path
update (stage 2) is one of :class:`~nearopt.planning.Method`:

``"scp"`` (default)
    Sequential convex programming on a clamped cubic B-spline path
    (:mod:`nearopt.planning.scp`): stage 1's convex program with every row linearised in the
    path, solved jointly in the path step and the timing within a trust region, the new path
    re-timed exactly.
``"paper"``
    The update of Section 6 (:mod:`nearopt.planning.paper`): the gradient η(t) of eq. (27) with
    respect to the torques, improved torques u* = u − αη clipped to the limits (eqs. 22, 30), the
    next path from the two-point boundary-value problem (eq. 20), for +Δt and −Δt, the better
    kept; α and Δt are searched instead of set by hand.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from ..collision import Clearance, CollisionModel, Scene, collisions_for
from ..cost import Cost, TimeCost, TorqueCost, check_cost
from ..errors import (
    ConfigurationError,
    InfeasiblePathError,
    NearoptError,
    SolverError,
    UnreachablePoseError,
)
from ..parallel import beside
from ..path import BSplinePath, Path, StraightPath
from ..robot import Robot
from ..robot.kinematics import ToolPose, inverse_kinematics
from ..timing import (
    AS_FAST,
    MAX_GRID,
    JerkTimingResult,
    TimingResult,
    as_fast_as,
    check_duration,
    optimal_timing,
    time_with_jerk_limits,
)
from ..validate import is_number
from .ends import check_at_limits, check_velocities, turned_onto
from .paper import paper_iterations
from .records import (
    MAX_CONTROL_POINTS,
    Iteration,
    Method,
    MethodOutcome,
    PaperOptions,
    PlanResult,
    Run,
    SCPOptions,
    Segment,
    StopReason,
)
from .scp import iterate_grid, knot_breaks, sequential_convex
from .smooth import smooth_iterations
from .start import first_path, position_bounds, resting_ends

if TYPE_CHECKING:
    from numpy.typing import ArrayLike, NDArray

__all__ = ["plan", "METHODS", "MAX_CONTROL_POINTS", "MAX_DURATION", "minimum_duration"]

METHODS = tuple(m.value for m in Method)


MAX_DURATION = 1e9
"""[s] The longest motion planned (31 years): a longer one comes from limits that are wrong."""


def minimum_duration(
    robot: Robot, q0: ArrayLike, qe: ArrayLike, velocity_limits: bool = True
) -> tuple[float, int]:
    """A lower bound on the duration of any motion from rest at q0 to rest at qe [s], and the
    joint that sets it: joint i moves by at least |qe_i − q0_i|, no faster than its speed limit
    (|Δθ|/v) and, with an acceleration limit a, no sooner than 2√(|Δθ|/a) from rest to rest."""
    lim = robot.limits
    move = np.abs(np.asarray(qe, dtype=float) - np.asarray(q0, dtype=float))
    with np.errstate(divide="ignore", invalid="ignore"):
        speed = move / lim.velocity if velocity_limits else np.zeros_like(move)
        accel = 2.0 * np.sqrt(move / lim.acceleration)
    bound = np.nan_to_num(np.maximum(speed, accel), nan=0.0, posinf=np.inf)
    joint = int(np.argmax(bound))
    return float(bound[joint]), joint


def plan(
    robot: Robot,
    q0: ArrayLike,
    qe: ArrayLike | ToolPose,
    cost: Cost | None = None,
    *,
    method: Method | str | None = None,
    options: SCPOptions | PaperOptions | None = None,
    grid: int = 200,
    max_iterations: int = 200,
    time_limit: float = 300.0,
    velocity_limits: bool = True,
    position_limits: bool = True,
    callback: Callable[[Iteration], None] | None = None,
    verbose: bool = False,
    scene: Scene | CollisionModel | None = None,
    margin: float | None = None,
    self_collision: bool | None = None,
    optimise_goal: bool = True,
    via: Sequence[ArrayLike | ToolPose] | None = (),
    duration: float | None = None,
    max_duration: float | None = None,
    qd0: ArrayLike | None = None,
    qde: ArrayLike | None = None,
) -> PlanResult:
    """Plan a near-optimum motion from θ0 to θe, at rest at both by default (Sections 4-6).

    Parameters
    ----------
    robot
        The arm; its torque (and by default speed and position, and any acceleration) limits are
        enforced.
    q0, qe
        Start and goal configurations θ0, θe [rad or m], shape (n,); the goal may be a
        :class:`~nearopt.ToolPose` (a placement of a frame), reached by inverse kinematics from
        θ0 within the position limits (:func:`~nearopt.robot.kinematics.inverse_kinematics`).
    cost
        The running cost f0 (default: :class:`~nearopt.TimeCost`). ``"scp"`` needs a
        :class:`~nearopt.TorqueCost` (time, the paper's eq. 32, per-joint weights).
    method
        The path update, ``"scp"`` or ``"paper"`` (see the module docstring); default: ``"scp"``
        for the built-in costs, ``"paper"`` for a :class:`~nearopt.CallableCost`.
    options
        The method's options (:class:`SCPOptions` or :class:`PaperOptions`); default: theirs.
    grid
        N, stage 1's grid segments at every iteration.
    max_iterations
        Iteration budget (accepted iterates); 0 times the straight line only (stage 1).
    time_limit
        Wall-time budget [s]: no iteration starts after it; the best plan so far is returned.
    velocity_limits, position_limits
        Enforce the robot's joint speed / position limits.
    callback
        Called with every accepted :class:`Iteration`, the straight line first.
    scene
        Obstacles (a :class:`~nearopt.collision.Scene`, or a ready
        :class:`~nearopt.collision.CollisionModel`): every link keeps ``margin`` from them and,
        with ``self_collision``, from the other links, along the whole path (certified between
        checks). If the straight line collides, OMPL's RRT-Connect gives the first path.
    margin
        The clearance [m] (default: the scene's, :data:`~nearopt.collision.DEFAULT_MARGIN`).
    self_collision
        Keep the robot's links apart (default: when a scene is given; ``True`` without a scene
        checks self-collision only).
    optimise_goal
        With a :class:`~nearopt.ToolPose` goal and ``"scp"``: θe moves with the path among the
        configurations that hold the pose (its step in the null space of the frame's Jacobian,
        projected back by inverse kinematics), so a redundant arm ends where J is lowest; so
        does the configuration of every tool-pose via-point. False keeps inverse kinematics'
        θe and via-point configurations.
    via
        Via-points passed through without stopping, in order: joint vectors or
        :class:`~nearopt.ToolPose` (inverse kinematics from the previous point). The path goes
        through each exactly at every iterate (at the σ of the polyline's arc length); stage 1
        times the whole path. ``"scp"`` only.
    duration, max_duration
        t_e = ``duration`` exactly, or t_e ≤ ``max_duration`` [s] (one or neither), J of a
        :class:`~nearopt.TimeCost` or :class:`~nearopt.TorqueCost` minimised under it. Stage 1
        meets it exactly (:mod:`nearopt.timing.duration`); every stage-2 iterate is timed
        under it, and the convex model keeps t_e, linearised at the iterate's timing, at T.
        Where the first path cannot be as fast as T, stage 2 starts from the path it finds
        for the time-optimal cost; stage 2 also runs from the plan without the duration where
        that path can be as fast, and the lower J is returned. ``"scp"`` only; not with jerk
        limits. ``max_duration=inf`` is no limit.
    qd0, qde
        The joint velocities θ̇(0) and θ̇(t_e) [rad/s or m/s], shape (n,); None (or zeros): at
        rest there. Every path leaves θ0 along qd0 and reaches θe along qde (its first and last
        interior control points on those rays, :mod:`nearopt.planning.ends`), and stage 1 times
        it with b_0 = (qd0·θ'/|θ'|²)²; the first path is the straight line with those ends (its
        end legs turned along them). Within the speed limits; ``"scp"`` only; not yet with
        via-points, obstacles or jerk or torque-rate limits.

    Returns
    -------
    PlanResult
        The best plan found; a KeyboardInterrupt (Ctrl-C) during the iterations ends them with
        the best plan so far (status ``StopReason.INTERRUPTED``).
    verbose
        Print one line per iteration.

    Raises
    ------
    ConfigurationError
        On a bad argument (wrong length, NaN, outside the position limits, unknown method, …).
    InfeasiblePathError
        If the straight line itself cannot be timed (gravity exceeds a limit along it).
    UnreachablePoseError
        If no configuration within the limits puts the frame at a goal pose (the message says
        how far the closest is, in metres and radians).
    CollisionError
        If the start or the goal is closer than the margin (naming the pair and the distance),
        or no collision-free path was found within the time limit.
    """
    t_start = time.perf_counter()
    if callback is not None and not callable(callback):
        raise ConfigurationError(
            f"callback must be a function of one Iteration, got {type(callback).__name__} "
            f"{callback!r:.60}"
        )
    setup = _setup(
        robot,
        q0,
        qe,
        cost,
        method,
        options,
        grid,
        max_iterations,
        time_limit,
        velocity_limits,
        position_limits,
        scene,
        margin,
        self_collision,
        optimise_goal,
        via,
        t_start,
    )
    if is_number(max_duration) and float(max_duration) == math.inf:  # type: ignore[arg-type]
        max_duration = None  # no limit (as time_limit = inf)
    if duration is not None or max_duration is not None:
        setup = replace(setup, duration=_check_duration(setup, duration, max_duration))
    if qd0 is not None or qde is not None:
        setup = replace(setup, ends=_check_ends(setup, qd0, qde))
    _check_moves(setup)
    initial, outcome, via_s = _within_limit(setup, callback, verbose)
    timing, reason, message, evaluations, history = outcome
    if setup.robot.limits.smooth:  # stage 2 goes on under the jerk (torque-rate) limits

        def report(entry: Iteration) -> None:
            history.append(entry)
            if verbose:
                print(_format(entry), flush=True)
            if callback is not None:
                callback(entry)

        smooth = _under_jerk_limits(setup, timing, initial, message)
        stage_2 = (reason, len(history))
        timing, jerk, message, reason = _smoothed(setup, smooth, report, stage_2, via_s)
        return _result(setup, timing, initial, history, (reason, message), evaluations, via_s, jerk)
    return _result(setup, timing, initial, history, (reason, message), evaluations, via_s)


Outcome = tuple[TimingResult, StopReason, str, int, list[Iteration]]
"""A stage-2 run's outcome: the timing, why it stopped, the message, the stage-1 solves spent and
the accepted iterates."""


def _within_limit(
    setup: Segment, callback: Callable[[Iteration], None] | None, verbose: bool
) -> tuple[TimingResult, Outcome, tuple]:
    """:func:`_planned`; under t_e ≤ T (``max_duration``) that stage 1 refuses by no more than
    its accuracy (:data:`~nearopt.timing.AS_FAST`), the plan without the limit where its own t_e
    keeps it (an unconstrained optimum that meets the limit is the constrained one): a ur5
    time-optimal re-plan asked for its own t_e as max_duration was refused, another solve of
    its path being 1.5e-11 slower (stage 1 is solved to 1e-9, t_e ≤ T holds to 1e-12)."""
    try:
        return _planned(setup, callback, verbose)
    except InfeasiblePathError as exc:
        limit = None if setup.duration is None or setup.duration[1] else setup.duration[0]
        if limit is None or exc.excess is None or exc.excess > AS_FAST * limit:
            raise  # (the fastest motion found is slower than T by more than stage 1's accuracy:
            # the plan without the limit, no faster, would not keep it)
        refused = exc
    try:
        free = _planned(replace(setup, duration=None), callback, verbose)
    except (InfeasiblePathError, SolverError):
        raise refused from None
    if free[1][0].duration > setup.duration[0]:
        raise refused
    timing, reason, message, spent, history = free[1]
    note = f"{message}; the plan without max_duration, whose t_e keeps it"
    return free[0], (timing, reason, note, spent, history), free[2]


def _planned(
    setup: Segment, callback: Callable[[Iteration], None] | None, verbose: bool
) -> tuple[TimingResult, Outcome, tuple]:
    """The checked request planned: the first path timed, stage 2's outcome (the better of the
    runs it takes) and the via-points' σ."""
    line, start, via_s = first_path(setup)
    first = (line, start)  # the plan without a duration starts from it
    run = setup  # (under a duration, maybe on the plan's grid: see _fast_enough)
    if setup.duration is not None:
        run, line, start = _fast_enough(setup, line, start, via_s)
    initial = _time_first_path(run, line, start)
    outcome = _lowest(run, *_starts(run, line, start, via_s, initial, callback, verbose))
    again = setup.max_iterations > 0 and outcome[1] is not StopReason.INTERRUPTED
    if again and setup.duration is not None and setup.method == Method.SCP:
        outcome = _from_free_plan(setup, *first, via_s, outcome, callback, verbose)
    again = again and outcome[1] is not StopReason.INTERRUPTED
    if again and any(v is not None for v in setup.ends) and all(resting_ends(setup)):
        outcome = _from_rest_plan(setup, via_s, outcome, callback, verbose)
    return initial, outcome, via_s


def _from_free_plan(
    setup: Segment,
    line: Path,
    start: Path | None,
    via_s: tuple[float, ...],
    first: Outcome,
    callback: Callable[[Iteration], None] | None,
    verbose: bool,
) -> Outcome:
    """Under a duration, stage 2 again from the plan without it, where that path can be as
    fast as T, and the lower J of the two runs: stage 2 finds local optima, and for a T near
    or beyond the free plan's t_e its path is a better start than the first path (a ur5
    motion at 1.5 times the free plan's t_e: J 3.34 from there)."""
    if time.perf_counter() >= setup.deadline:
        return first
    free = replace(setup, duration=None)
    best, spent = first, first[3]
    try:  # (stage 2's coarser grid may time the path a little slower; the time may run out)
        first_free = _time_first_path(free, line, start)
        plans_free, spent_free = _starts(free, line, start, via_s, first_free, None, False)
        spent += spent_free
        # from each free run's path (the second start's is slower: a T it cannot meet may be met
        # by the first run's, a better start there; ur5 at T = 1.2 s: J 3.42 against 3.17)
        fits = []  # the free runs whose path can be as fast as T
        for plan_free in plans_free:
            path = plan_free[0].trajectory.path
            if time.perf_counter() >= setup.deadline:
                break
            run = _fitting(setup, _fastest_on(setup, path))
            if run is None:
                continue
            fits.append(plan_free)
            initial = _time_first_path(run, path, path)
            second = _improve(run, path, path, via_s, initial, callback, verbose)
            spent += second[3]
            best = _lower(best, second, spent, "without the duration")
            if second[1] is StopReason.INTERRUPTED:
                break
        else:
            best, spent = _binding(setup, plans_free, fits, (best, spent), via_s, callback, verbose)
    except (InfeasiblePathError, SolverError, KeyboardInterrupt):
        pass  # (a Ctrl-C ends planning with the best plan so far)
    return (*best[:3], spent, best[4])


def _binding(
    setup: Segment,
    plans_free: list[Outcome],
    fits: list[Outcome],
    so_far: tuple[Outcome, int],
    via_s: tuple[float, ...],
    callback: Callable[[Iteration], None] | None,
    verbose: bool,
) -> tuple[Outcome, int]:
    """Under t_e ≤ T, where a plan without the duration is lower than the best so far but
    slower than T (its basin's optimum under the limit has t_e = T), stage 2 again under
    t_e = T from the lowest free path that ``fits`` (can be as fast as T), and the lower J with
    the stage-1 solves spent (ur5 at t_e ≤ 1.5 s: J 2.71 at 0.74 s, where the motion at 1.5 s
    costs 2.18)."""
    best, spent = so_far
    limit, exact = setup.duration  # type: ignore[misc]
    slower = [p for p in plans_free if p[0].J < best[0].J and p[0].duration > limit]
    if exact or not slower or not fits or time.perf_counter() >= setup.deadline:
        return best, spent
    at = replace(setup, duration=(limit, True))
    path = min(fits, key=lambda p: p[0].J)[0].trajectory.path
    initial = _time_first_path(at, path, path)
    second = _improve(at, path, path, via_s, initial, callback, verbose)
    spent += second[3]
    return _lower(best, second, spent, f"at t_e = {limit:g} s"), spent


def _lowest(setup: Segment, runs: list[Outcome], spent: int) -> Outcome:
    """The lower J of :func:`_starts`' runs, with the stage-1 solves ``spent`` by all; where the
    second is lower, the history is the first run's iterates followed by the second's (its first
    entry, α None, the heavier start's path: J falls all along, as the callback saw it)."""
    first = runs[0]
    if len(runs) == 1 or runs[1][0].J >= first[0].J:
        return (*first[:3], spent, first[4])
    second = runs[1]
    factor = setup.options.continuation  # type: ignore[union-attr]
    under = f"{factor:g} times the torque weights"
    if _time_optimal(setup):
        under = f"f0 = 1 + {SOFTENED:g} Σ (u/U)²"
    note = f"{second[2]}; from the plan under {under}"
    return (second[0], second[1], note, spent, first[4] + second[4])


def _starts(
    setup: Segment,
    line: Path,
    start: Path | None,
    via_s: tuple[float, ...],
    initial: TimingResult,
    callback: Callable[[Iteration], None] | None,
    verbose: bool,
) -> tuple[list[Outcome], int]:
    """Stage 2 from the first path and, where :func:`_continues`, from the path a coarse stage 2
    under heavier torque weights finds (:func:`_heavier_path`, ``SCPOptions.continuation``), in
    a forked child at the same time (each run with the whole iteration budget); stage 2 goes on
    from that path only where it is timed under the cost itself below the first run's plan.
    Returns the runs (the first run's first) and the stage-1 solves spent. The second start
    never costs the first run's plan: where its child fails, dies or outlasts the time limit,
    the first run's plan stands; a Ctrl-C while it finishes returns that plan, interrupted."""
    if not _continues(setup, start):
        run = _improve(setup, line, start, via_s, initial, callback, verbose)
        return [run], run[3]
    done: list[Outcome] = []

    def here() -> Outcome:
        done.append(_improve(setup, line, start, via_s, initial, callback, verbose))
        return done[0]

    moving = any(v is not None for v in setup.ends)
    try:
        first, found = beside(
            here,
            (lambda: _heavier_run(setup)) if moving else (lambda: _heavier_path(setup)),
            lambda outcome: (
                outcome[1] is not StopReason.INTERRUPTED and time.perf_counter() < setup.deadline
            ),
            "stage 2 under heavier torque weights",
            deadline=setup.deadline + SECOND_START_GRACE,
        )
        if found is None:
            return [first], first[3]
        offset = len(first[4])  # its iterates numbered on from the first run's

        def follow(entry: Iteration) -> None:
            moved = replace(entry, index=entry.index + offset)
            if verbose:
                print(_format(moved), flush=True)
            if callback is not None:
                callback(moved)

        if moving:  # the child's run, its plan timed here as the child's run timed it
            path, reason, message, spent, entries = found
            for entry in entries:  # (reported when it has ended)
                follow(entry)
            timed = _time_first_path(setup, path, path)
            moved = [replace(entry, index=entry.index + offset) for entry in entries]
            return [first, (timed, reason, message, spent, moved)], first[3] + spent + 1
        path, spent = found
        spent += first[3] + 1
        timed = _time_first_path(setup, path, path)
        if timed.J >= first[0].J:  # the first run's basin, or a worse one: no second run
            return [first], spent
        second = _improve(setup, path, path, via_s, timed, follow, False)
        moved = [replace(entry, index=entry.index + offset) for entry in second[4]]
        second = (*second[:4], moved)
    except KeyboardInterrupt:
        if not done:
            raise
        note = "; interrupted while the second start (heavier torque weights) ended"
        return [(done[0][0], StopReason.INTERRUPTED, done[0][2] + note, *done[0][3:])], done[0][3]
    except (InfeasiblePathError, SolverError):  # the child's failure, or its path's
        if not done:
            raise
        return [done[0]], done[0][3]
    return [first, second], spent + second[3]


SECOND_START_GRACE = 1.0
"""[s] How long past the time limit a plan waits for its second start's child (which stops
at the time limit itself, within an iteration) before it ends it."""


def _continues(setup: Segment, start: Path | None) -> bool:
    """Whether :func:`_starts` runs the second start: stage 2 by SCP from the straight line
    (no obstacles or via-points; with moving ends, the line leaving along them, unless every
    moving end nearly rests: :func:`_from_rest_plan` then plans from rest, second start and
    all), θe fixed, no duration, a torque cost with some weight > 0 (or, with moving ends, the
    time-optimal cost: :func:`_heavier_run`) and ``SCPOptions.continuation`` > 1 (under jerk
    limits too: the phase under them starts from the lower run's path)."""
    options, cost = setup.options, setup.cost
    moving = any(v is not None for v in setup.ends)
    return (
        setup.method == Method.SCP
        and isinstance(options, SCPOptions)
        and options.continuation > 1.0
        and isinstance(cost, TorqueCost)
        and (moving or bool(np.any(cost.torque_weights(setup.robot.n) > 0.0)))
        and (start is None or (moving and not all(resting_ends(setup))))
        and setup.max_iterations > 0
        and setup.collisions is None
        and not setup.vias
        and setup.goal is None
        and setup.duration is None
    )


def _heavier_run(
    setup: Segment,
) -> tuple[Path, StopReason, str, int, list[Iteration]] | None:
    """With moving ends, the second start's whole run (in its child): stage 2 under the cost
    itself from the path of :func:`_heavier_path`, whatever that path's J — from a moving
    start it is timed above the first run's plan although stage 2 goes on from it to a lower
    one (ur5 leaving at 1 rad/s along the line: 2.52 at t_e 1.93 s → 2.06, against the first
    run's 2.51 at 0.71 s). Its plan's path, why it stopped, the message, the stage-1 solves
    spent and its iterates; None where it fails. For f0 = 1 (no torque weight to make heavier)
    the run is stage 2 under :data:`SOFTENED` from the first path, then under f0 = 1 from its
    path: a baxter arm re-planned time-optimally from 0.7 of its plan to the same goal stopped
    at 0.4252 (the rest of the old plan lasts 0.3980 s) and now ends at 0.3974."""
    found = _softened_path(setup) if _time_optimal(setup) else _heavier_path(setup)
    if found is None:
        return None
    path, spent = found
    try:
        run = _improve(setup, path, path, (), _time_first_path(setup, path, path), None, False)
    except NearoptError:
        return None
    return run[0].trajectory.path, run[1], run[2], spent + run[3] + 1, run[4]


SOFTENED = 0.01
"""The running cost 1 + SOFTENED · Σ (u_i/U_i)² (U_i: joint i's larger effort limit) of the second
start of a time-optimal plan with moving ends (:func:`_heavier_run`). Under f0 = 1 stage 2's
model ties between bang-bang motions, and from the first path leaving along qd0 it stopped in a
poor optimum; the small torque term orders them. On the baxter re-plan of :func:`_heavier_run`,
1.0 ended at 0.4246 (the run under it too slow), 0.1 at 0.3985, 0.01 at 0.3974."""


def _time_optimal(setup: Segment) -> bool:
    """Whether the plan's cost is f0 = 1 (a torque cost without weights)."""
    cost = setup.cost
    return isinstance(cost, TorqueCost) and not np.any(cost.torque_weights(setup.robot.n) > 0.0)


def _softened_path(setup: Segment) -> tuple[Path, int] | None:
    """The path of stage 2 under f0 = 1 + :data:`SOFTENED` Σ (u/U)² from the first path (a
    whole plan's stage 2, in the second start's child), and the stage-1 solves spent; None where
    it fails."""
    lim = setup.robot.limits
    effort = np.maximum(np.abs(lim.effort_lower), np.abs(lim.effort_upper))
    soft = replace(setup, cost=TorqueCost(weights=SOFTENED / effort**2))
    try:
        line, start, via_s = first_path(soft)
        initial = _time_first_path(soft, line, start)
        run = _improve(soft, line, start, via_s, initial, None, False)
    except NearoptError:
        return None
    if run[1] is StopReason.INTERRUPTED:
        raise KeyboardInterrupt
    return run[0].trajectory.path, run[3] + 1


def _heavier_path(setup: Segment) -> tuple[BSplinePath, int] | None:
    """The path of stage 2 from the straight line under the torque weights times
    ``SCPOptions.continuation``, coarse (half the control points, a 32-segment grid, no
    refinement, four times the first trust radius), as a B-spline of the plan's own knots (its
    control points on that path at their Greville abscissae), and the stage-1 solves spent;
    None where it fails (KeyboardInterrupt where it was interrupted). With moving ends, that
    run is from rest to rest and its path's end legs are turned onto the velocities' rays
    (:func:`~nearopt.planning.ends.turned_onto`): from the line leaving along them, the
    heavier run stayed among the fast motions (ur5 leaving at 1 rad/s: t_e 0.72 s)."""
    options: SCPOptions = setup.options  # type: ignore[assignment]
    cost: TorqueCost = setup.cost  # type: ignore[assignment]
    k = options.control_points
    coarse = replace(
        options,
        control_points=max(4, k // 2),
        grid=32,
        refinements=0,
        continuation=1.0,
        trust_radius=4.0 * options.trust_radius,  # it explores: ur5, 25 iterations instead of 201
    )
    weights = options.continuation * cost.torque_weights(setup.robot.n)
    heavy = replace(
        setup, cost=TorqueCost(weights=weights), options=coarse, grid=min(setup.grid, 64)
    )
    moving = (setup.ends[0] is not None, setup.ends[1] is not None)
    try:
        line = StraightPath(setup.q0, setup.qe)
        heavy = replace(heavy, ends=(None, None))
        first = _time_first_path(heavy, line, None)
        outcome = _improve(heavy, line, None, (), first, None, False)
        if outcome[1] is StopReason.INTERRUPTED:  # (run here, on one core: the plan ends)
            raise KeyboardInterrupt
        found = outcome[0].trajectory.path
        breaks = knot_breaks(options, k, moving)
        sigma = BSplinePath.greville(k + 2, breaks)
        points = found(sigma * found.s_end)
        points[[0, -1]] = setup.q0, setup.qe
        path = BSplinePath(points, breaks)
        if any(moving):  # its end legs back onto the velocities' rays
            bounds = position_bounds(setup.robot, setup.position_limits)
            if bounds[0] is None or bounds[1] is None:
                bounds = (np.full(setup.robot.n, -np.inf), np.full(setup.robot.n, np.inf))
            path = turned_onto(setup.robot, path, setup.ends, bounds)  # type: ignore[arg-type]
        return path, outcome[3] + 1
    except NearoptError:
        return None


def _lower(
    first: Outcome,
    second: Outcome,
    spent: int,
    plan: str,
) -> Outcome:
    """The run of lower J, with the stage-1 solves ``spent`` by all; the second's message says
    it started from "the plan ``plan``"."""
    if second[0].J < first[0].J:
        return (*second[:2], f"{second[2]}; from the plan {plan}", spent, second[4])
    return (*first[:3], spent, first[4])


def _from_rest_plan(
    setup: Segment,
    via_s: tuple[float, ...],
    first: Outcome,
    callback: Callable[[Iteration], None] | None,
    verbose: bool,
) -> Outcome:
    """With nearly resting moving ends (:func:`~nearopt.planning.start.resting_ends`), stage 2
    again from the plan from rest to rest, its path turned onto the ends' directions
    (:func:`~nearopt.planning.ends.turned_onto`), and the lower J of the two runs. From the
    straight line leaving along a velocity of 1e-7 to 1e-2 rad/s, stage 2 stopped after a few
    iterations up to 23 % above the plan from rest (ur5 re-planned at the end of a motion): its
    model's end terms b_0 ∝ |qd0|² / |θ'(0)|² hardly see a turn right after the start."""
    if time.perf_counter() >= setup.deadline:
        note = "; no time left to plan again from the plan from rest"
        return (*first[:2], first[2] + note, *first[3:])
    rest = replace(setup, ends=(None, None))
    try:  # (the whole plan from rest: under a duration too)
        plan_rest = _planned(rest, None, False)[1]
        lower, upper = position_bounds(setup.robot, setup.position_limits)
        if lower is None or upper is None:
            lower, upper = np.full(setup.robot.n, -np.inf), np.full(setup.robot.n, np.inf)
        found = plan_rest[0].trajectory.path
        for share in (1.0, 1e-3):  # its first leg turned, else hardly any of it (a duration)
            path = turned_onto(setup.robot, found, setup.ends, (lower, upper), share)
            try:
                initial = _time_first_path(setup, path, path)
                break
            except InfeasiblePathError:
                if share < 1.0 or time.perf_counter() >= setup.deadline:
                    raise
        second = _improve(setup, path, path, via_s, initial, callback, verbose)
    except (InfeasiblePathError, SolverError, ConfigurationError, KeyboardInterrupt):
        return first  # no second plan (a Ctrl-C ends planning with the first)
    return _lower(first, second, first[3] + plan_rest[3] + second[3], "from rest")


def _fast_enough(
    setup: Segment, line: Path, start: Path | None, via_s: tuple[float, ...]
) -> tuple[Segment, Path, Path | None]:
    """The first path, if it can be as fast as the plan's duration; else the path stage 2
    finds for the time-optimal cost, else the one it finds without the duration (the first
    path of the plan then), if that can; else InfeasiblePathError with the fastest motion
    found. A path only the plan's grid times as fast as T (the iterate grid is coarser: a
    moving start's first segment, or T at the free plan's own t_e) is improved on the plan's
    grid (the request returned with that grid for stage 2)."""
    duration, exact = setup.duration
    word = "duration" if exact else "max_duration"
    fastest = _fastest_on(setup, line)
    run = _fitting(setup, fastest)
    if run is not None:
        return run, line, start
    if setup.max_iterations == 0:
        raise InfeasiblePathError(
            f"{word} {duration:.9g} s is shorter than the time-optimal motion along the first "
            f"path, {max(fastest):.9g} s"
        )
    quickest = np.inf
    requests = (replace(setup, cost=TimeCost(), duration=None), replace(setup, duration=None))
    for whole, request in zip((False, True), requests, strict=True):
        try:  # the time-optimal run's path; the plan's without the duration, as plan makes it
            # (for f0 = 1 too: its second start finds faster motions than the one run)
            if not whole:
                first = _time_first_path(request, line, start)
                path = _improve(request, line, start, via_s, first, None, False)[0].trajectory.path
            else:
                path = _planned(request, None, False)[1][0].trajectory.path
        except (InfeasiblePathError, SolverError):
            continue
        found = _fastest_on(setup, path)
        quickest = min(quickest, found[0])
        run = _fitting(setup, found)
        if run is not None:
            return run, path, path
    found = "stage 2 timed no path" if quickest == np.inf else "along the fastest path stage 2"
    raise InfeasiblePathError(
        f"{word} {duration:.9g} s is shorter than the time-optimal motion along the first "
        f"path ({fastest[0]:.9g} s) and {found} found ({quickest:.9g} s)",
        excess=min(fastest[0], quickest) - duration,
    )


def _check_duration(setup: Segment, duration: object, max_duration: object) -> tuple[float, bool]:
    """(T, exact) of :func:`plan`'s duration arguments; ConfigurationError for both, a bad
    value, a cost outside 1 + Σ w u², jerk or torque-rate limits."""
    exact = check_duration("duration", duration)
    most = check_duration("max_duration", max_duration)
    if exact is not None and most is not None:
        raise ConfigurationError("give duration (t_e = T) or max_duration (t_e ≤ T), not both")
    if not isinstance(setup.cost, TorqueCost):
        raise ConfigurationError(
            "a duration is kept for f0 = 1 + Σ w u² (TimeCost, TorqueCost), not "
            f"{setup.cost.describe()}"
        )
    if setup.robot.limits.smooth:
        raise ConfigurationError(
            "a duration with jerk or torque-rate limits is not planned yet: give one or the other"
        )
    if setup.method == Method.PAPER:
        raise ConfigurationError("a duration needs method 'scp' (the paper's update has none)")
    return (exact, True) if exact is not None else (most, False)


def _check_ends(
    setup: Segment, qd0: object, qde: object
) -> tuple[NDArray[np.float64] | None, NDArray[np.float64] | None]:
    """(qd0, qde) of :func:`plan`'s arguments (None: at rest); ConfigurationError for a bad
    value (naming the joint) or what moving ends are not planned with yet."""
    ends = check_velocities(setup.robot, qd0, qde, setup.velocity_limits)
    if ends[0] is None and ends[1] is None:
        return ends
    if setup.position_limits:
        check_at_limits(setup.robot, setup.q0, ends[0], "qd0", side=-1)
        check_at_limits(setup.robot, setup.qe, ends[1], "qde", side=1)
    what = None
    if setup.method == Method.PAPER:
        what = "method 'paper' (the straight line's update keeps rest ends); use method='scp'"
    elif setup.robot.limits.smooth:
        what = "jerk or torque-rate limits (they start and end at rest)"
    elif setup.collisions is not None:
        what = "obstacles or self-collision checks"
    elif setup.vias:
        what = "via-points"
    elif setup.options.control_points < 4:
        what = "fewer than 4 interior control points"
    if what is not None:
        raise ConfigurationError(f"boundary velocities (qd0, qde) are not planned with {what}")
    return ends


def _check_moves(setup: Segment) -> None:
    """ConfigurationError where θe = θ0, no via-point and both ends at rest: there is nothing to
    plan. (From a moving state, θe = θ0 is a motion: the arm brakes and comes back.)"""
    moving = any(v is not None for v in setup.ends)
    if moving or setup.vias or not np.array_equal(setup.q0, setup.qe):
        return
    if setup.goal is not None:
        raise ConfigurationError(
            f"the {setup.goal.frame or setup.robot.tip!r} frame already holds the goal pose at "
            "q0: there is nothing to plan (the arm stays where it is)"
        )
    raise ConfigurationError(
        "q0 equals qe: a zero-length motion has nothing to plan (the arm stays where it is)"
    )


def _fitting(setup: Segment, fastest: tuple[float, float]) -> Segment | None:
    """The request to improve a path under its duration whose time-optimal motions take
    ``fastest`` [s] (:func:`_fastest_on`): as it is where both grids time it as fast as T, on
    the plan's grid where only that one does, None where neither does."""
    if not _meets(fastest[0], setup.duration):  # type: ignore[arg-type]
        return None
    if _meets(fastest[1], setup.duration):  # type: ignore[arg-type]
        return setup
    return replace(setup, options=replace(setup.options, grid=setup.grid))


def _meets(fastest: float, asked: tuple[float, bool]) -> bool:
    """Whether a path whose time-optimal motion takes ``fastest`` [s] can take the duration
    ``asked`` (T, exact): t_e = T to stage 1's accuracy (:data:`~nearopt.timing.AS_FAST`: the
    free plan's own t_e asked for came out 1.5e-11 above the time-optimal timing of another
    solve of its path), t_e ≤ T to rounding (1e-12 relative, as verify checks it; 1.2e-15 seen)."""
    return as_fast_as(fastest, *asked)


def _fastest_on(setup: Segment, path: Path) -> tuple[float, float]:
    """t_e of the time-optimal timing of a path [s] on the plan's grid and on the grid stage 2
    times its iterates on (that of ``SCPOptions.grid``, at least 4 segments per control point,
    at most the plan's), inf where the grid cannot time the path (a moving start's first
    segment too long to turn in)."""
    grid, options = setup.grid, setup.options
    iterate = grid
    if setup.max_iterations > 0 and isinstance(options, SCPOptions):  # (a duration's method)
        count = options.control_points
        if isinstance(path, BSplinePath):
            count = path.control_points.shape[0] - 2
        iterate = iterate_grid(grid, options, count)
    found = {}
    for g in {grid, iterate}:
        try:
            found[g] = optimal_timing(
                setup.robot,
                path,
                grid=g,
                velocity_limits=setup.velocity_limits,
                qd0=setup.ends[0],
                qde=setup.ends[1],
            ).duration
        except (InfeasiblePathError, SolverError):  # (the limits between its samples too)
            found[g] = np.inf
    return found[grid], found[iterate]


def _setup(
    robot: Robot,
    q0: ArrayLike,
    qe: ArrayLike | ToolPose,
    cost: Cost | None,
    method: Method | str | None,
    options: SCPOptions | PaperOptions | None,
    grid: int,
    max_iterations: int,
    time_limit: float,
    velocity_limits: bool,
    position_limits: bool,
    scene: Scene | CollisionModel | None,
    margin: float | None,
    self_collision: bool | None,
    optimise_goal: bool,
    via: Sequence[ArrayLike | ToolPose] | None,
    t_start: float,
) -> Segment:
    """Check :func:`plan`'s arguments (see there for what it raises), find the goal
    configuration of a pose and the collision model."""
    if not isinstance(robot, Robot):
        raise ConfigurationError(
            f"robot must be a nearopt.Robot (e.g. Robot.from_name('two_link') or "
            f"Robot.from_urdf(path)), got {type(robot).__name__} {robot!r:.60}"
        )
    cost = TimeCost() if cost is None else check_cost(cost)
    _check_jerk_cost(robot, cost)
    method, options = _check_method(method, options, cost)
    for name, value, low, high in (
        ("max_iterations", max_iterations, 0, np.inf),
        ("grid", grid, 2, MAX_GRID),
    ):
        if not isinstance(value, int | np.integer) or not low <= value <= high:
            raise ConfigurationError(
                f"{name} must be an integer ≥ {low}"
                + (f" and ≤ {high}" if high < np.inf else "")
                + f", got {value!r}"
            )
    if not (is_number(time_limit) and time_limit > 0):
        raise ConfigurationError(
            f"time_limit must be a positive number of seconds (inf: none), got {time_limit!r}"
        )

    q0 = robot.check_configuration(q0, "q0")
    goal = qe if isinstance(qe, ToolPose) else None
    if goal is not None:  # inverse kinematics from the start, within the position limits
        qe = inverse_kinematics(robot, goal, seed=q0)
    qe = robot.check_configuration(qe, "qe")
    if position_limits:
        robot.limits.check_within(q0, "q0", prismatic=robot.prismatic)
        robot.limits.check_within(qe, "qe", prismatic=robot.prismatic)
    vias = _via_points(robot, via, q0, qe, position_limits)
    if vias and method != Method.SCP:
        raise ConfigurationError("via-points need method 'scp' (the B-spline path)")
    shortest, joint = minimum_duration(robot, q0, qe, velocity_limits)
    if shortest > MAX_DURATION:
        raise ConfigurationError(
            f"joint {robot.joint_names[joint]!r} cannot move from q0 to qe in less than "
            f"{shortest:.3g} s at its speed and acceleration limits (more than "
            f"{MAX_DURATION:.0e} s, 31 years): are the limits meant to be that small?",
            joint=robot.joint_names[joint],
        )
    collisions = collisions_for(robot, scene, margin, self_collision)
    if collisions is not None:
        if method == Method.PAPER:
            raise ConfigurationError(
                "method 'paper' cannot keep clearances from obstacles; use method='scp'"
            )
        collisions.check_configuration(q0, "start configuration q0")
        if goal is not None:  # another solution of the pose if the first one collides
            qe = _clear_solution(robot, goal, q0, qe, collisions)
        collisions.check_configuration(qe, "goal configuration qe")
        _check_vias(robot, via, vias, q0, qe, collisions)
    return Segment(
        robot,
        q0,
        qe,
        goal,
        cost,
        method,
        options,
        grid,
        max_iterations,
        velocity_limits,
        position_limits,
        collisions,
        vias,
        optimise_goal,
        t_start,
        t_start + time_limit,
        via_poses=tuple(v if isinstance(v, ToolPose) else None for v in via or ()),
    )


FIRST_TIMING = 10.0
"""Stage 1 of the first path gets at least this much time [s], whatever is left of the plan's
time limit: without it there is no plan to return."""


def _time_first_path(setup: Segment, line: Path, start: Path | None) -> TimingResult:
    """Stage 1 on the first path, on the plan's grid (under the plan's duration, if any), with
    what is left of the time limit, at least :data:`FIRST_TIMING`."""
    robot, cost, grid = setup.robot, setup.cost, setup.grid
    velocity_limits, deadline = setup.velocity_limits, setup.deadline
    t, exact = setup.duration or (None, False)
    try:
        initial = optimal_timing(
            robot,
            line,
            cost,
            grid=grid,
            velocity_limits=velocity_limits,
            # the first path is timed however little time is left (a plan is at least its
            # timing: a cell plan's collision-free search spent its limit, leaving one < 0)
            time_limit=max(deadline - time.perf_counter(), FIRST_TIMING),
            duration=t if exact else None,
            max_duration=None if exact else t,
            qd0=setup.ends[0],
            qde=setup.ends[1],
        )
    except SolverError as exc:
        what = "the straight line" if start is None else "the collision-free start"
        if any(v is not None for v in setup.ends):
            what = "the straight line with the boundary velocities"
        raise SolverError(f"no plan: timing {what} failed: {exc}", status=exc.status) from exc
    return initial


def _improve(
    setup: Segment,
    line: Path,
    start: Path | None,
    via_s: tuple[float, ...],
    initial: TimingResult,
    callback: Callable[[Iteration], None] | None,
    verbose: bool,
) -> Outcome:
    """Stage 2 from the first path (or none, ``max_iterations = 0``): the timing returned, why
    it stopped, the message, the stage-1 solves spent and the accepted iterates."""
    robot, q0, qe, cost, goal = setup.robot, setup.q0, setup.qe, setup.cost, setup.goal
    method, options, grid, collisions = setup.method, setup.options, setup.grid, setup.collisions
    velocity_limits, position_limits = setup.velocity_limits, setup.position_limits
    max_iterations, optimise_goal = setup.max_iterations, setup.optimise_goal
    t_start, deadline = setup.t_start, setup.deadline
    history: list[Iteration] = []
    best: list[TimingResult] = [initial]  # the last accepted iterate's timing (the best)

    def accept(entry: Iteration, timing: TimingResult) -> None:
        history.append(entry)
        best[0] = timing
        if verbose:
            print(_format(entry), flush=True)
        if callback is not None:
            callback(entry)

    run = Run(max_iterations, deadline, t_start, accept)
    common = dict(
        grid=grid,
        velocity_limits=velocity_limits,
        position_limits=position_limits,
        options=options,
        run=run,
    )
    if method == Method.SCP and optimise_goal:  # a tool-pose via-point moves along its pose
        common["via_poses"] = setup.via_poses
    if max_iterations == 0 or method == Method.PAPER:
        run.report(0, initial, None, line)
    if max_iterations == 0:
        timing, reason, evaluations = initial, StopReason.ITERATION_LIMIT, 1
        first = "the straight line" if start is None else "the first path"
        message = f"max_iterations = 0: {first}, timed by stage 1"
    else:
        try:
            if method == Method.SCP:
                outcome = sequential_convex(
                    robot,
                    q0,
                    qe,
                    cost,
                    **common,
                    collisions=collisions,
                    start=start,
                    via=via_s,
                    duration=setup.duration,
                    ends=setup.ends,
                )
                free = goal if goal is not None and optimise_goal else None
                if free is not None and len(history) <= max_iterations:
                    # then θe moves along the pose, from that plan: J can only go down
                    outcome = _continued(
                        robot, q0, qe, cost, free, outcome, outcome.timing.trajectory.path,
                        common, history, collisions, via_s, setup.duration, setup.ends,
                    )  # fmt: skip
                # (not under jerk limits: a finer path found without them was worse under them,
                # +2–4 % J in cells and on kinova; stage 2 under the limits goes on instead)
                for _ in range(0 if robot.limits.smooth else options.refinements):
                    outcome = _refined(setup, outcome, free, common, history, via_s)
            else:
                outcome = paper_iterations(robot, initial, cost, **common)
            timing, reason = outcome.timing, outcome.reason
            message, evaluations = outcome.message, outcome.evaluations + 1
        except KeyboardInterrupt:  # the best plan so far, timed on the plan's grid
            timing, reason, evaluations = best[0], StopReason.INTERRUPTED, len(history) + 1
            if timing.problem.segments != initial.problem.segments:
                timing = _time_first_path(setup, timing.trajectory.path, start)
            message = f"interrupted after {len(history) - 1} iterations: the best plan so far"
        if timing.J > initial.J:  # e.g. no better path: the line as a B-spline on another grid
            timing = initial
            message += (
                f"; {'the straight line' if start is None else 'the first path'} is "
                "returned: it costs less on the plan's grid"
            )
    return timing, reason, message, evaluations, history


def _result(
    setup: Segment,
    timing: TimingResult,
    initial: TimingResult,
    history: list[Iteration],
    ended: tuple[StopReason, str],
    evaluations: int,
    via_s: tuple[float, ...],
    jerk: JerkTimingResult | None = None,
) -> PlanResult:
    """The plan, its clearance certified when collisions are checked."""
    robot, collisions, goal, vias = setup.robot, setup.collisions, setup.goal, setup.vias
    method, t_start = setup.method, setup.t_start
    reason, message = ended
    if any(pose is not None for pose in setup.via_poses):  # moved along their poses: the path's
        at = (timing if jerk is None else jerk).trajectory.path(np.asarray(via_s, dtype=float))
        vias = [at[k] if pose is not None else v for k, (v, pose) in
                enumerate(zip(vias, setup.via_poses, strict=True))]  # fmt: skip
    return PlanResult(
        robot=robot,
        timing=timing,
        initial=initial,
        history=tuple(history),
        method=method,
        status=reason,
        message=message,
        evaluations=evaluations,
        wall_time=time.perf_counter() - t_start,
        collisions=collisions,
        clearance=None if collisions is None else _certify(collisions, timing.trajectory.path),
        goal=goal,
        via=tuple(vias),
        via_s=via_s,
        jerk_timing=jerk,
        duration_asked=setup.duration,
        qd0=setup.ends[0],
        qde=setup.ends[1],
        via_poses=setup.via_poses,
    )


def _under_jerk_limits(
    setup: Segment, timing: TimingResult, initial: TimingResult, message: str
) -> tuple[TimingResult, JerkTimingResult, str]:
    """The path found and the first path timed under the jerk limits (stage 2 does not know
    them yet: its path may be the worse one under them); the better, its stage-1 timing, the
    message. Within what is left of the plan's time limit (past it, each jerk-limited timing
    stops at its first feasible iterate: the message says so)."""
    late: list[str] = []
    lim = setup.robot.limits
    pairs = (("jerk", lim.jerk), ("torque-rate", lim.torque_rate))
    kinds = [kind for kind, values in pairs if np.any(np.isfinite(values))]
    limits = f"{' and '.join(kinds)} limits"

    def timed(path: Path) -> JerkTimingResult:
        result = time_with_jerk_limits(
            setup.robot,
            path,
            setup.cost,
            grid=setup.grid,
            velocity_limits=setup.velocity_limits,
            time_limit=max(setup.deadline - time.perf_counter(), 0.0),
        )
        if result.timing.timed_out:
            late.append(f"; the timing under the {limits} stopped at the plan's time limit")
        return result

    if initial.trajectory.path is not timing.trajectory.path:
        try:
            found = timed(timing.trajectory.path)
        except (InfeasiblePathError, SolverError) as exc:  # (the first path may be timed)
            first = timed(initial.trajectory.path)
            return (
                initial,
                first,
                f"{message}; the path found could not be timed under the {limits} ({exc}): "
                f"the first path is returned, timed under them (te {first.duration:.4g} s)"
                f"{''.join(late[:1])}",
            )
        first = timed(initial.trajectory.path)
        if first.J < found.J:
            return (
                initial,
                first,
                f"{message}; under the {limits} the first path costs less (J "
                f"{first.J:.6g} against {found.J:.6g} for the path found without them): it is "
                f"returned, timed under them (te {first.duration:.4g} s){''.join(late[:1])}",
            )
    else:
        found = timed(timing.trajectory.path)
    note = f"J {timing.J:.6g} -> {found.J:.6g}, te {timing.duration:.4g} -> {found.duration:.4g} s"
    return timing, found, f"{message}; timed under the {limits}: {note}{''.join(late[:1])}"


def _smoothed(
    setup: Segment,
    chosen: tuple[TimingResult, JerkTimingResult, str],
    report: Callable[[Iteration], None],
    stage_2: tuple[StopReason, int],
    via_s: tuple[float, ...],
) -> tuple[TimingResult, JerkTimingResult, str, StopReason]:
    """Stage 2 under the jerk (torque-rate) limits (:func:`~nearopt.planning.smooth_iterations`)
    from the path :func:`_under_jerk_limits` chose, with the plan's remaining iterations and
    time, unless stage 2 (``stage_2``: why it stopped, its history's length) was interrupted;
    its iterates go to ``report`` (J and t_e under the limits, on the iterate grid; the first,
    with α None, is the chosen path, so J rises there where the limits bind). The better of the
    two paths timed under the limits on the plan's grid: its stage-1 timing, its timing under
    the limits, the message, why the plan stopped."""
    timing, limited, message = chosen
    reason, offset = stage_2
    left = setup.max_iterations - max(offset - 1, 0)
    if reason is StopReason.INTERRUPTED or setup.method != Method.SCP:
        return timing, limited, message, reason
    if left <= 0 or time.perf_counter() >= setup.deadline:
        why = "no iterations" if left <= 0 else "no time"
        return timing, limited, f"{message}; {why} left for stage 2 under the limits", reason
    path, options = timing.trajectory.path, setup.options
    if not isinstance(path, BSplinePath):  # the straight line
        k = options.control_points
        path = BSplinePath.line(setup.q0, setup.qe, k, knot_breaks(options, k))
    count = path.control_points.shape[0] - 2
    try:
        outcome = smooth_iterations(
            setup.robot, setup.cost, path,
            grid=iterate_grid(setup.grid, options, count),
            velocity_limits=setup.velocity_limits, position_limits=setup.position_limits,
            options=options, collisions=setup.collisions, via=via_s,
            run=Run(left, setup.deadline, setup.t_start,
                    lambda entry, _: report(replace(entry, index=entry.index + offset))),
        )  # fmt: skip
    except (InfeasiblePathError, SolverError) as exc:
        return timing, limited, f"{message}; stage 2 under the limits failed: {exc}", reason
    head = f"{message}; stage 2 under the limits from there"
    if outcome.iterations == 0:  # (the plan is stage 2's: its status, unless interrupted now)
        ended = outcome.reason if outcome.reason is StopReason.INTERRUPTED else reason
        return timing, limited, f"{head}: {outcome.message}", ended
    try:
        better = time_with_jerk_limits(
            setup.robot, outcome.path, setup.cost, grid=setup.grid,
            velocity_limits=setup.velocity_limits,
            time_limit=max(setup.deadline - time.perf_counter(), 0.0),
        )  # fmt: skip
        plain = optimal_timing(
            setup.robot, outcome.path, setup.cost, grid=setup.grid,
            velocity_limits=setup.velocity_limits,
        )  # fmt: skip
    except (InfeasiblePathError, SolverError) as exc:
        note = f"{head}: its path could not be timed on the plan's grid ({exc}); the path before"
        return timing, limited, note, outcome.reason
    if better.J >= limited.J:  # (J on the iterate grid went down, on the plan's not)
        note = f"{head}: no lower J on the plan's grid ({outcome.message})"
        return timing, limited, note, outcome.reason
    note = (
        f"{head}: J {limited.J:.6g} -> {better.J:.6g} (te {better.duration:.4g} s) in "
        f"{outcome.iterations} iteration(s), {outcome.message}"
    )
    return plain, better, note, outcome.reason


def _via_points(
    robot: Robot,
    via: Sequence[ArrayLike | ToolPose] | None,
    q0: NDArray[np.float64],
    qe: NDArray[np.float64],
    position_limits: bool,
) -> list[NDArray[np.float64]]:
    """The via-points as joint vectors, checked; a tool pose by inverse kinematics: of the
    solutions from the previous point, the next joint vector (a later via-point or qe) and
    points on the line between them (:data:`VIA_SEEDS`), the one with the shortest way from the
    previous point to the next (from the previous point alone, a panda pose on a plan's own path
    came out on a far branch: J 2×)."""
    if via is None:
        return []
    flat = isinstance(via, np.ndarray) and via.ndim == 1
    if (
        flat
        or not isinstance(via, Sequence | np.ndarray)
        or isinstance(via, str)
        or any(isinstance(v, int | float | np.number) for v in via)
    ):
        raise ConfigurationError(
            f"via is a list of via-points, each a joint vector of {robot.n} values or a "
            f"ToolPose (e.g. via=[q1, q2]), got {via!r:.80}"
        )
    out: list[NDArray[np.float64]] = []
    previous = q0
    for k, point in enumerate(via):
        if isinstance(point, ToolPose):
            later = [v for v in via[k + 1 :] if not isinstance(v, ToolPose)]
            after = robot.check_configuration(later[0], "a via-point") if later else qe
            # from the points around it, and along the line between them where the pose leaves
            # the arm no redundancy (its branch is then final: stage 2 cannot move along it)
            fixed = robot.n <= (6 if point.quaternion is not None else 3)
            found = [
                inverse_kinematics(robot, point, seed=previous + g * (after - previous))
                for g in (VIA_SEEDS if fixed else VIA_SEEDS[:3])
            ]
            q = min(
                found,
                key=lambda x: np.linalg.norm(x - previous) + np.linalg.norm(after - x),  # noqa: B023
            )
        else:
            q = robot.check_configuration(point, f"via[{k}]")
        if position_limits:
            robot.limits.check_within(q, f"via[{k}]", prismatic=robot.prismatic)
        out.append(q)
        previous = q
    return out


VIA_SEEDS = (0.0, 1.0, 0.5, 0.125, 0.25, 0.375, 0.625, 0.75, 0.875)
"""Where inverse kinematics of a tool-pose via-point starts: at these fractions of the line from
the point before it to the point after it (the first three only where the arm has redundancy
left at the pose, along which stage 2 moves it). From the two points and their midpoint alone, a
6-joint arm (ur5, two poses of a free plan's own path) came out on other branches than the
path's (J +57 % and +61 % on 2 of 5 seeds); along the line, one start reaches it. On redundant
arms more starts changed the basin stage 2 ends in both ways (panda −0.01 → +2.6 % on one seed,
xarm7 +1.5 → −0.04 % on another; the pick-and-place example +0.4 %)."""


def _clear_solution(
    robot: Robot,
    goal: ToolPose,
    q0: NDArray[np.float64],
    qe: NDArray[np.float64],
    collisions: CollisionModel,
    tries: int = 20,
) -> NDArray[np.float64]:
    """An inverse-kinematics solution of the goal pose clear of the margin: ``qe`` if it is,
    else one from seeded random starts; a :class:`~nearopt.CollisionError` when none is, saying
    that the configuration was solved for the pose."""
    if collisions.closest(qe).distance >= collisions.margin:
        return qe
    clear = next(_clear_solutions(robot, goal, collisions, [], tries), None)
    if clear is None:
        what = "goal configuration qe solved for the goal pose (no solution found keeps the margin)"
        collisions.check_configuration(qe, what)
    return qe if clear is None else clear


def _clear_solutions(
    robot: Robot,
    pose: ToolPose,
    collisions: CollisionModel,
    seeds: list[NDArray[np.float64]],
    tries: int,
) -> Iterator[NDArray[np.float64]]:
    """The pose's inverse-kinematics solutions clear of the margin, from ``seeds`` and then
    from ``tries`` seeded random starts (drawn as they are needed)."""
    rng = np.random.default_rng(20261124)
    lower, upper = robot.limits.sampling_box()
    starts = itertools.chain(seeds, (rng.uniform(lower, upper) for _ in range(tries)))
    for seed in starts:
        try:
            q = inverse_kinematics(robot, pose, seed=seed, attempts=3)
        except UnreachablePoseError:
            continue
        if collisions.closest(q).distance >= collisions.margin:
            yield q


def _check_vias(
    robot: Robot,
    via: Sequence[ArrayLike | ToolPose] | None,
    vias: list[NDArray[np.float64]],
    q0: NDArray[np.float64],
    qe: NDArray[np.float64],
    collisions: CollisionModel,
) -> None:
    """Every via-point clear of the margin, or a :class:`~nearopt.CollisionError` naming it; a
    tool pose's solution that collides replaced (in ``vias``) by a clear one
    (:func:`_clear_via`)."""
    for k, q in enumerate(vias):
        if via is not None and isinstance(via[k], ToolPose):
            before = vias[k - 1] if k else q0
            after = vias[k + 1] if k + 1 < len(vias) else qe
            vias[k] = _clear_via(robot, via[k], before, after, q, collisions)
        collisions.check_configuration(vias[k], f"via-point {k}")


def _clear_via(
    robot: Robot,
    pose: ToolPose,
    before: NDArray[np.float64],
    after: NDArray[np.float64],
    q: NDArray[np.float64],
    collisions: CollisionModel,
    tries: int = 20,
) -> NDArray[np.float64]:
    """A tool-pose via-point's solution clear of the margin: ``q`` if it is, else of the
    solutions from ``before``, ``after``, their midpoint and seeded random starts the clear one
    with the shortest way from ``before`` to ``after`` (``q`` when none is: the caller reports
    it)."""
    if collisions.closest(q).distance >= collisions.margin:
        return q
    seeds = [before, after, 0.5 * (before + after)]
    found = _clear_solutions(robot, pose, collisions, seeds, tries)
    return min(
        found,
        key=lambda x: np.linalg.norm(x - before) + np.linalg.norm(after - x),
        default=q,
    )


GRID_TRUST = 5e-3
"""How much lower the iterate grid may put a path's J than the plan's grid (relatively) before
the refined run iterates on the plan's grid (moving starts: the coarse grid misjudged J by up to
4 %, and stage 2 followed its error)."""


def _refined(
    setup: Segment,
    first: MethodOutcome,
    goal: ToolPose | None,
    common: dict[str, object],
    history: list[Iteration],
    via: tuple[float, ...],
) -> MethodOutcome:
    """Stage 2 continued from ``first``'s path with a knot in the middle of every other span
    (the same path, about 1.5 times the control points; ``SCPOptions.refinements``), where it
    converged and the iterations, the time and :data:`MAX_CONTROL_POINTS` allow."""
    path = first.timing.trajectory.path
    if (
        first.reason is not StopReason.CONVERGED
        or not isinstance(path, BSplinePath)
        or len(history) > setup.max_iterations
        or time.perf_counter() >= setup.deadline
    ):
        return first
    fine = path.refined()
    count = fine.control_points.shape[0] - 2
    if count > MAX_CONTROL_POINTS:
        return first
    misjudged = first.timing.J / history[-1].J - 1.0  # the plan's grid against the iterates'
    options: SCPOptions = common["options"]  # type: ignore[assignment]
    on_plan_grid = dict(common, options=replace(options, grid=setup.grid))
    coarse = iterate_grid(setup.grid, options, count) < setup.grid  # the refined run's
    if misjudged > GRID_TRUST and coarse:
        common, coarse = on_plan_grid, False

    def run(settings: dict[str, object]) -> MethodOutcome:
        try:
            return _continued(
                setup.robot, setup.q0, setup.qe, setup.cost, goal, first, fine, settings,
                history, setup.collisions, via, setup.duration, setup.ends,
            )  # fmt: skip
        except (InfeasiblePathError, SolverError):  # e.g. the refined path cannot be timed
            return first  # on the iterate grid (a z1 re-plan: stage 1 could not hold a moving
            # end's limits between the samples): the first run's plan stands

    mark = len(history)
    second = run(common)
    low = min((e.J for e in history[mark:]), default=np.inf)  # the refined iterates' lowest
    if coarse and second.timing.J > (1.0 + GRID_TRUST) * low:
        # the plan's grid puts what the refined run returned (or the first run's plan, where
        # its own was no lower there) that far above its iterates: the iterate grid misjudged
        # J (a re-plan from 0.35 of a ur5 plan: iterates at 1.310, their path 1.561 on the
        # plan's grid, a torque peak between the samples at the ends of a segment; 36 seeded
        # free plans: −0.23 … +0.06 %), so the refined run goes again on the plan's grid
        misjudged = second.timing.J / low - 1.0
        again = run(on_plan_grid)
        second = again if again.timing.J < second.timing.J else second
    if second is first:
        return first
    note = f"{second.message} (the path refined to {count} control points"
    if misjudged > GRID_TRUST:
        note += f", iterated on the plan's grid: the iterates' put J {misjudged:.1%} low"
    return replace(second, message=note + ")")


def _continued(
    robot: Robot,
    q0: NDArray[np.float64],
    qe: NDArray[np.float64],
    cost: Cost,
    goal: ToolPose | None,
    first: MethodOutcome,
    start: BSplinePath,
    common: dict[str, object],
    history: list[Iteration],
    collisions: CollisionModel | None,
    via: tuple[float, ...] = (),
    duration: tuple[float, bool] | None = None,
    ends: tuple[NDArray[np.float64] | None, NDArray[np.float64] | None] = (None, None),
) -> MethodOutcome:
    """Stage 2 continued after ``first`` from ``start`` (its path, or the same curve with more
    control points), with θe free along the goal pose ``goal`` (None: θe as ``start`` ends);
    its iterates follow the first run's in the history (its iterate 0, the same path, is not
    repeated). The first run's outcome where the second ends higher."""
    run: Run = common["run"]  # type: ignore[assignment]
    offset = len(history) - 1

    def follow(entry: Iteration, timing: TimingResult) -> None:
        if entry.index > 0:
            run.accept(replace(entry, index=entry.index + offset), timing)

    options = dict(
        common, run=replace(run, accept=follow, max_iterations=run.max_iterations - offset)
    )
    second = sequential_convex(
        robot,
        q0,
        qe,
        cost,
        **options,
        collisions=collisions,
        start=start,
        goal=goal,
        via=via,
        duration=duration,
        ends=ends,
    )
    if second.timing.J > first.timing.J:  # e.g. re-timed on another grid: keep the first
        return first
    return MethodOutcome(
        second.timing, second.reason, second.message, first.evaluations + second.evaluations
    )


def _certify(collisions: CollisionModel, path: Path) -> Clearance:
    """The returned path's certified clearance; a plan that is not certified is an error."""
    clear = collisions.path_clearance(path)
    if not clear.certified:  # every iterate was certified: this is a defect, never a plan
        raise SolverError(
            f"the planned path is not certified collision-free: {clear.closest.pair} at "
            f"{clear.closest.distance * 1e3:.2f} mm (margin {collisions.margin * 1e3:.1f} mm) "
            f"at s = {clear.s:.4f}"
        )
    return clear


def _check_jerk_cost(robot: Robot, cost: Cost) -> None:
    """The jerk-limited timing minimises time or 1 + Σ w u² only."""
    if robot.limits.smooth and not isinstance(cost, TimeCost | TorqueCost):
        raise ConfigurationError(
            "with jerk or torque-rate limits the cost must be TimeCost or TorqueCost "
            "(1 + Σ w u²), got "
            f"{type(cost).__name__}"
        )


def _check_method(
    method: Method | str | None, options: SCPOptions | PaperOptions | None, cost: Cost
) -> tuple[Method, SCPOptions | PaperOptions]:
    if method is None:
        method = Method.SCP if isinstance(cost, TorqueCost) else Method.PAPER
    try:
        method = Method(method)
    except ValueError:
        raise ConfigurationError(
            f"method must be one of {', '.join(METHODS)}, got {method!r}"
        ) from None
    expected = SCPOptions if method == Method.SCP else PaperOptions
    if options is None:
        options = expected()
    if not isinstance(options, expected):
        raise ConfigurationError(
            f"method {method.value!r} takes {expected.__name__}, got {type(options).__name__}"
        )
    if method == Method.SCP:
        if not isinstance(cost, TorqueCost):
            raise ConfigurationError(
                f"method 'scp' needs a cost f0 = 1 + Σ w u² (TimeCost or TorqueCost); for "
                f"{cost.describe()!r} use method='paper'"
            )
        k = options.control_points
        if not isinstance(k, int | np.integer) or not 2 <= k <= MAX_CONTROL_POINTS:
            raise ConfigurationError(
                f"control_points must be an integer from 2 to {MAX_CONTROL_POINTS}, got {k!r}"
            )
        if options.knots not in ("clustered", "uniform"):
            raise ConfigurationError(
                f"knots must be 'clustered' or 'uniform', got {options.knots!r}"
            )
        if not isinstance(options.grid, int | np.integer) or not 2 <= options.grid <= MAX_GRID:
            raise ConfigurationError(
                f"the optimisation grid must be an integer from 2 to {MAX_GRID}, "
                f"got {options.grid!r}"
            )
        for name in ("trust_radius", "min_trust_radius", "tolerance"):
            value = getattr(options, name)
            if not (np.isfinite(value) and value > 0):
                raise ConfigurationError(f"{name} must be a positive number, got {value}")
        if not (is_number(options.continuation) and 1.0 <= options.continuation <= 1e6):
            raise ConfigurationError(
                f"continuation must be a number from 1 (off) to 1e6, got {options.continuation!r}"
            )
        refinements = options.refinements
        if isinstance(refinements, bool) or not (
            isinstance(refinements, int | np.integer) and 0 <= refinements <= 3
        ):
            raise ConfigurationError(
                f"refinements must be an integer from 0 to 3, got {refinements!r}"
            )
    else:
        for name in ("gamma", "alpha", "delta_t", "tolerance"):
            value = getattr(options, name)
            if not (np.isfinite(value) and value > 0):
                raise ConfigurationError(f"{name} must be a positive number, got {value}")
        if not isinstance(options.trials, int | np.integer) or not 1 <= options.trials <= 100:
            raise ConfigurationError(
                f"trials must be an integer from 1 to 100, got {options.trials!r}"
            )
    return method, options


def _format(entry: Iteration) -> str:
    alpha = "" if entry.alpha is None else f"{entry.alpha:.3g}"
    return (
        f"iteration {entry.index:3d}  J = {entry.J:.6f}  step = {alpha:>8}  "
        f"te = {entry.duration:.4f} s  {entry.wall_time:7.2f} s"
    )
