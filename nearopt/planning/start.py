"""The path stage 2 starts from: the straight joint line (eqs. 28-29), the B-spline through
via-points, or, where either collides, the best of a few OMPL paths (RRT-Connect), each improved
by a few stage-2 iterations before the best is continued.
"""

from __future__ import annotations

import functools
import time
from typing import TYPE_CHECKING

import numpy as np

from ..collision.sampling import collision_free_path
from ..errors import (
    CollisionError,
    ConfigurationError,
    InfeasiblePathError,
    NearoptError,
    SolverError,
)
from ..parallel import in_parallel
from ..path import BSplinePath, Path, StraightPath
from ..timing import optimal_timing
from .ends import braking_distance, leaving_along, stopping_short
from .records import MAX_CONTROL_POINTS, Method, Run, SCPOptions, Segment
from .scp import knot_breaks, path_through, sequential_convex

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from ..collision import CollisionModel
    from ..cost import Cost
    from ..robot import Robot

__all__ = [
    "first_path",
    "screen",
    "around_obstacles",
    "position_bounds",
    "check_inside",
    "resting_ends",
    "SCREENING",
    "SEARCHES",
    "ompl_starts",
]

SCREENING = 6  # stage-2 iterations from each OMPL path before the best is continued
SEARCHES = (3, 2)
"""OMPL searches for the first path in a cell: at first, and then where fewer than two paths
were found. Three instead of five: on 36 seeded pairs of ``bench_cell.py`` (ur5, panda, xarm7)
J moved by −0.11 … +0.05 % (26 the same), the panda median 2.06 → 1.66 s (the slowest of five
searches set the time)."""


def first_path(setup: Segment) -> tuple[Path, Path | None, tuple[float, ...]]:
    """The path stage 2 starts from: the straight line, the B-spline through the via-points,
    or (where it collides) the best of a few OMPL paths. Returns it, the start given to stage 2
    (None: the straight line) and the via-points' σ."""
    robot, q0, qe, cost, options = setup.robot, setup.q0, setup.qe, setup.cost, setup.options
    vias, collisions, method = setup.vias, setup.collisions, setup.method
    position_limits, velocity_limits = setup.position_limits, setup.velocity_limits
    max_iterations, deadline = setup.max_iterations, setup.deadline
    line: Path = StraightPath(q0, qe)
    start = None
    via_s: tuple[float, ...] = ()
    # moving ends (plan refuses them with via-points and obstacles): the line leaving along them
    if setup.ends[0] is not None or setup.ends[1] is not None:
        line = start = _leaving_line(setup)
        return line, start, via_s
    if vias:
        points = np.vstack([q0, *vias, qe])
        same = np.flatnonzero(np.all(np.diff(points, axis=0) == 0.0, axis=1))
        if same.size:
            names = ["the start", *(f"via-point {k}" for k in range(len(vias))), "the goal"]
            raise ConfigurationError(
                f"{names[same[0]]} and {names[same[0] + 1]} are the same configuration: "
                "consecutive points (start, via-points, goal) must differ"
            )
        k = max(options.control_points, 4 * (len(vias) + 1))
        bounds = position_bounds(robot, position_limits)
        start, sigma = path_through(points, k, knot_breaks(options, k), None, *bounds)
        check_inside(robot, start, bounds)
        line, via_s = start, tuple(float(x) for x in sigma)
    if collisions is not None:
        if vias and not collisions.path_is_clear(line):
            start, sigma = around_obstacles(
                collisions,
                points,
                options,
                bounds,
                min(max(0.25 * (deadline - time.perf_counter()), 1e-3), 5.0),
            )
            line, via_s = start, tuple(float(x) for x in sigma)
        if not vias and not collisions.path_is_clear(line):
            k = options.control_points
            breaks = knot_breaks(options, k)
            # a few OMPL paths (around the obstacles on different sides), the cheapest first
            starts = ompl_starts(collisions, q0, qe, k, breaks, deadline)
            timed = []
            for candidate in starts:
                try:
                    timed.append(
                        (
                            optimal_timing(
                                robot,
                                candidate,
                                cost,
                                grid=options.grid,
                                velocity_limits=velocity_limits,
                            ).J,
                            candidate,
                        )
                    )
                except (InfeasiblePathError, SolverError):
                    continue
            if not timed:
                raise InfeasiblePathError(
                    "no collision-free path OMPL found can be timed within the limits"
                )
            timed.sort(key=lambda x: x[0])
            start = line = timed[0][1]
            if method == Method.SCP and max_iterations > SCREENING and len(timed) > 1:
                line, start = screen(
                    robot,
                    q0,
                    qe,
                    cost,
                    [c for _, c in timed[:3]],
                    velocity_limits=velocity_limits,
                    position_limits=position_limits,
                    options=options,
                    collisions=collisions,
                    deadline=deadline,
                )
    return line, start, via_s


