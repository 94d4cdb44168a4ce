"""Stage 2 and the planner (Sections 5-6): improve the path itself, re-timing it by stage 1.

Every iterate is a path from θ0 to θe exactly, timed optimally by stage 1 (so it is feasible, at
rest at both ends, and the computation can stop at any time with the best plan so far). Two
updates:

``method="quasi-newton"`` (default)
    The path is a clamped cubic B-spline (:class:`~nearopt.BSplinePath`) whose end control points
    are θ0 and θe; the interior ones are moved by SciPy's L-BFGS-B to minimise stage 1's optimal
    cost J*(path), starting from the straight line of eqs. (28)-(29). The gradient is exact for
    the discretised problem: the envelope theorem at stage 1's KKT point
    (:func:`~nearopt.planning.timing_sensitivity`), one stage-1 solve per evaluation. Joint
    position limits are box bounds on the control points, which keep the curve inside them.
``method="paper"``
    The update of Section 6: the gradient η(t) of eq. (27) with respect to the torques (adjoint
    form, :func:`~nearopt.planning.torque_gradient`), improved torques u* = u − αη clipped to the
    limits (eqs. 22, 30), the next path from the two-point boundary-value problem (eq. 20), for
    +Δt and −Δt, the better kept; α is found by a line search instead of by hand.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np
from scipy.optimize import Bounds, minimize

from ..cost import Cost, TimeCost
from ..errors import ConfigurationError, InfeasiblePathError, SolverError
from ..path import BSplinePath, Path, StraightPath
from ..timing import (
    MAX_GRID,
    build_timing_problem,
    optimal_timing,
    solve_timing,
)
from ..trajectory import segment_times
from .records import Iteration, PlanResult
from .sensitivity import timing_sensitivity

if TYPE_CHECKING:
    from numpy.typing import ArrayLike, NDArray

    from ..robot import Robot

__all__ = ["plan", "METHODS"]

METHODS = ("quasi-newton", "paper")


def plan(
    robot: Robot,
    q0: ArrayLike,
    qe: ArrayLike,
    cost: Cost | None = None,
    *,
    method: str = "quasi-newton",
    grid: int = 200,
    control_points: int = 12,
    max_iterations: int = 200,
    time_limit: float = 300.0,
    tolerance: float = 1e-7,
    velocity_limits: bool = True,
    position_limits: bool = True,
    gamma: float = 0.1,
    callback: Callable[[Iteration], None] | None = None,
    verbose: bool = False,
) -> PlanResult:
    """Plan a near-optimum motion from rest at θ0 to rest at θe (Sections 4-6).

    Parameters
    ----------
    robot
        The arm; its torque (and by default speed and position) limits are enforced.
    q0, qe
        Start and goal configurations θ0, θe [rad], shape (n,).
    cost
        The running cost f0 (default: :class:`~nearopt.TimeCost`).
    method
        ``"quasi-newton"`` (default) or ``"paper"`` (Section 6's update); see the module docstring.
    grid
        N, stage 1's grid segments at every iteration.
    control_points
        Interior B-spline control points of the path (``"quasi-newton"``).
    max_iterations
        Iteration budget (accepted iterates); 0 times the straight line only (stage 1).
    time_limit
        Wall-time budget [s]; the best plan so far is returned when it runs out.
    tolerance
        Stop when an iteration lowers J by less than this fraction of J.
    velocity_limits, position_limits
        Enforce the robot's joint speed / position limits.
    gamma
        γ of eq. (33), the weight of the terminal penalty F in the gradient (``"paper"``).
    callback
        Called with every accepted :class:`Iteration`.
    verbose
        Print one line per iteration.

    Raises
    ------
    ConfigurationError
        On a bad argument (wrong length, NaN, outside the position limits, unknown method, …).
    InfeasiblePathError
        If the straight line itself cannot be timed (gravity exceeds a limit along it).
    """
    t_start = time.perf_counter()
    cost = TimeCost() if cost is None else cost
    if method not in METHODS:
        raise ConfigurationError(f"method must be one of {METHODS}, got {method!r}")
    for name, value, low, high in (
        ("max_iterations", max_iterations, 0, np.inf),
        ("grid", grid, 2, MAX_GRID),
    ):
        if not isinstance(value, int | np.integer) or not low <= value <= high:
            raise ConfigurationError(
                f"{name} must be an integer ≥ {low}" + (f" and ≤ {high}" if high < np.inf else "")
                + f", got {value!r}"
            )
    if not isinstance(control_points, int | np.integer) or control_points < 2:
        raise ConfigurationError(f"control_points must be an integer ≥ 2, got {control_points!r}")
    for name, value in (("time_limit", time_limit), ("tolerance", tolerance), ("gamma", gamma)):
        if not (np.isfinite(value) and value > 0):
            raise ConfigurationError(f"{name} must be a positive number, got {value}")
    q0 = robot.check_configuration(q0, "q0")
    qe = robot.check_configuration(qe, "qe")
    if position_limits:
        _check_within(robot, q0, "q0")
        _check_within(robot, qe, "qe")
    if np.array_equal(q0, qe):
        raise ConfigurationError(
            "q0 equals qe: a zero-length motion has nothing to plan (the arm stays where it is)"
        )
    options = dict(grid=grid, velocity_limits=velocity_limits)
    line = StraightPath(q0, qe)
    initial = optimal_timing(robot, line, cost, **options)
    history = [
        Iteration(0, initial.objective, None, initial.duration, initial.wall_time, line)
    ]

    def accept(entry: Iteration) -> None:
        history.append(entry)
        if verbose:
            print(_format(entry), flush=True)
        if callback is not None:
            callback(entry)

    if verbose:
        print(_format(history[0]), flush=True)
    if max_iterations == 0:
        path, status, evaluations = line, "iteration_limit", 1
        message = "max_iterations = 0: the straight line, timed by stage 1"
    elif method == "quasi-newton":
        path, status, message, evaluations = _quasi_newton(
            robot, q0, qe, cost, control_points, options, position_limits, max_iterations,
            time_limit, tolerance, t_start, accept,
        )
    else:
        from .paper import paper_iterations

        path, status, message, evaluations = paper_iterations(
            robot, initial, cost, options, position_limits, gamma, max_iterations, time_limit,
            tolerance, t_start, accept,
        )
    timing = initial
    if len(history) > 1:
        try:
            timing = optimal_timing(robot, path, cost, **options)
        except (InfeasiblePathError, SolverError) as exc:  # e.g. gravity between two knots
            path, message = line, f"{message}; the straight line is returned: {exc}"
    if timing.J > initial.J:  # the iterates improved stage 1's grid J, the motion did not
        path, timing = line, initial
        message += "; the straight line is returned: the last iterate's motion costs more"
    return PlanResult(
        robot=robot,
        cost=cost,
        trajectory=timing.trajectory,
        path=path,
        J=timing.J,
        duration=timing.duration,
        history=tuple(history),
        status=status,
        method=method,
        message=message,
        evaluations=evaluations,
        wall_time=time.perf_counter() - t_start,
        initial=initial,
        timing=timing,
    )


def _format(entry: Iteration) -> str:
    alpha = "" if entry.alpha is None else f"{entry.alpha:.3g}"
    return (
        f"iteration {entry.index:3d}  J = {entry.J:.6f}  alpha = {alpha:>8}  "
        f"te = {entry.duration:.4f} s  {entry.wall_time:7.2f} s"
    )


def _check_within(robot: Robot, q: NDArray[np.float64], what: str) -> None:
    lim = robot.limits
    for i, name in enumerate(robot.joint_names):
        if not lim.position_lower[i] <= q[i] <= lim.position_upper[i]:
            raise ConfigurationError(
                f"{what}[{i}] = {q[i]:.6g} rad is outside the position limits "
                f"[{lim.position_lower[i]:.6g}, {lim.position_upper[i]:.6g}] of joint {name!r}",
                joint=name,
            )


def _quasi_newton(
    robot: Robot,
    q0: NDArray[np.float64],
    qe: NDArray[np.float64],
    cost: Cost,
    interior: int,
    options: dict,
    position_limits: bool,
    max_iterations: int,
    time_limit: float,
    tolerance: float,
    t_start: float,
    accept: Callable[[Iteration], None],
) -> tuple[Path, str, str, int]:
    """L-BFGS-B on the interior B-spline control points, gradient by the envelope theorem."""
    start = BSplinePath.line(q0, qe, interior)
    n = robot.n
    cache: dict[tuple[bytes, int], NDArray[np.float64]] = {}

    def basis(at: NDArray[np.float64], order: int) -> NDArray[np.float64]:
        """∂θ^(order)(σ)/∂c of the interior control points at σ (the grid's are reused)."""
        key = (at.tobytes(), order)
        if key not in cache:
            cache[key] = start.basis(at, order)[:, 1:-1]
        return cache[key]
    ends = start.control_points[[0, -1]]
    evaluations = {"count": 0, "worst": np.inf}
    last: dict[str, object] = {}

    def controls(x: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.vstack([ends[:1], x.reshape(interior, n), ends[1:]])

    def objective(x: NDArray[np.float64]) -> tuple[float, NDArray[np.float64]]:
        evaluations["count"] += 1
        path = BSplinePath(controls(x))
        try:
            problem = build_timing_problem(robot, path, **options)
            sol = solve_timing(problem, cost)
        except (InfeasiblePathError, SolverError):
            # outside the feasible region (or a path the solver cannot time): a value above
            # every feasible one makes the line search step back; the gradient is not used there
            return 2.0 * evaluations["worst"], np.zeros_like(x)
        sens = timing_sensitivity(robot, problem, sol.b, cost)
        grad = sens.gradient(basis, problem.sigma)
        duration = float(np.sum(segment_times(problem.sigma, sol.b)))
        last.update(x=x.copy(), J=sol.objective, duration=duration)
        if not np.isfinite(evaluations["worst"]):
            evaluations["worst"] = sol.objective
        evaluations["worst"] = max(evaluations["worst"], sol.objective)
        return sol.objective, grad.ravel()

    x0 = start.control_points[1:-1].ravel()
    lower = np.tile(robot.limits.position_lower, interior)
    upper = np.tile(robot.limits.position_upper, interior)
    bounds = Bounds(lower, upper) if position_limits else None
    state = {"x": x0, "index": 0, "stop": ""}

    def on_iteration(intermediate_result: object) -> None:
        x = intermediate_result.x
        if last.get("x") is None or not np.array_equal(last["x"], x):
            objective(x)  # L-BFGS-B reports the point it evaluated last; this is a safeguard
        state["index"] += 1
        accept(
            Iteration(
                index=state["index"],
                J=float(last["J"]),
                alpha=float(np.max(np.abs(x - state["x"]))),
                duration=float(last["duration"]),
                wall_time=time.perf_counter() - t_start,
                path=BSplinePath(controls(x)),
            )
        )
        state["x"] = x.copy()
        if time.perf_counter() - t_start > time_limit:
            state["stop"] = "time_limit"
            raise StopIteration

    res = minimize(
        objective,
        x0,
        jac=True,
        method="L-BFGS-B",
        bounds=bounds,
        callback=on_iteration,
        options={"maxiter": max_iterations, "ftol": tolerance, "gtol": 1e-10, "maxcor": 50},
    )
    if state["stop"]:
        status, message = state["stop"], f"time limit of {time_limit} s reached"
    elif res.status == 1:
        status, message = "iteration_limit", str(res.message)
    elif res.status == 0:
        status, message = "converged", str(res.message)
    else:  # e.g. the line search found no lower J along the quasi-Newton direction
        status, message = "stalled", str(res.message)
    return BSplinePath(controls(state["x"])), status, message, evaluations["count"]

