"""Stage 1 end to end: sample the path, solve, keep the limits between samples, return a motion."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..cost import Cost, TimeCost, check_cost
from ..errors import ConfigurationError, SolverError
from ..path import Path
from ..robot import check_robot
from ..trajectory import MotionCost, Trajectory
from .between import BetweenSamples, inherit_margins, tighten, uniform_slow_down
from .problem import build_timing_problem
from .solvers import TimingMethod, TimingSolution, TimingStatus, out_of_time, solve_timing

if TYPE_CHECKING:
    from numpy.typing import NDArray

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

    Returns
    -------
    TimingResult
        The trajectory, J (integrated over the returned motion) and the solver's report.

    Raises
    ------
    InfeasiblePathError
        If gravity alone exceeds a torque limit somewhere on the path (names joint, s, θ, excess).
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
    if not np.any(problem.dtheta):
        raise ConfigurationError(
            "the path does not move (θ' = 0 all along it, e.g. θ0 = θe): there is nothing to time"
        )
    if margins is not None and margins.sigma.size == problem.sigma.size:
        problem = inherit_margins(problem, margins)
    try:
        problem, sol, b = _solve_exactly(robot, path, problem, cost, tolerance, guess, deadline)
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


def _solve_exactly(
    robot: Robot,
    path: Path,
    problem: TimingProblem,
    cost: Cost,
    tolerance: float,
    guess: NDArray[np.float64] | None,
    deadline: float,
) -> tuple[TimingProblem, TimingSolution, NDArray[np.float64]]:
    """Solve on the grid, then keep the limits between samples (see :func:`optimal_timing`).

    Returns the problem last solved (margins tightened), its solution and the b returned.
    """

    def left() -> float:
        if time.perf_counter() >= deadline:
            raise out_of_time(problem, 0.0)
        return deadline - time.perf_counter()

    sol = solve_timing(
        problem,
        cost,
        tolerance=tolerance,
        guess=guess,  # gravity at the knots
        time_limit=left(),
    )
    between = BetweenSamples(robot, path, problem)  # and between them
    for _ in range(4):
        # where the motion leaves a limit between samples: a uniform slow-down by α if that
        # costs less than 1e-5 of b (below the grid's own error), otherwise tighten and re-solve
        b = uniform_slow_down(between, sol.b)
        if np.all(b >= (1.0 - 1e-5) * sol.b):
            break
        tighter = tighten(problem, between, sol.b)
        if tighter is None:
            break
        problem = tighter
        sol = solve_timing(problem, cost, tolerance=tolerance, guess=sol.b, time_limit=left())
    else:
        b = uniform_slow_down(between, sol.b)
    return problem, sol, b
