"""Stage 2 by sequential convex programming: the path and its timing improved together.

The path is a clamped cubic B-spline θ(σ) = Σ_j B_j(σ) c_j with c_0 = θ0 and c_{K+1} = θe; its
interior control points p are what stage 2 moves. At the current path p⁰, timed optimally by
stage 1 (b⁰), every row of stage 1 (:class:`~nearopt.timing.Discretisation`) is linear in b for
the fixed path and is linearised in the path (:func:`~nearopt.planning.row_path_jacobian`):

    row(b, p⁰ + Δp) ≈ row(b, p⁰) + G(b⁰) Δp.

With it, stage 1's own second-order cone program (:func:`~nearopt.timing.solve_conic`) becomes a
convex program in (b, Δp) jointly — the torques of the cost and of the limits, the accelerations
and every joint's speed row linearised in the path, the paper's idea of linearised dynamics
(eqs. 20-26) taken to the path's parameters. The cost keeps its exact convex form in the
linearised torques (a Gauss-Newton model in the path, exact in the timing). A speed row
b θ'_i² ≤ v_i² enters as b ≤ v_i²/θ'_i² with that bound's tangent in θ' (convex, so the tangent
is conservative). Per-joint speed rows make two joints reaching their limits together a corner of
the convex model, not a kink of a gradient. A trust region on the change of θ' (|Δp_{j,i}| ≤
ρ_j·s_i/(K − 1) for control point j, s_i the joint's scale) and the position limits on the
control points (which keep the whole curve within them, convex-hull property) bound the step.
The new path is re-timed exactly by stage 1 and accepted if its J is lower; the gain is judged
against the decrease the model predicts from its own value at Δp = 0 (:func:`model_floor`: the
model leaves out stage 1's rows between the samples, so it lies a little below J); after a step
that did as well as the model predicted, ρ_j doubles for the control points whose step reached it (a
bend that needs room gets it without letting the rest of the path swing), and all shrink after
poor or rejected steps. Every accepted iterate is therefore a
path from θ0 to θe timed optimally by stage 1: feasible, at rest at both ends.

The convex model is solved by nearopt's own interior-point method with a dense Newton system in
(b, Δp) (:func:`~nearopt.timing.solve_joint`: a few hundred variables, 15–25 iterations, 3–4
times faster than Clarabel's conic form of it), from the iterate's own timing; where it does not
converge, Clarabel's second-order cone program solves the model instead.

The iterates are timed on the coarser grid ``SCPOptions.grid`` (64 segments by default) and the
best path is timed on the plan's grid at the end.

It stops when the model predicts no relative decrease above the tolerance (a stationary point of
the discretised problem, to first order), when a step the model saw gain less than the tolerance
raised J, when J changed by less than the tolerance in each of
the last three iterations, when the trust region has shrunk below its minimum, or at the
iteration / time budget.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from ..cost import TorqueCost
from ..errors import ConfigurationError, InfeasiblePathError, SolverError, UnreachablePoseError
from ..path import BSplinePath
from ..robot.kinematics import ToolPose, inverse_kinematics, task_jacobian
from ..timing import (
    Discretisation,
    LinearRows,
    duration_gradient,
    duration_of,
    is_solved,
    optimal_timing,
    solve_conic,
    solve_interior,
    solve_joint,
)
from .ends import MovingEnds, end_terms
from .linearisation import PathBasis, path_basis, row_path_jacobian
from .records import MethodOutcome, Run, SCPOptions, StopReason

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from ..collision import CollisionModel
    from ..cost import Cost
    from ..robot import Robot
    from ..timing import TimingResult

__all__ = [
    "sequential_convex",
    "IterateParts",
    "after_failure",
    "iterate_model",
    "new_radius",
    "model_floor",
    "solve_model",
    "trust_scale",
    "collision_rows",
    "CollisionSamples",
    "path_through",
    "knot_breaks",
    "iterate_grid",
    "through_vias",
    "onto_points",
]


# why a run converged (formatted with the tolerance, or the smallest trust radius)
_MODEL_GAINS_NOTHING = (
    "converged: the convex model finds no path that lowers J by more than {:g} relative"
)
_J_STOPPED = "converged: J changed by less than {:g} relative in each of the last 3 iterations"
_NOTHING_SEEN = (
    "converged: the convex model sees no path that lowers J by more than {:g} relative, "
    "and its step raised J"
)
_NO_STEP_LOWERS_J = "converged: no step longer than {:g} of the joints' scale lowers J"


def sequential_convex(
    robot: Robot,
    q0: NDArray[np.float64],
    qe: NDArray[np.float64],
    cost: Cost,
    *,
    grid: int,
    velocity_limits: bool,
    position_limits: bool,
    options: SCPOptions,
    run: Run,
    collisions: CollisionModel | None = None,
    start: BSplinePath | None = None,
    goal: ToolPose | None = None,
    via: tuple[float, ...] = (),
    duration: tuple[float, bool] | None = None,
    ends: tuple[NDArray[np.float64] | None, NDArray[np.float64] | None] = (None, None),
    via_poses: tuple[ToolPose | None, ...] = (),
) -> MethodOutcome:
    """Improve the path from the straight line by sequential convex programming.

    Parameters
    ----------
    robot
        The arm.
    q0, qe
        Start and goal [rad or m], shape (n,).
    cost
        The running cost (a :class:`~nearopt.TorqueCost`: the convex model needs
        f0 = 1 + Σ w u²).
    grid
        Stage 1's grid for the returned path; the iterates use ``options.grid`` (at least 4
        segments per control point) if coarser.
    velocity_limits, position_limits
        Which limits hold (position limits bound the control points).
    options
        The method's options.
    run
        The budget (iterations, deadline) and where the accepted iterates go (the first path
        as iterate 0 first).
    collisions
        Pairs of bodies kept apart by the margin along the whole path (see
        :func:`collision_rows`), or None.
    start
        The first path (default: the straight line with ``options.control_points`` interior
        points); its control points and knots are those of every iterate.
    goal
        A tool pose the end θe must keep (to 1e-10 m and rad): θe then moves with the path, its
        step in the null space of the frame's Jacobian and projected back onto the pose by
        inverse kinematics; None: θe fixed.
    via
        Path parameters σ_v where the path must keep its current configuration (via-points
        passed through: Σ_j B_j(σ_v) Δc_j = 0, exact since linear); ``start`` goes through them.
    duration
        (T, exact): every iterate timed with t_e = T (or ≤ T); the model keeps t_e, linearised
        at the iterate's timing, at T (:func:`_with_duration`; every trial is timed exactly).
    ends
        The joint velocities (qd0, qde) at the start and the end [rad/s or m/s], None: at rest
        there. ``start`` must leave θ0 along qd0 (reach θe along qde); every iterate does (the
        first and last interior control points on those rays, :mod:`nearopt.planning.ends`).
    """
    weights = cost.torque_weights(robot.n) if isinstance(cost, TorqueCost) else None
    if weights is None:
        raise SolverError("sequential convex programming needs f0 = 1 + Σ w u² (a TorqueCost)")
    n = robot.n
    start, k_count, breaks = _first_iterate(options, q0, qe, start)
    fixed = start.control_points[[0, -1]]
    grid_of_iterates = iterate_grid(grid, options, k_count)
    scale, lower, upper = trust_scale(robot, q0, qe, k_count, goal is not None, position_limits)
    kept = MovingEnds(*ends, q0, qe, k_count - 1, goal is not None)

    def path_of(p: NDArray[np.float64]) -> BSplinePath:
        end = fixed[1:] if goal is None else p[-n:][None, :]
        inner = p[: k_count * n].reshape(k_count, n)
        return BSplinePath(np.vstack([fixed[:1], inner, end]), breaks)

    time_it = _timer(robot, cost, velocity_limits, path_of, grid_of_iterates, duration, ends)

    p = start.control_points[1 : -1 if goal is None else None].ravel()
    timing = time_it(p)
    evaluations, index, small, failures = 1, 0, 0, 0
    run.report(0, timing, None, start)
    basis, moving = None, p.size // n  # moving: the interior control points (and θe, a pose)
    parts = IterateParts(timing, path_of(p))
    radius = np.full(moving, options.trust_radius)  # per control point (see new_radius)
    reason, message = StopReason.ITERATION_LIMIT, f"{run.max_iterations} iterations"
    while index < run.max_iterations:
        if run.out_of_time():
            reason, message = StopReason.TIME_LIMIT, "the time limit was reached"
            break
        disc = Discretisation.of(timing.problem)
        z = timing.b[1:-1]
        if basis is None:  # the grid (knots, interior points) is the same for every iterate
            basis = path_basis(timing.trajectory.path, disc, end=goal is not None)
        bound = np.repeat(radius, n) * scale
        parts = parts if parts.timing is timing else IterateParts(timing, path_of(p))
        model = iterate_model(
            robot, disc, z, basis, p, parts, bound, collisions, start, (via, via_poses), goal,
            duration, (kept, weights),
        )  # fmt: skip
        j0 = timing.objective
        step = solve_model(disc, weights, model, z, p, bound, lower, upper)
        if step is None:  # numerical trouble: a smaller step is a better-conditioned model
            failures, radius, retry = after_failure(failures, radius, options)
            if retry:
                continue
            reason, message = StopReason.SOLVER, "the convex model could not be solved"
            break
        failures = 0
        dp, predicted, z_model = step
        if j0 - predicted <= options.tolerance * abs(j0):
            reason, message = StopReason.CONVERGED, _MODEL_GAINS_NOTHING.format(options.tolerance)
            break
        p_trial, trial, timed, samples = _try_step(  # stage 1 of the trial from the model's b
            robot, through_vias(start, (via, via_poses), path_of, (lower, upper), p + dp, robot),
            goal, collisions, path_of,
            lambda q, like=timing, z=z_model, d=disc: time_it(q, like, d.b(z)), kept,
        )  # fmt: skip
        evaluations += timed
        gain = -np.inf if trial is None else j0 - trial.objective
        plain = duration is None and not robot.limits.smooth  # stage 1 by its own kernel alone
        promised = parts.floor_of(weights, plain) - predicted  # what the model sees it gain
        reach = np.max((np.abs(dp) / scale).reshape(moving, n), axis=1)  # per control point
        radius = new_radius(radius, gain, gain / max(promised, 1e-300), reach)
        if gain > 0.0:
            p, timing, index = p_trial, trial, index + 1
            parts = IterateParts(timing, path_of(p), samples=samples)  # the certificate's
            run.report(index, timing, float(np.max(np.abs(dp))), timing.trajectory.path)
            small = small + 1 if gain < options.tolerance * abs(j0) else 0
            if small == 3:
                reason, message = StopReason.CONVERGED, _J_STOPPED.format(options.tolerance)
                break
        stop = _stopped(gain, promised / abs(j0), radius, options)
        if stop is not None:
            reason, message = StopReason.CONVERGED, stop
            break
    if grid_of_iterates < grid:  # the returned path on the plan's own grid
        timing, message, timed = _on_plan_grid(
            lambda: time_it(p, on=grid), timing, message, grid_of_iterates
        )
        evaluations += timed
    return MethodOutcome(timing, reason, message, evaluations)


def through_vias(
    start: BSplinePath,
    vias: tuple[tuple[float, ...], tuple[ToolPose | None, ...]],
    path_of: Callable[[NDArray[np.float64]], BSplinePath],
    bounds: tuple[NDArray[np.float64], NDArray[np.float64]],
    p: NDArray[np.float64],
    robot: Robot | None = None,
) -> NDArray[np.float64] | None:
    """The iterate p moved by the least change (:func:`onto_points`) that puts θ(σ_v) back on
    the via-points (``vias``: their σ_v and, per via-point, the tool pose it keeps or None):
    ``start``'s θ at σ_v, or for a pose the configuration inverse kinematics finds from p's θ(σ_v)
    (None where it finds none: a step to reject). The model keeps them to its own accuracy only,
    and over many iterations that drifted by 1.6e-8 rad (kinova, verify asks 1e-8)."""
    via, poses = vias
    if not via:
        return p
    lower, upper = bounds
    sigma = np.asarray(via)
    n = start.dof
    here = path_of(p)(sigma)  # (V, n)
    target = start(sigma)
    for k, pose in enumerate(poses):
        if pose is not None:
            found = _onto(robot, pose, here[k])  # type: ignore[arg-type]
            if found is None:
                return None
            target[k] = found
    miss = target - here
    moving = p.size // n
    inner = start.basis(sigma)[:, 1 : 1 + moving]
    control = p.reshape(moving, n)
    step = onto_points(inner, miss, control, lower.reshape(moving, n), upper.reshape(moving, n))
    return p + step.ravel()


def _stopped(
    gain: float, promised: float, radius: NDArray[np.float64], options: SCPOptions
) -> str | None:
    """Why stage 2 has converged after a step (``promised``: the decrease the model saw in
    it, relative to J), or None: a step the model saw gain less than the tolerance raised J,
    or the trust region shrank below its minimum."""
    if gain <= 0.0 and promised <= options.tolerance:
        return _NOTHING_SEEN.format(options.tolerance)
    if radius.max() < options.min_trust_radius:
        return _NO_STEP_LOWERS_J.format(options.min_trust_radius)
    return None


def model_floor(timing: TimingResult, weights: NDArray[np.float64]) -> float:
    """The convex model's J at Δp = 0, what its predicted decrease is measured from: stage 1
    of the iterate's path on its grid without the rows between the samples, which the model
    leaves out (their path derivatives made every model solve slower than the iterations they
    saved). It lies below the iterate's J by what those rows cost (2–3e-4 relative on ur5 and
    panda); measured from J instead, a model whose steps can no longer lower J still predicted
    that much, so the stopping test never passed and the trust region shrank through ten
    rejected steps, and every ratio of gain to prediction came out low. J itself where the
    problem has no such rows or this solve fails."""
    problem = timing.problem
    if problem.interior is None:
        return timing.objective
    disc = Discretisation(replace(problem, interior=None))
    sol = solve_interior(disc, weights, guess=timing.b, tolerance=1e-9)
    if not sol.converged:
        return timing.objective
    return min(timing.objective, disc.objective(sol.z, timing.cost)[0])


def _first_iterate(
    options: SCPOptions,
    q0: NDArray[np.float64],
    qe: NDArray[np.float64],
    start: BSplinePath | None,
) -> tuple[BSplinePath, int, NDArray[np.float64] | None]:
    """The first iterate (``start``, or the straight line as a B-spline), its interior control
    points' count and its interior knots."""
    if start is not None:
        k_count = start.control_points.shape[0] - 2
        return start, k_count, start.knots[4:-4] if k_count > 2 else None
    k_count = options.control_points
    breaks = knot_breaks(options, k_count)
    return BSplinePath.line(q0, qe, k_count, breaks), k_count, breaks