def ompl_starts(
    collisions: CollisionModel,
    q0: NDArray[np.float64],
    qe: NDArray[np.float64],
    control_points: int,
    breaks: NDArray[np.float64] | None,
    deadline: float,
) -> list[BSplinePath]:
    """The OMPL candidates stage 2 may start from: :data:`SEARCHES` [0] searches at once, then
    :data:`SEARCHES` [1] more where they found fewer than two paths (each search seeded by its
    number: the first ones are the same either way). Raises a
    :class:`~nearopt.CollisionError` where the start or the goal collides, or where no search
    found a path."""
    found: list[BSplinePath] = []
    first = 0
    for count in SEARCHES:
        try:
            found += collision_free_path(
                collisions, q0, qe, control_points=control_points, breaks=breaks,
                attempts=count, first=first,
                time_limit=min(max(0.25 * (deadline - time.perf_counter()), 1e-3), 5.0),
            )  # fmt: skip
        except CollisionError as exc:
            if exc.pair is not None:  # the start or the goal collides
                raise
            if first + count == sum(SEARCHES) and not found:
                raise CollisionError(
                    f"no collision-free path from the start to the goal found by "
                    f"{sum(SEARCHES)} OMPL searches (the last {count}: {exc})"
                ) from None
        first += count
        if len(found) >= 2:
            break
    return found


def screen(
    robot: Robot,
    q0: NDArray[np.float64],
    qe: NDArray[np.float64],
    cost: Cost,
    candidates: list[BSplinePath],
    *,
    velocity_limits: bool,
    position_limits: bool,
    options: SCPOptions,
    collisions: CollisionModel,
    deadline: float,
) -> tuple[BSplinePath, BSplinePath]:
    """The first path stage 2 continues from: each OMPL candidate improved by
    :data:`SCREENING` iterations on the iterate grid, the best kept (the order of the candidates'
    own J predicts the optimum's poorly: ±15 % on panda in a cell), the candidates at the same
    time on this machine's cores (:func:`~nearopt.parallel.in_parallel`). Returns the chosen
    candidate and its improved path."""

    def improve(candidate: BSplinePath) -> tuple[float, Path] | None:
        try:
            outcome = sequential_convex(
                robot,
                q0,
                qe,
                cost,
                grid=options.grid,
                velocity_limits=velocity_limits,
                position_limits=position_limits,
                options=options,
                run=Run(SCREENING, deadline, time.perf_counter(), lambda *_: None),
                collisions=collisions,
                start=candidate,
            )
        except (InfeasiblePathError, SolverError):
            return None
        return outcome.timing.J, outcome.timing.trajectory.path

    best: tuple[float, BSplinePath, BSplinePath] | None = None
    tasks = [functools.partial(improve, c) for c in candidates]
    for candidate, improved in zip(candidates, in_parallel(tasks), strict=True):
        if improved is not None and (best is None or improved[0] < best[0]):
            best = (improved[0], candidate, improved[1])  # type: ignore[assignment]
    if best is None:
        return candidates[0], candidates[0]
    return best[1], best[2]


