"""Stage 1 end to end: sample the path, solve, keep the limits between samples, return a motion."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..cost import Cost, TimeCost, TorqueCost, check_cost
from ..errors import ConfigurationError, InfeasiblePathError, SolverError
from ..path import Path
from ..robot import check_robot
from ..trajectory import MotionCost, Trajectory
from .between import BetweenSamples, inherit_margins, tighten, uniform_slow_down
from .discretisation import Discretisation
from .duration import as_fast_as, check_duration, duration_of, solve_for_duration
from .problem import build_timing_problem, with_moving_ends
from .solvers import TimingMethod, TimingSolution, TimingStatus, out_of_time, solve_timing

if TYPE_CHECKING:
    from numpy.typing import ArrayLike, NDArray

    from ..robot import Robot
    from .problem import TimingProblem

__all__ = ["TimingResult", "optimal_timing"]


@dataclass(frozen=True)
class TimingResult(MotionCost):
    """The optimal timing of a path: a trajectory and its cost.

    Attributes
    ----------
    trajectory
        θ(t), θ̇(t), θ̈(t), u(t) for t ∈ [0, duration].
    cost
        The running cost f0 that was minimised.
    objective
        The discretised cost the solver minimised (differs from J by the discretisation, O(Δσ²)).
    problem
        The problem as finally solved (tightened where the motion left a limit between samples).
    b
        b = (dσ/dt)² at its knots σ (``problem.sigma``), shape (N+1,).
    status, solver, iterations, message
        As in :class:`~nearopt.timing.TimingSolution`.
    wall_time
        Time spent [s], building the problem included.
    """

    trajectory: Trajectory
    cost: Cost
    objective: float
    problem: TimingProblem
    b: NDArray[np.float64]
    status: TimingStatus
    solver: TimingMethod
    iterations: int
    message: str
    wall_time: float


def optimal_timing(
    robot: Robot,
    path: Path,
    cost: Cost | None = None,
    *,
    grid: int = 200,
    velocity_limits: bool = True,
    tolerance: float = 1e-9,
    guess: NDArray[np.float64] | None = None,
    margins: TimingProblem | None = None,
    time_limit: float = np.inf,
    qd0: ArrayLike | None = None,
    qde: ArrayLike | None = None,
    duration: float | None = None,
    max_duration: float | None = None,
) -> TimingResult:
    """Stage 1: the timing λ(s) of a path that minimises J = ∫ f0 dt under the robot's limits.

    Parameters
    ----------
    robot
        The arm; its effort limits, its acceleration limits (if it has any, see
        :meth:`~nearopt.Robot.with_limits`) and, if ``velocity_limits``, its speed limits are
        enforced, at all times (not only at samples; see :class:`BetweenSamples`).
    path
        The spatial path θ(s).
    cost
        The running cost f0; default :class:`~nearopt.TimeCost` (time-optimal).
    grid
        N, the number of grid segments.
    velocity_limits
        Enforce |θ̇_i| ≤ v_i (the URDF's velocity limits unless overridden).
    tolerance
        Optimality tolerance of the NLP.
    guess
        b = (dσ/dt)² at the grid's knots of a path close to this one (e.g. the last iterate of
        stage 2), shape (N+1,): where a damping torque is first linearised.
    margins
        A problem on the same grid for a path close to this one, whose torque and acceleration
        margins (where its motion bulged out between samples) this one starts from, so that it
        is seldom tightened and solved again.
    time_limit
        Wall-time budget of the whole call [s], checked between and inside its solves; a
        solve cannot be stopped while Clarabel factorises, so a grid of 10⁵ segments may
        overrun it by a few seconds.
    qd0, qde
        The joint velocities θ̇(0) and θ̇(t_e) [rad/s or m/s], shape (n,); None: at rest. Each
        must point along the path there (θ̇ = θ'(s)·ṡ) and be within the speed limits.
    duration, max_duration
        t_e = ``duration`` exactly, or t_e ≤ ``max_duration`` [s] (one or neither), J of
        ``cost`` minimised under it (a :class:`~nearopt.TimeCost` or
        :class:`~nearopt.TorqueCost`; see :mod:`nearopt.timing.duration`). An exact duration
        is met to 1e-9 relative (to rounding for a motion at rest at both ends).

    Returns
    -------
    TimingResult
        The trajectory, J (integrated over the returned motion) and the solver's report.

    Raises
    ------
    InfeasiblePathError
        If gravity alone exceeds a torque limit somewhere on the path (names joint, s, θ, excess),
        or no timing starts at ``qd0`` and ends at ``qde`` within the limits, or the duration
        asked for is shorter than the time-optimal one (named).
    ConfigurationError
        If ``qd0`` or ``qde`` is beyond a speed limit or does not point along the path.
    SolverError
        If the solver fails, or the time limit runs out.
    """
    t0 = time.perf_counter()
    deadline = t0 + time_limit
    check_robot(robot)
    cost = TimeCost() if cost is None else check_cost(cost)
    if not isinstance(path, Path):
        raise ConfigurationError(
            "path must be a nearopt path — StraightPath, SplinePath, BSplinePath, or an object "
            f"with s_end, dof and __call__(s, order) — got {type(path).__name__} {path!r:.60}"
        )
    problem = build_timing_problem(robot, path, grid=grid, velocity_limits=velocity_limits)
    problem = with_moving_ends(problem, qd0, qde)
    target = _duration_target(duration, max_duration, cost, problem)
    if not np.any(problem.dtheta):
        raise ConfigurationError(
            "the path does not move (θ' = 0 all along it, e.g. θ0 = θe): there is nothing to time"
        )
    if margins is not None and margins.sigma.size == problem.sigma.size:
        problem = inherit_margins(problem, margins)
    try:
        if target is None:
            problem, sol, b = _solve_exactly(robot, path, problem, cost, tolerance, guess, deadline)
        else:

            def exactly(prob: TimingProblem, below: float) -> tuple:
                return _solve_exactly(
                    robot, path, prob, cost, tolerance, guess, deadline, target, below
                )

            problem, sol, b = _solve_for_duration(problem, cost, target, exactly)
    except SolverError as exc:
        if exc.status == "MaxTime":  # say the caller's budget, not what was left of it
            raise out_of_time(problem, time_limit) from None
        raise
    # back from σ = s / s_e to the path's own s: b_s = s_e² b_σ
    traj = Trajectory(
        path, problem.sigma * path.s_end, b * path.s_end**2, robot.inverse_dynamics_batch
    )
    return TimingResult(
        trajectory=traj,
        cost=cost,
        objective=sol.objective,
        problem=problem,
        b=b,
        status=sol.status,
        solver=sol.solver,
        iterations=sol.iterations,
        message=sol.message,
        wall_time=time.perf_counter() - t0,
    )


def _duration_target(
    duration: object, max_duration: object, cost: Cost, problem: TimingProblem
) -> tuple[float, bool] | None:
    """(T, exact) of a duration asked for, None for none; ConfigurationError for both or a
    bad value."""
    exact, most = check_duration("duration", duration), check_duration("max_duration", max_duration)
    if exact is not None and most is not None:
        raise ConfigurationError("give duration (t_e = T) or max_duration (t_e ≤ T), not both")
    if exact is None and most is None:
        return None
    if not isinstance(cost, TorqueCost):
        raise ConfigurationError(
            f"a duration is kept for f0 = 1 + Σ w u² (TimeCost, TorqueCost), not {cost.describe()}"
        )
    return (exact, True) if exact is not None else (most, False)


def _solve_exactly(
    robot: Robot,
    path: Path,
    problem: TimingProblem,
    cost: Cost,
    tolerance: float,
    guess: NDArray[np.float64] | None,
    deadline: float,
    target: tuple[float, bool] | None = None,
    below: float = 0.0,
) -> tuple[TimingProblem, TimingSolution, NDArray[np.float64]]:
    """Solve on the grid, then keep the limits between samples (see :func:`optimal_timing`);
    with a duration ``target`` (T, exact), every solve is a search over the cost's weights
    (:func:`~nearopt.timing.duration.solve_for_duration`) aiming ``below`` (a fraction) under T.

    Returns the problem last solved (margins tightened), its solution and the b returned.
    """

    def left() -> float:
        if time.perf_counter() >= deadline:
            raise out_of_time(problem, 0.0)
        return deadline - time.perf_counter()

    def plain(
        prob: TimingProblem,
        f0: Cost,
        start: NDArray | None,
        price: NDArray | None = None,
        kernel: bool = False,
    ) -> TimingSolution:
        return solve_timing(
            prob,
            f0,
            tolerance=tolerance,
            guess=start,
            time_limit=left(),
            price=price,
            method=TimingMethod.INTERIOR if kernel else None,
        )

    def timed(prob: TimingProblem, start: NDArray | None) -> TimingSolution:
        if target is None:
            return plain(prob, cost, start)
        found, _ = solve_for_duration(
            prob, cost, target[0], exact=target[1], solve=plain, guess=start, below=below
        )
        return found

    sol = timed(problem, guess)
    between = BetweenSamples(robot, path, problem)  # and between them
    for _ in range(4):
        # where the motion leaves a limit between samples: a uniform slow-down by α if that
        # costs less than 1e-5 of b (below the grid's own error), otherwise tighten and re-solve
        # (a motion with fixed moving ends has no uniform slow-down: it is left as it is where
        # α ≥ 1 − 1e-9, an excess within the safety margin of the limits, 1e-8 of them)
        b = uniform_slow_down(between, sol.b)
        ok = 1.0 - (1e-5 if problem.at_rest else MOVING_EXCESS)
        if np.all(b >= ok * sol.b):
            b = b if problem.at_rest else sol.b
            break
        tighter = tighten(problem, between, sol.b)
        if tighter is None:
            break
        problem = tighter
        sol = timed(problem, sol.b)
    else:
        b = uniform_slow_down(between, sol.b)
        moving = sol.b > 0.0  # (a rest end's b = 0 stays 0)
        shrink = 1.0 - float(np.min(b[moving] / sol.b[moving], initial=1.0))
        if not problem.at_rest:
            # an excess a slow-down by ≤ 4e-7 would take back is within verify's tolerance
            # (1e-6 of a limit: the slow-down changes speeds by half of it, torques' inertial
            # parts by about as much): the motion is left as it is; more is an error. Such an
            # excess sits next to a moving end whose given state is at a limit (a plan's own
            # state re-planned from: 1.07e-7, four tightenings left it there)
            if shrink > MOVING_SLACK:
                raise SolverError(
                    "stage 1 could not hold the limits between its samples with the motion's "
                    f"moving ends fixed (it would have to slow down by {shrink:.2e} of b); "
                    "try another grid"
                )
            b = sol.b
    return problem, sol, b


def _solve_for_duration(
    problem: TimingProblem,
    cost: Cost,
    target: tuple[float, bool],
    exactly: Callable[[TimingProblem, float], tuple],
) -> tuple[TimingProblem, TimingSolution, NDArray[np.float64]]:
    """:func:`_solve_exactly` with a duration (T, exact) — ``exactly(problem, below)``. Where
    the uniform slow-down that keeps a motion at rest within its limits between the samples
    lengthened it past T, the search aims that much lower and runs again (at most twice more);
    a motion at rest is then slowed down to exactly T where the bound binds (b → αb, α ≤ 1:
    every torque stays between gravity's and the motion's)."""
    below = 0.0
    for _ in range(3):
        solved, sol, b = exactly(problem, below)
        over = duration_of(solved, b) / target[0] - 1.0
        if not solved.at_rest or over <= 1e-12:
            break
        below += 2.0 * over
    if solved.at_rest:
        b = _slowed_to(solved, b, target, below)
    # the user's J on the grid, not that of the weights searched
    objective = Discretisation.of(solved).objective(b[1:-1], cost)[0]
    return solved, dataclasses.replace(sol, objective=objective), b


MOVING_EXCESS = 1e-9  # the slow-down a motion with moving ends is left without (see above)
MOVING_SLACK = 4e-7  # … after four tightenings


def _slowed_to(
    problem: TimingProblem,
    b: NDArray[np.float64],
    target: tuple[float, bool],
    below: float,
) -> NDArray[np.float64]:
    """b slowed down uniformly (b → αb, α ≤ 1: every torque between gravity's and the
    motion's) to t_e = T, where the search met or passed T (t_e ≤ T was binding, or t_e = T
    is asked for); b as it is where t_e ≤ T holds with room."""
    t_e = duration_of(problem, b)
    duration, exact = target
    if not as_fast_as(t_e, duration, exact):  # the fastest motion, slowed between its samples
        raise InfeasiblePathError(
            f"duration {duration:.9g} s is shorter than the time-optimal motion along this "
            f"path that holds the limits between its samples too, {t_e:.9g} s"
        )
    if t_e >= duration or (not exact and t_e < duration * (1.0 - below - 1e-6)):
        return b  # as fast as T to stage 1's accuracy (never sped up), or the free optimum
    return b * (t_e / duration) ** 2
