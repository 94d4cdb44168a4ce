"""A first collision-free path when the straight line collides: OMPL's RRT-Connect and its path
simplifier in joint space, fitted to stage 2's B-spline.

OMPL plans with a clearance larger than the margin (``clearance``) so that the B-spline, which
cuts the corners of OMPL's polyline, keeps the margin; every straight piece OMPL accepts is
certified collision-free by :meth:`CollisionModel.path_clearance`'s certificate
(``path_is_clear``; not sampled at a resolution).
The fitted B-spline is certified too; if it is not, more control points follow the polyline more
closely.

OMPL's random generator can be seeded once per process only; each search therefore runs in a
forked child seeded afresh, so that a request gives the same paths whatever ran before it.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import numpy as np

from ..errors import CollisionError, ConfigurationError
from ..parallel import cores, in_children
from ..path import BSplinePath, StraightPath

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from .model import CollisionModel

__all__ = ["collision_free_path", "search_paths", "fit_polyline", "OMPL_SEED"]

OMPL_SEED = 20260101
_seeded = False


def collision_free_path(
    collisions: CollisionModel,
    q0: NDArray[np.float64],
    qe: NDArray[np.float64],
    *,
    control_points: int,
    breaks: NDArray[np.float64] | None,
    time_limit: float,
    clearance: float | None = None,
    attempts: int = 3,
    first: int = 0,
) -> list[BSplinePath]:
    """Paths from θ0 to θe whose every pair keeps the margin, certified: one per OMPL search
    that succeeds (they may pass the obstacles on different sides).

    The ``attempts`` searches (numbered ``first``, ``first`` + 1, …) run at the same time, each
    in a forked child process whose OMPL generator is seeded afresh (:data:`OMPL_SEED` plus the
    search's number: a search gives the same path whichever others run with it), so the same
    request gives the same paths whatever ran before in this process (OMPL seeds once per
    process) and however the children share the cores; where ``os.fork`` is missing they run
    here one after the other (reproducible for the first request). Each has the whole time
    limit times the searches per core (a safety net: a search ends after a count of checks,
    and sharing a core slows it down). Parameters and errors as :func:`search_paths`.
    """
    if _seeded:  # OMPL runs in this process already (seeded here): it searches here again
        return search_paths(
            collisions, q0, qe, control_points=control_points, breaks=breaks,
            time_limit=time_limit, clearance=clearance, attempts=attempts,
        )  # fmt: skip
    arguments = dict(
        control_points=control_points,
        breaks=breaks,
        time_limit=time_limit * max(1.0, attempts / cores()),
        clearance=clearance,
    )

    def attempt(seed: int) -> list[NDArray[np.float64]] | CollisionError:
        try:
            found = search_paths(collisions, q0, qe, attempts=1, seed=seed, **arguments)  # type: ignore[arg-type]
        except CollisionError as exc:  # no path in this search: the others may find one
            return exc
        return [p.control_points for p in found]

    began = time.perf_counter()
    answers = in_children(
        [lambda i=i: attempt(OMPL_SEED + i) for i in range(first, first + attempts)],
        "the OMPL search",
    )
    found = [c for a in answers if not isinstance(a, CollisionError) for c in a]
    errors = [a for a in answers if isinstance(a, CollisionError)]
    if errors and errors[0].pair is not None:  # the start or the goal collides
        raise errors[0]
    if not found:  # (each search's message quotes its own scaled time limit)
        raise CollisionError(
            f"no collision-free path from the start to the goal found in "
            f"{time.perf_counter() - began:.3g} s by {attempts} OMPL searches at once "
            f"(RRT-Connect, each ending after {SEARCH_CHECKS} checks or its share of the time "
            "limit; the straight line collides)"
        )
    return [BSplinePath(c, breaks if c.shape[0] == control_points + 2 else None) for c in found]


SEARCH_CHECKS = 20_000  # validity and motion checks one OMPL search may take (about 1-2 s)
MOTION_SAMPLES = 4
"""Intervals of an OMPL motion's first pass (its certificate bisects where they do not
suffice)."""
KNOWN_STATES = 4096
"""States whose distances a search keeps for the motions that end there (then forgotten)."""


def search_paths(
    collisions: CollisionModel,
    q0: NDArray[np.float64],
    qe: NDArray[np.float64],
    *,
    control_points: int,
    breaks: NDArray[np.float64] | None,
    time_limit: float,
    clearance: float | None = None,
    attempts: int = 3,
    seed: int = OMPL_SEED,
) -> list[BSplinePath]:
    """:func:`collision_free_path` in this process, one search after the other.

    Parameters
    ----------
    collisions
        The bodies, the pairs and the margin.
    q0, qe
        Start and goal [rad or m], shape (n,), both clear of the margin.
    control_points
        Interior control points K of the returned B-spline (more if K cannot follow OMPL's path
        within the margin, up to 8 K).
    breaks
        Interior knots of the B-spline (as :class:`~nearopt.BSplinePath`), for K points.
    time_limit
        Budget for OMPL's searches and simplifications [s], a safety net: each search stops at
        its first solution or after ``SEARCH_CHECKS`` checks, each simplification after one
        pass, whatever the time.
    clearance
        The distance OMPL keeps [m] (default: margin + 2 cm).
    attempts
        Independent OMPL searches, sharing the time limit.
    seed
        OMPL's seed, where this process has not seeded it yet (OMPL seeds once per process).

    Raises
    ------
    CollisionError
        When no collision-free path is found within the time limit (or no B-spline of up to
        8 K control points follows OMPL's within the margin).
    """
    ob, og = _ompl(seed)
    margin = collisions.margin
    clearance = margin + 0.02 if clearance is None else clearance
    setup, checks = _ompl_setup(ob, og, collisions, q0, qe, clearance)
    found = _search(
        ob, setup, checks, collisions, q0, qe, control_points, breaks, time_limit, attempts
    )
    if not found:
        raise CollisionError(
            f"no collision-free path from the start to the goal found in {time_limit:.3g} s "
            f"(OMPL RRT-Connect's share of the time limit, clearance {clearance * 1e3:.0f} mm; "
            "the straight line collides)"
        )
    return found


def _ompl(seed: int = OMPL_SEED) -> tuple[object, object]:
    """OMPL's base and geometric modules, its log silenced and its generator seeded (with
    ``seed``) once per process."""
    try:
        from ompl import base as ob
        from ompl import geometric as og
        from ompl import util as ou
    except ImportError as exc:  # pragma: no cover - ompl is a dependency
        raise ConfigurationError(
            f"a collision-free start needs OMPL: pip install ompl ({exc})"
        ) from None
    global _seeded
    if not _seeded:
        ou.setLogLevel(ou.LOG_NONE)
        ou.RNG.setSeed(seed)
        _seeded = True
    return ob, og


def _ompl_setup(
    ob: object,
    og: object,
    collisions: CollisionModel,
    q0: NDArray[np.float64],
    qe: NDArray[np.float64],
    clearance: float,
) -> tuple[object, list[int]]:
    """RRT-Connect in the joints' box (the position limits, or ±π beyond the ends), its states
    kept ``clearance`` from collision (the margin next to the ends), its motions certified;
    returns the set-up and the counter of its checks."""
    margin = collisions.margin
    robot = collisions.robot
    n = robot.n
    lim = robot.limits
    lower = np.where(
        np.isfinite(lim.position_lower), lim.position_lower, np.minimum(q0, qe) - np.pi
    )
    upper = np.where(
        np.isfinite(lim.position_upper), lim.position_upper, np.maximum(q0, qe) + np.pi
    )
    for q, what in ((q0, "start"), (qe, "goal")):
        collisions.check_configuration(q, what)
    space = ob.RealVectorStateSpace(n)
    bounds = ob.RealVectorBounds(n)
    for i in range(n):
        bounds.setLow(i, float(lower[i]))
        bounds.setHigh(i, float(upper[i]))
    space.setBounds(bounds)
    setup = og.SimpleSetup(space)
    info = setup.getSpaceInformation()
    # the ends may be closer than `clearance` (not than the margin): OMPL's states near them are
    # held to the margin, the rest to the clearance
    end_distance = max(float(np.max(np.abs(upper - lower))) * 0.05, 1e-3)

    def level(q: NDArray[np.float64]) -> float:
        near = min(np.max(np.abs(q - q0)), np.max(np.abs(q - qe))) < end_distance
        return margin if near else clearance

    checks = [0]  # validity and motion checks so far: the searches' deterministic clock
    # the distances of the states checked last: RRT-Connect checks a motion right after its
    # new end (and, long before, its tree end), so the motion's ends need not be computed again
    known: dict[bytes, NDArray[np.float64]] = {}

    def distances(q: NDArray[np.float64]) -> NDArray[np.float64]:
        d = known.get(q.tobytes())
        if d is None:
            if len(known) >= KNOWN_STATES:
                known.clear()
            d = known[q.tobytes()] = collisions.distances(q)
        return d

    def valid(state: object) -> bool:
        checks[0] += 1
        q = np.array(state[0:n])  # type: ignore[index]
        d = distances(q)
        return bool(d.size == 0 or d.min() >= level(q))

    class Motion(ob.MotionValidator):  # type: ignore[misc, name-defined]
        def checkMotion(self, s1: object, s2: object) -> bool:  # noqa: N802 - OMPL's name
            checks[0] += 1
            a, b = np.array(s1[0:n]), np.array(s2[0:n])  # type: ignore[index]
            if np.array_equal(a, b):
                return valid(s1)
            lv = min(level(a), level(b))
            path = StraightPath(a, b)
            s = np.linspace(0.0, 1.0, MOTION_SAMPLES + 1)
            inner = collisions.distances_along(path(s[1:-1]))
            d = np.vstack([distances(a), inner, distances(b)])
            return collisions.path_is_clear(
                path, lv, samples=MOTION_SAMPLES, distances=d, exact_below=np.inf
            )

    setup.setStateValidityChecker(valid)
    motion = Motion(info)
    info.setMotionValidator(motion)
    start, goal = info.allocState(), info.allocState()
    start[0:n] = [float(x) for x in q0]
    goal[0:n] = [float(x) for x in qe]
    setup.setStartAndGoalStates(start, goal)
    setup.setPlanner(og.RRTConnect(info))
    return setup, checks


def _search(
    ob: object,
    setup: object,
    checks: list[int],
    collisions: CollisionModel,
    q0: NDArray[np.float64],
    qe: NDArray[np.float64],
    control_points: int,
    breaks: NDArray[np.float64] | None,
    time_limit: float,
    attempts: int,
) -> list[BSplinePath]:
    """Up to ``attempts`` searches, each simplified and fitted by a certified B-spline."""
    n = collisions.robot.n
    # Each search ends at its first solution or after SEARCH_CHECKS checks, and each
    # simplification after one pass: counted, not timed, so that the same request gives the same
    # paths however fast this process runs (a long-running one is slower). The wall-clock
    # time_limit only stops what is left once it has run out.
    deadline = time.perf_counter() + time_limit
    found: list[BSplinePath] = []
    for _ in range(attempts):
        if time.perf_counter() >= deadline:
            break
        setup.clear()
        first = checks[0]
        status = setup.solve(
            ob.PlannerTerminationCondition(
                lambda first=first: (
                    checks[0] - first > SEARCH_CHECKS or time.perf_counter() >= deadline
                )
            )
        )
        if status.getStatus() != ob.PlannerStatus.EXACT_SOLUTION:
            continue
        path = setup.getSolutionPath()
        setup.getPathSimplifier().simplify(path, ob.PlannerTerminationCondition(lambda: True))
        points = np.array([s[0:n] for s in path.getStates()], dtype=float)
        points[0], points[-1] = q0, qe
        for k in (control_points, 2 * control_points, 4 * control_points, 8 * control_points):
            spline = fit_polyline(points, k, breaks if k == control_points else None)
            if collisions.path_is_clear(spline):
                found.append(spline)
                break
    return found


def fit_polyline(
    points: NDArray[np.float64], interior: int, breaks: NDArray[np.float64] | None = None
) -> BSplinePath:
    """A clamped cubic B-spline whose control points lie on a joint-space polyline at its
    Greville abscissae by arc length (a straight polyline gives the line exactly).

    Parameters
    ----------
    points
        The polyline's vertices [rad or m], shape (m, n), m ≥ 2.
    interior
        Interior control points K.
    breaks
        Interior knots (default uniform).
    """
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(seg)])
    if arc[-1] <= 0.0:
        raise ConfigurationError("the polyline has zero length")
    u = BSplinePath.greville(interior + 2, breaks) * arc[-1]
    control = np.column_stack([np.interp(u, arc, points[:, i]) for i in range(points.shape[1])])
    return BSplinePath(control, breaks)