def around_obstacles(
    collisions: CollisionModel,
    points: NDArray[np.float64],
    options: SCPOptions,
    bounds: tuple[NDArray[np.float64] | None, NDArray[np.float64] | None],
    time_limit: float,
) -> tuple[BSplinePath, NDArray[np.float64]]:
    """A first path through via-points whose straight legs collide: each colliding leg is an
    OMPL path (RRT-Connect, certified, fitted), the legs joined into one polyline and the
    B-spline along it through the via-points exactly; certified, with a quarter more control
    points at a time where it does not keep the margin. Each colliding leg is the shortest of
    :data:`SEARCHES` [0] OMPL searches (run at the same time): a single search's detour may go
    the long way round, and stage 2 stays on its side. Returns it and the σ of the via-points."""
    legs = len(points) - 1
    polyline, exact = [points[:1]], []
    dense = np.linspace(0.0, 1.0, 4 * options.control_points + 1)[1:]
    for a, b in zip(points[:-1], points[1:], strict=True):
        if collisions.path_is_clear(StraightPath(a, b)):
            piece = b[None, :]
        else:
            found = collision_free_path(
                collisions,
                a,
                b,
                control_points=options.control_points,
                breaks=None,
                time_limit=time_limit / legs,
                attempts=SEARCHES[0],
            )
            pieces = [np.vstack([a, leg(dense, 0)]) for leg in found]
            piece = min(pieces, key=lambda x: np.sum(np.linalg.norm(np.diff(x, axis=0), axis=1)))
            piece = piece[1:]
        polyline.append(piece)
        exact.append(sum(len(p) for p in polyline) - 1)
    joined = np.vstack(polyline)
    k0 = max(options.control_points, 4 * legs)
    # a quarter more control points at a time: the fewest that keep the margin (stage 2's
    # steps cost more with every one; doubled, a via-point plan of panda took 128 and ended
    # 22 % above the plan whose path it was taken from)
    most = min(8 * k0, MAX_CONTROL_POINTS)
    for k in sorted({min(int(round(k0 * 1.25**i)), most) for i in range(11)}):
        path, sigma = path_through(
            joined, k, knot_breaks(options, k) if k == k0 else None, exact[:-1], *bounds
        )
        if collisions.path_is_clear(path):
            check_inside(collisions.robot, path, bounds)
            return path, sigma
    raise CollisionError(
        "no B-spline through the via-points keeps the margin along the collision-free legs "
        f"OMPL found (tried up to {most} control points)"
    )


LEAST_LEG = 1e-6
"""The shortest end leg of a first path leaving along a velocity, relative to the end's largest
|θ| (at least 1 rad): a control point within about 1e-8 of that |θ| of its end would be off the
velocity's ray by rounding (stage 1 holds the direction to 1e-8)."""