def _with_duration(
    model: _Model,
    disc: Discretisation,
    z: NDArray[np.float64],
    duration: tuple[float, bool],
    p_size: int,
    end_gradient: NDArray[np.float64] | None = None,
) -> _Model:
    """The model with the duration's row: t_e linearised at the iterate's timing b,
    t_e(b) + ∇t_e·(b' − b) = T (or ≤ T), in units of T. t_e is convex in b, so the model's
    timing may last a little longer than T; the trial is timed to it exactly. With moving ends,
    ``end_gradient`` is ∂t_e/∂p through b_0 and b_N."""
    b = disc.b(z)
    grad = duration_gradient(disc.problem, b)[1:-1]
    t_now = duration_of(disc.problem, b)
    t, exact = duration
    path_part = np.zeros(p_size) if end_gradient is None else end_gradient
    row = sp.csr_matrix(np.concatenate([grad, path_part])[None, :] / t)
    level = (t - t_now + grad @ z) / t
    return _with_rows(model, row, np.array([level if exact else -np.inf]), np.array([level]))


def _timer(
    robot: Robot,
    cost: Cost,
    velocity_limits: bool,
    path_of: Callable[[NDArray[np.float64]], BSplinePath],
    grid_of_iterates: int,
    duration: tuple[float, bool] | None = None,
    ends: tuple[NDArray[np.float64] | None, NDArray[np.float64] | None] = (None, None),
) -> Callable[..., TimingResult]:
    """Stage 1 of the iterate with control points p: on the iterate grid (or ``on``), from the
    margins of a close timing (``like``) and a guess of b; under the duration, if any; with
    the boundary velocities ``ends``."""
    t, exact = duration or (None, False)

    def time_it(
        p: NDArray[np.float64],
        like: TimingResult | None = None,
        guess: NDArray[np.float64] | None = None,
        on: int = grid_of_iterates,
    ) -> TimingResult:
        return optimal_timing(
            robot,
            path_of(p),
            cost,
            grid=on,
            velocity_limits=velocity_limits,
            guess=guess,
            margins=None if like is None else like.problem,
            duration=t if exact else None,
            max_duration=None if exact else t,
            qd0=ends[0],
            qde=ends[1],
        )

    return time_it


def after_failure(
    failures: int, radius: NDArray[np.float64], options: SCPOptions
) -> tuple[int, NDArray[np.float64], bool]:
    """After the convex model failed: the failures in a row, the trust region cut to a quarter
    (a smaller step is a better-conditioned model), and whether to try again (fewer than 3
    failures, the radius above its minimum)."""
    failures, radius = failures + 1, 0.25 * radius
    return failures, radius, failures < 3 and radius.max() >= options.min_trust_radius


def new_radius(
    radius: NDArray[np.float64],
    gain: float,
    ratio: float,
    reach: NDArray[np.float64],
) -> NDArray[np.float64]:
    """The trust region after a step that moved each control point by ``reach`` (fractions of
    scale): after a step that did as the model predicted, doubled for the control points that
    reached it (the others did not need more room); after a poor one, cut to half the step's
    length, after a rejected one to a quarter, for all of them."""
    if gain > 0.0:
        if ratio > 0.75:
            return np.where(reach > 0.9 * radius, 2.0 * radius, radius)
        if ratio < 0.25:
            return np.minimum(radius, 0.5 * np.max(reach))
        return radius
    return np.minimum(radius, 0.25 * np.max(reach))


def trust_scale(
    robot: Robot,
    q0: NDArray[np.float64],
    qe: NDArray[np.float64],
    k_count: int,
    moving_goal: bool,
    position_limits: bool,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The trust region's scale of every moving coordinate (the interior control points, and θe
    with a goal pose) and their bounds (the position limits, when they hold)."""
    n, lim = robot.n, robot.limits
    # a control point moved by δ changes θ' by about δ·(K − 1): the trust region is measured in
    # changes of θ' relative to each joint's scale (its motion, at least 10 % of its range and
    # 0.1 rad), where the linearisation's error grows
    scale = np.maximum.reduce([np.abs(qe - q0), 0.1 * _range(lim), np.full(n, 0.1)])
    moving = k_count + moving_goal  # the interior control points, and θe with a goal
    scale = np.tile(scale / (k_count - 1), moving)
    lower = np.tile(lim.position_lower, moving) if position_limits else np.full(n * moving, -np.inf)
    upper = np.tile(lim.position_upper, moving) if position_limits else np.full(n * moving, np.inf)
    return scale, lower, upper


def _on_plan_grid(
    time_it: Callable[[], TimingResult], timing: TimingResult, message: str, grid_of_iterates: int
) -> tuple[TimingResult, str, int]:
    """The returned path timed on the plan's own grid (the iterate's timing kept, and said,
    where stage 1 fails there); the stage-1 solves spent."""
    try:
        return time_it(), message, 1
    except (InfeasiblePathError, SolverError) as exc:  # keep the iterate's own timing
        return (
            timing,
            message
            + (
                f"; timed on the iterate grid ({grid_of_iterates} segments): on the plan's "
                f"grid stage 1 failed ({exc})"
            ),
            0,
        )


@dataclass
class IterateParts:
    """What the convex model takes from the iterate alone, not from the trust region: built
    once per iterate (a rejected step's smaller model takes it again)."""

    timing: TimingResult
    path: BSplinePath
    jacobian: sp.csr_matrix | None = None
    samples: CollisionSamples | None = None
    floor: float | None = None

    def floor_of(self, weights: NDArray[np.float64], plain: bool) -> float:
        """The model's J at Δp = 0 (:func:`model_floor`, once per iterate; the iterate's J
        where stage 1 is not its kernel alone, ``plain`` False: durations, jerk limits)."""
        if self.floor is None:
            self.floor = model_floor(self.timing, weights) if plain else self.timing.objective
        return self.floor


def iterate_model(
    robot: Robot,
    disc: Discretisation,
    z: NDArray[np.float64],
    basis: PathBasis,
    p: NDArray[np.float64],
    parts: IterateParts,
    reach: NDArray[np.float64],
    collisions: CollisionModel | None,
    start: BSplinePath,
    vias: tuple[tuple[float, ...], tuple[ToolPose | None, ...]],
    goal: ToolPose | None,
    duration: tuple[float, bool] | None = None,
    ends: tuple[MovingEnds, NDArray[np.float64]] | None = None,
) -> _Model:
    """The convex model at the iterate p (timing z; its path and what else depends on the
    iterate alone in ``parts``): stage 1's rows linearised in
    the path, the clearances, the via-points kept (``vias``: their σ_v and the pose each keeps
    or None; B(σ_v) Δp = 0 per joint, or J_pose B(σ_v) Δp = 0 for a pose), θe kept on the
    pose (J_task Δθe = 0) and the ends' directions kept with their b_0, b_N following the path
    (``ends``: the moving ends and the torque weights, :mod:`nearopt.planning.ends`)."""
    n = robot.n
    if parts.jacobian is None:
        parts.jacobian = row_path_jacobian(robot, disc, z, basis, between=False)
    jac = parts.jacobian
    terms = None
    if ends is not None and ends[0].moving:
        terms = end_terms(disc, z, basis, *ends)
        jac = jac + terms.jacobian
    model = _model(disc, z, jac, reach)
    if terms is not None:
        rows = ends[0].direction_rows(p.size)
        zero = np.zeros(rows.shape[0])
        model = replace(_with_rows(model, rows, zero, zero), price=terms.price)
    if collisions is not None:
        if parts.samples is None:
            parts.samples = CollisionSamples(collisions, parts.path, end=goal is not None)
        model = _with_rows(  # a joint's largest step bound over the control points
            model,
            *collision_rows(
                collisions,
                parts.path,
                reach.reshape(-1, n).max(axis=0),
                end=goal is not None,
                samples=parts.samples,
            ),
        )
    via, poses = vias
    if via:  # every iterate goes through the via-points: B(σ_v) Δp = 0 per joint (J B Δp: a pose)
        at = start.basis(np.asarray(via))[:, 1 : None if goal is not None else -1]
        blocks = [np.kron(at[k : k + 1], np.eye(n)) for k in range(len(via))]
        for k, pose in enumerate(poses):
            if pose is not None:
                blocks[k] = (
                    task_jacobian(robot, pose, parts.path(np.array([via[k]]))[0]) @ blocks[k]
                )
        rows = sp.csr_matrix(np.vstack(blocks))
        model = _with_rows(model, rows, np.zeros(rows.shape[0]), np.zeros(rows.shape[0]))
    if goal is not None:  # θe moves along the pose: J_task Δθe = 0
        task = task_jacobian(robot, goal, p[-n:])
        rows = sp.hstack([sp.csr_matrix((task.shape[0], p.size - n)), sp.csr_matrix(task)])
        model = _with_rows(model, rows.tocsr(), np.zeros(task.shape[0]), np.zeros(task.shape[0]))
    if duration is not None:  # t_e, linearised at the iterate's timing, kept at T
        end_gradient = None
        if terms is not None:
            per_end = _end_duration_gradient(disc, z)
            end_gradient = per_end[0] * terms.gradients[0] + per_end[1] * terms.gradients[1]
        model = _with_duration(model, disc, z, duration, p.size, end_gradient)
    return model


def _end_duration_gradient(disc: Discretisation, z: NDArray[np.float64]) -> tuple[float, float]:
    """∂t_e/∂b_0 and ∂t_e/∂b_N at the timing z (0 at a rest end) [s³]."""
    lam = np.sqrt(disc.b(z))
    ds = np.diff(disc.problem.sigma)
    first = -ds[0] / ((lam[0] + lam[1]) ** 2 * lam[0]) if lam[0] > 0.0 else 0.0
    last = -ds[-1] / ((lam[-2] + lam[-1]) ** 2 * lam[-1]) if lam[-1] > 0.0 else 0.0
    return first, last


def _try_step(
    robot: Robot,
    p_trial: NDArray[np.float64] | None,
    goal: ToolPose | None,
    collisions: CollisionModel | None,
    path_of: Callable[[NDArray[np.float64]], BSplinePath],
    time_it: Callable[[NDArray[np.float64]], TimingResult],
    ends: MovingEnds,
) -> tuple[NDArray[np.float64] | None, TimingResult | None, int, CollisionSamples | None]:
    """The step's iterate (θe back onto the pose, the ends' control points back onto their
    rays; None: a via-point's pose was not found again), its timing if it is certified clear
    and stage 1 times it (None otherwise), the stage-1 solves spent (0 or 1) and its path's
    clearances (:class:`CollisionSamples`, on which the certificate starts; None without
    obstacles)."""
    n = robot.n
    if p_trial is not None and goal is not None:  # back onto the pose (to first order the
        end = _onto(robot, goal, p_trial[-n:])  # step never left it)
        p_trial = None if end is None else np.concatenate([p_trial[:-n], end])
    if p_trial is not None and ends.moving:  # (to first order the step kept them there)
        p_trial = ends.onto_rays(p_trial)
    if p_trial is None:
        return p_trial, None, 0, None
    samples = None
    if collisions is not None:
        samples = CollisionSamples(collisions, path_of(p_trial), end=goal is not None)
        if not samples.certified():
            return p_trial, None, 0, samples
    try:
        return p_trial, time_it(p_trial), 1, samples
    except (InfeasiblePathError, SolverError):
        return p_trial, None, 0, samples
    except ConfigurationError:
        if not ends.moving:
            raise
        # a moving end's direction lost to rounding (the end's control point within ~1e-8 of
        # θ0 or θe): a step to reject like any other
        return p_trial, None, 0, samples


MODEL_TOLERANCE = 1e-7
"""Relative accuracy to which the convex model is solved (its duality gap and residuals, F
scaled to 1): three orders below the stopping test's default (``SCPOptions.tolerance``, 1e-4), so
that the predicted decrease the test and the trust region compare is exact enough. 1e-9 took
~25 % more Newton iterations for J within 3.5e-4 (17 reference plans; 1e-6 moved J by ±4e-4)."""

ACTIVATION = 0.05
"""Pairs farther than the margin plus this from each other get no row in the model [m]
(TrajOpt's distance-check threshold)."""


def iterate_grid(grid: int, options: SCPOptions, count: int) -> int:
    """The grid stage 2 times its iterates on: ``options.grid``, at least 4 segments per
    control point (``count`` interior ones: with fewer, the grid cannot see what one control
    point changes), at most the plan's ``grid``."""
    return min(grid, max(options.grid, 4 * count))


def knot_breaks(
    options: SCPOptions, count: int, moving: tuple[bool, bool] = (False, False)
) -> NDArray[np.float64] | None:
    """The interior knots of a B-spline path with ``count`` interior control points: clustered
    at the rest ends, where stage 1's grid is dense too (σ = ½(1 − cos πx)), or None (uniform).

    ``moving`` (start, end): whether the motion starts (ends) moving. A moving end is not
    clustered: knots close together there make θ' large and b = |θ̇|²/|θ'|² small at that end,
    and b then grows tenfold within a few segments of stage 1's coarse iterate grid, whose
    quadrature misjudged J by up to 15 % (ur5 re-planned from a moving state: the iterates'
    J 3.07, the same timings' J 3.59). With one rest end, σ = 1 − cos(πx/2) (or sin(πx/2))
    clusters at that end alone; with two moving ends the knots are uniform."""
    if options.knots != "clustered" or all(moving):
        return None
    x = np.linspace(0.0, 1.0, count)[1:-1]
    if moving[0]:
        return np.sin(0.5 * np.pi * x)
    if moving[1]:
        return 1.0 - np.cos(0.5 * np.pi * x)
    return 0.5 * (1.0 - np.cos(np.pi * x))


class CollisionSamples:
    """The clearances along one path at ``checks`` uniform σ, and their gradients where
    :func:`collision_rows` asks for them, computed once: a rejected step's smaller model takes
    them again (its path is the same). Exact up to m⁺ + :data:`ACTIVATION`, lower bounds beyond
    (no row is kept there)."""

    def __init__(
        self, collisions: CollisionModel, path: BSplinePath, checks: int = 129, end: bool = False
    ) -> None:
        self.collisions, self.path = collisions, path
        sigma = np.linspace(0.0, 1.0, checks)
        self.q = path(sigma)
        self.basis = path.basis(sigma)[:, 1 : None if end else -1]  # (S, K), or K + 1
        self.below = _inner(collisions.margin) + ACTIVATION  # exact up to this [m]
        self.dist = collisions.distances_along(self.q, self.below)
        self._gradients: dict[int, tuple[NDArray[np.int64], NDArray, NDArray]] = {}

    def certified(self) -> bool:
        """Whether the path keeps the margin at every σ (the certificate of
        :meth:`~nearopt.collision.CollisionModel.path_clearance`, its first pass on these
        checks' distances)."""
        return self.collisions.path_is_clear(
            self.path, samples=len(self.q) - 1, distances=self.dist, exact_below=self.below
        )

    def gradients(
        self, m: int, pairs: NDArray[np.int64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """d and ∂d/∂θ of ``pairs`` at the m-th check (from the last call there when it asked
        for these pairs or more)."""
        known = self._gradients.get(m)
        if known is None or not np.all(np.isin(pairs, known[0])):
            order = np.unique(pairs)  # kept sorted, to be looked up
            d, grad = self.collisions.distance_gradients(self.q[m], order)
            known = self._gradients[m] = (order, d, grad)
        where = np.searchsorted(known[0], pairs)
        return known[1][where], known[2][where]


def collision_rows(
    collisions: CollisionModel,
    path: BSplinePath,
    reach: NDArray[np.float64],
    checks: int = 129,
    end: bool = False,
    samples: CollisionSamples | None = None,
) -> tuple[sp.csr_matrix, NDArray[np.float64]]:
    """The clearances at ``checks`` uniform σ, linearised in the interior control points:

        d_k(σ_m) + ∇d_k(θ(σ_m))ᵀ Σ_j B_j(σ_m) Δc_j ≥ min(m⁺, d_k(σ_m)),

    m⁺ = margin + max(¼ margin, 1 mm) at the checked points, so that the certified check between
    them (at the margin itself) has room; the current path (Δc = 0) always satisfies them. Only
    pairs within :data:`ACTIVATION` of m⁺ whose distance the step (|Δθ_i| ≤ ``reach_i``) could
    bring to m⁺ are kept, at their local minima along σ and the checks beside them.
    ``samples``: the path's clearances computed before (:class:`CollisionSamples`; at their
    checks and with their end point, not ``checks`` and ``end``).

    Returns
    -------
    G, lower
        ``G Δp ≥ lower``, G of shape (rows, K·n) over the interior control points (point-major),
        (rows, (K + 1)·n) with the end point when ``end``.
    """
    inner = _inner(collisions.margin)
    if samples is None:
        samples = CollisionSamples(collisions, path, checks, end)
    q, basis, dist = samples.q, samples.basis, samples.dist
    # how far the step can move each pair, at most ACTIVATION: farther pairs wait for the next
    # iterate (a step that brings one into contact fails the certificate and is rejected)
    moved = np.minimum(collisions.motion_rates @ reach, ACTIVATION)
    # rows where a pair could reach m⁺: at its local minima along σ and their neighbours (the
    # minimum moves with the path), and wherever it is already within m⁺ + 5 mm
    low = np.zeros(dist.shape, dtype=bool)
    low[1:-1] = (dist[1:-1] <= dist[:-2]) & (dist[1:-1] <= dist[2:])
    low[[0, -1]] = True
    low[1:] |= low[:-1].copy()
    low[:-1] |= low[1:].copy()
    keep = (dist - inner <= moved) & (low | (dist < inner + 0.005))
    keep[:, :] &= np.any(basis != 0.0, axis=1)[:, None]
    blocks, lower = [], []
    for m in np.flatnonzero(keep.any(axis=1)):
        d, grad = samples.gradients(int(m), np.flatnonzero(keep[m]))
        # row: Σ_j B_j(σ) ∇dᵀ Δc_j (np.kron(basis[m], grad), without its overhead)
        blocks.append((basis[m][None, :, None] * grad[:, None, :]).reshape(grad.shape[0], -1))
        lower.append(np.minimum(inner - d, 0.0))
    if not blocks:
        return sp.csr_matrix((0, basis.shape[1] * q.shape[1])), np.zeros(0)
    return sp.csr_matrix(np.vstack(blocks)), np.concatenate(lower)


def _inner(margin: float) -> float:
    """m⁺ of :func:`collision_rows`: the clearance held at the checked points [m]."""
    return margin + max(0.25 * margin, 1e-3)


def _with_rows(
    model: _Model,
    path_rows: sp.csr_matrix,
    lower: NDArray[np.float64],
    upper: NDArray[np.float64] | None = None,
) -> _Model:
    """The model with rows ``lower ≤ path_rows Δp ≤ upper`` (default no upper bound) that do
    not involve the timing."""
    if lower.size == 0:
        return model
    upper = np.full(lower.size, np.inf) if upper is None else upper
    z_cols = model.matrix.shape[1] - path_rows.shape[1]
    rows = sp.hstack([sp.csr_matrix((lower.size, z_cols)), path_rows]).tocsr()
    return replace(
        model,
        matrix=sp.vstack([model.matrix, rows]).tocsr(),
        lower=np.concatenate([model.lower, lower]),
        upper=np.concatenate([model.upper, upper]),
    )


def _onto(robot: Robot, goal: ToolPose, q: NDArray[np.float64]) -> NDArray[np.float64] | None:
    """θ near q that meets the goal pose to 1e-10 (None if inverse kinematics from q fails)."""
    try:
        return inverse_kinematics(robot, goal, seed=q, attempts=1, iterations=50)
    except UnreachablePoseError:
        return None


def path_through(
    points: NDArray[np.float64],
    interior: int,
    breaks: NDArray[np.float64] | None = None,
    exact: Sequence[int] | None = None,
    lower: NDArray[np.float64] | None = None,
    upper: NDArray[np.float64] | None = None,
) -> tuple[BSplinePath, NDArray[np.float64]]:
    """A B-spline from ``points[0]`` to ``points[-1]`` along the polyline through ``points``,
    through the points ``exact`` exactly, and the σ where it passes them (by joint-space arc
    length along the polyline).

    The control points lie on the polyline at their Greville abscissae, then move by the least
    change that puts θ(σ_v) on each exact point; with position limits, the least change that also
    keeps every control point within them (a small QP per joint, Clarabel), so the whole curve
    stays within them (a B-spline lies in the convex hull of its control points).

    Parameters
    ----------
    points
        The polyline: start, …, goal [rad or m], shape (m + 2, n).
    interior
        Interior control points K (≥ the exact points).
    breaks
        Interior knots (default uniform).
    exact
        Indices of the points the path passes exactly (default: every point between the ends).
    lower, upper
        Position limits [rad or m], shape (n,), that every point lies within (default: none).
    """
    from ..collision.sampling import fit_polyline

    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    index = np.arange(1, len(points) - 1) if exact is None else np.asarray(exact, dtype=int)
    sigma = arc[index] / arc[-1]
    spline = fit_polyline(points, interior, breaks)
    control = spline.control_points.copy()
    if index.size:
        basis = spline.basis(sigma)
        inner = basis[:, 1:-1]
        miss = points[index] - basis @ control  # (m, n)
        step = inner.T @ np.linalg.solve(inner @ inner.T, miss)
        if lower is not None and upper is not None:
            inside = control[1:-1] + step
            for j in np.flatnonzero(
                np.any(inside < lower - 1e-12, axis=0) | np.any(inside > upper + 1e-12, axis=0)
            ):
                step[:, j] = _bounded_step(
                    inner, miss[:, j], control[1:-1, j], lower[j], upper[j], step[:, j]
                )
        control[1:-1] += step
    return BSplinePath(control, breaks), sigma


def _bounded_step(
    inner: NDArray[np.float64],
    miss: NDArray[np.float64],
    control: NDArray[np.float64],
    lower: float,
    upper: float,
    fallback: NDArray[np.float64],
) -> NDArray[np.float64]:
    """min ½|x|² s.t. inner x = miss, lower ≤ control + x ≤ upper (one joint), by Clarabel;
    ``fallback`` if it has no solution."""
    import clarabel

    k = control.size
    rows = [sp.csr_matrix(inner)]
    rhs = [miss]
    cones: list[object] = [clarabel.ZeroConeT(miss.size)]
    bounds = []
    if np.isfinite(upper):
        rows.append(sp.identity(k, format="csr"))
        rhs.append(upper - control)
        bounds.append(k)
    if np.isfinite(lower):
        rows.append(-sp.identity(k, format="csr"))
        rhs.append(control - lower)
        bounds.append(k)
    if bounds:
        cones.append(clarabel.NonnegativeConeT(sum(bounds)))
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    solver = clarabel.DefaultSolver(
        sp.identity(k, format="csc"),
        np.zeros(k),
        sp.vstack(rows, format="csc"),
        np.concatenate(rhs),
        cones,
        settings,
    )
    solution = solver.solve()
    if solution.status != clarabel.SolverStatus.Solved:
        return fallback
    x = np.asarray(solution.x)
    # the bounds to rounding, then the exact points again (the residual is rounding only) by
    # the control points off the bounds
    x = np.clip(control + x, lower, upper) - control
    at = (control + x)[:, None]
    lo, hi = np.full_like(at, lower), np.full_like(at, upper)
    return x + onto_points(inner, (miss - inner @ x)[:, None], at, lo, hi)[:, 0]


def onto_points(
    inner: NDArray[np.float64],
    miss: NDArray[np.float64],
    control: NDArray[np.float64],
    lower: NDArray[np.float64],
    upper: NDArray[np.float64],
) -> NDArray[np.float64]:
    """The least change x of the control points ``control`` (K, n) with ``inner`` x = ``miss``
    (inner: the basis at the points to pass, (m, K); miss (m, n)) that keeps them within their
    bounds ``lower``, ``upper`` (K, n), for a change about a rounding error: per joint by the
    control points inside their bounds, those the change would take beyond them left where they
    are (and the change taken again by the others); none where no such change is found."""
    x = np.zeros_like(control)
    for j in range(control.shape[1]):
        c, lo, hi = control[:, j], lower[:, j], upper[:, j]
        free = (c > lo) & (c < hi)
        while free.any():
            y = np.linalg.lstsq(inner[:, free], miss[:, j], rcond=None)[0]
            beyond = (c[free] + y < lo[free]) | (c[free] + y > hi[free])
            if not beyond.any():
                x[free, j] = y
                break
            free[np.flatnonzero(free)[beyond]] = False
    return x


def _range(lim: object) -> NDArray[np.float64]:
    """Each joint's position range, with 2π for joints without limits [rad]."""
    span = lim.position_upper - lim.position_lower
    return np.where(np.isfinite(span), span, 2.0 * np.pi)


@dataclass(frozen=True)
class _Model:
    """The convex model: the torques [A_z, G] (z, Δp) + const at every sample, within
    ``torque_limits`` where they may bind, and lower ≤ [A_z, G] (z, Δp) ≤ upper for the other
    rows that may bind (``rows``: indices into the discretisation's)."""

    rows: NDArray[np.int64]
    matrix: sp.csr_matrix
    lower: NDArray[np.float64]
    upper: NDArray[np.float64]
    torque: sp.csr_matrix
    torque_const: NDArray[np.float64]
    torque_limits: tuple[NDArray[np.float64], NDArray[np.float64]]
    price: NDArray[np.float64] | None = None  # a linear term c·Δp of the model's J


def _model(
    disc: Discretisation, z: NDArray[np.float64], jac: sp.csr_matrix, reach: NDArray[np.float64]
) -> _Model:
    """The convex model at the timing z, with the rows that can bind: those within half their
    range (torques, accelerations) or above a quarter of their bound (speeds², i.e. half the
    speed limit) of a limit, and those the path step alone (|Δp| ≤ ``reach``) could move by
    half their slack."""
    rows = disc.linear_rows(z)  # the damping's tangent at z
    value = disc.values(z)
    span = np.where(np.isfinite(disc.lower), 0.5 * (disc.upper - disc.lower), np.abs(disc.upper))
    slack = np.minimum(disc.upper - value, value - disc.lower)
    moved = abs(jac) @ reach
    keep = (slack <= np.where(np.isfinite(disc.lower), 0.5, 0.75) * span) | (slack <= 2.0 * moved)
    for block in (
        disc.blocks.torque_between,
        disc.blocks.acceleration_between,
        disc.blocks.speed_between,
    ):
        keep[block] = False
    # a speed row b θ'_i² ≤ v_i² is taken in its bound form b ≤ v_i²/θ'_i², whose tangent in θ'
    # lies below the convex bound: what the model allows, the exact row allows too
    lower, upper = rows.lower.copy(), rows.upper.copy()
    factor = np.ones(value.size)
    path_factor = np.ones(value.size)
    for block in (disc.blocks.speed, disc.blocks.interior_speed):
        index = np.arange(block.start, block.stop)
        slope2 = disc.coef_left[index] + disc.coef_right[index]  # θ'_i² (weights sum to 1)
        moving = (slope2 > 0.0) & (value[index] > 0.0)
        keep[index[~moving]] = False
        factor[index[moving]] = 1.0 / slope2[moving]
        path_factor[index[moving]] = disc.upper[index[moving]] / value[index[moving]]
    torque = disc.blocks.torque
    scaled = sp.diags(factor)
    matrix = sp.hstack([scaled @ rows.matrix, scaled @ sp.diags(path_factor) @ jac]).tocsr()
    lower, upper = factor * lower, factor * upper
    const = disc.upper[torque] - rows.upper[torque]
    # the torque rows' limits become bounds of the torque variables (±inf where not kept)
    held = keep[torque]
    limits = (
        np.where(held, disc.lower[torque], -np.inf),
        np.where(held, disc.upper[torque], np.inf),
    )
    keep[torque] = False
    keep = np.flatnonzero(keep)
    return _Model(keep, matrix[keep], lower[keep], upper[keep], matrix[torque], const, limits)


def solve_model(
    disc: Discretisation,
    weights: NDArray[np.float64],
    model: _Model,
    z: NDArray[np.float64],
    p: NDArray[np.float64],
    radius: NDArray[np.float64],
    lower: NDArray[np.float64],
    upper: NDArray[np.float64],
) -> tuple[NDArray[np.float64], float, NDArray[np.float64]] | None:
    """The convex model's best step Δp within the trust region, its predicted J and timing:
    by nearopt's joint interior-point method (:func:`~nearopt.timing.solve_joint`) from the
    model's own timing z, by Clarabel where that does not converge."""
    bounds = (np.maximum(-radius, lower - p), np.minimum(radius, upper - p))
    rows = LinearRows(model.matrix, model.lower, model.upper)
    problem = (disc.ds, weights, rows, (model.torque, model.torque_const), disc.z_upper)
    limits = {"p_bounds": bounds, "torque_limits": model.torque_limits}
    b_ends = disc.problem.b_ends
    joint = solve_joint(
        *problem, **limits, start=z, tolerance=MODEL_TOLERANCE, b_ends=b_ends, p_price=model.price
    )
    if joint.converged:
        return np.clip(joint.p, *bounds), joint.objective, joint.z
    for tolerance in (1e-8, 1e-7, 1e-6):  # (without the price on the ends' λ: a fallback)
        sol = solve_conic(*problem, **limits, tolerance=tolerance, b_ends=b_ends)
        if is_solved(sol.status):
            return np.clip(sol.p, *bounds), sol.objective, sol.z
    return None