def _leaving_line(setup: Segment) -> BSplinePath:
    """The straight line with the plan's boundary velocities
    (:func:`~nearopt.planning.ends.leaving_along`): of the end legs of 1, 2, 4 and 8 times the
    line's own first leg (and 1/16 and 1/4 of it where every moving end brakes within that: slow
    ends, whose direction hardly matters) and of 1 and 2 times the braking distance at each
    moving end (fast ones: overshoot and come back), the one stage 1 times at the lowest J on
    stage 2's grid; stage 1's InfeasiblePathError where it can time none (the arm cannot brake
    or turn in time on any)."""
    robot, options = setup.robot, setup.options
    k = options.control_points
    moving = (setup.ends[0] is not None, setup.ends[1] is not None)
    line = BSplinePath.line(setup.q0, setup.qe, k, knot_breaks(options, k, moving))
    lower, upper = position_bounds(robot, setup.position_limits)
    if lower is None or upper is None:
        lower, upper = np.full(robot.n, -np.inf), np.full(robot.n, np.inf)
    points = line.control_points
    base = (np.linalg.norm(points[2] - points[0]), np.linalg.norm(points[-3] - points[-1]))
    brake = (
        braking_distance(robot, setup.q0, setup.ends[0], True),
        braking_distance(robot, setup.qe, setup.ends[1], False),
    )
    # short legs only where every moving end brakes within them (a fast end cannot take a
    # short leg, and stage 1 spends long proving it: 1.8 s on the panda)
    legs = [
        (f * base[0], f * base[1])
        for f in (1 / 16, 1 / 4, 1.0, 2.0, 4.0, 8.0)
        if f >= 1.0
        or all(v is None or d <= f * h for d, h, v in zip(brake, base, setup.ends, strict=True))
    ]
    # braking legs where they are longer than the shortest above (a leg of a rounding error
    # would leave the path's direction at the end to rounding)
    if all(
        v is None or (np.isfinite(d) and d > h / 16)
        for d, h, v in zip(brake, base, setup.ends, strict=True)
    ):
        legs += [(f * brake[0], f * brake[1]) for f in (1.0, 2.0)]
    # and none so short that rounding turns it off its ray (a goal 1e-9 rad away: a leg of
    # 1e-10 rad left θ0 2e-6 off qd0's direction, which stage 1 refused)
    least = [LEAST_LEG * max(1.0, float(np.max(np.abs(q)))) for q in (setup.q0, setup.qe)]
    legs = [
        leg
        for leg in legs
        if all(v is None or d >= m for d, m, v in zip(leg, least, setup.ends, strict=True))
    ]
    first_error: NearoptError | None = None
    best: tuple[float, BSplinePath] | None = None
    for path in leaving_along(robot, line, setup.ends, (lower, upper), legs, setup.velocity_limits):
        try:
            timing = optimal_timing(
                robot,
                path,
                setup.cost,
                grid=min(setup.grid, options.grid),
                velocity_limits=setup.velocity_limits,
                qd0=setup.ends[0],
                qde=setup.ends[1],
            )
        except (InfeasiblePathError, SolverError) as exc:
            first_error = first_error or exc
            continue
        if best is None or timing.J < best[0]:
            best = (timing.J, path)
    if best is None:
        for q, qd, at_start in ((setup.q0, setup.ends[0], True), (setup.qe, setup.ends[1], False)):
            why = stopping_short(robot, q, qd, (lower, upper), at_start)
            if why is not None:
                raise InfeasiblePathError(f"no plan: {why}")
        raise InfeasiblePathError(
            "no plan: the straight line with the boundary velocities (leaving along qd0, "
            f"arriving along qde) cannot be timed: {first_error}"
        )
    return best[1]


def resting_ends(setup: Segment) -> tuple[bool, bool]:
    """Whether each end is at rest or nearly (its velocity brakes within 1/16 of the first
    leg of the straight line whose knots cluster at rest ends: a direction that hardly
    matters)."""
    options, k = setup.options, setup.options.control_points
    points = BSplinePath.line(setup.q0, setup.qe, k, knot_breaks(options, k)).control_points
    leg = (np.linalg.norm(points[2] - points[0]), np.linalg.norm(points[-3] - points[-1]))
    brake = (
        braking_distance(setup.robot, setup.q0, setup.ends[0], True),
        braking_distance(setup.robot, setup.qe, setup.ends[1], False),
    )
    return (brake[0] <= leg[0] / 16, brake[1] <= leg[1] / 16)


def position_bounds(
    robot: Robot, position_limits: bool
) -> tuple[NDArray[np.float64] | None, NDArray[np.float64] | None]:
    """The position limits a first path through via-points keeps, when they are enforced."""
    if not position_limits:
        return None, None
    return robot.limits.position_lower, robot.limits.position_upper


def check_inside(
    robot: Robot,
    path: BSplinePath,
    bounds: tuple[NDArray[np.float64] | None, NDArray[np.float64] | None],
) -> None:
    """A first path whose control points leave the position limits is refused, naming the
    joint (its curve could leave them; stage 2 starts from feasible paths only)."""
    lower, upper = bounds
    if lower is None or upper is None:
        return
    c = path.control_points
    excess = np.maximum(lower - c, c - upper)
    k, j = np.unravel_index(np.argmax(excess), excess.shape)
    if excess[k, j] > 1e-9:
        raise InfeasiblePathError(
            f"no first path through the via-points keeps joint {robot.joint_names[j]!r} within "
            f"its position limits [{lower[j]:.6g}, {upper[j]:.6g}] (a control point at "
            f"{c[k, j]:.6g}): move the via-points away from the limit"
        )
