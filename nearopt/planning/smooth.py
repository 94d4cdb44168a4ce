"""Stage 2 under jerk (and torque-rate) limits: the path improved for its J under them.

Stage 2's convex model (:mod:`nearopt.planning.scp`) knows stage 1's rows, not the jerk: its
timing is piecewise linear in b, so θ̈ jumps and θ⃛ is not defined. Under jerk limits the path
it finds is often worse than the straight line (θ‴ = 0 only on a line; a bent path adds θ‴b^{3/2}
to the jerk). :func:`smooth_iterations` continues from a path (the better of the path found and
the first path, timed under the limits) with the same model and, per knot k of the iterate grid
and joint i, the jerk θ⃛_i = √b L_i, L_i = θ‴_i b + 3θ″_i a + θ′_i a′, with a = b′/2 and
a′ = b″/2 by three-point differences of the knots' b (:func:`jerk_rows`). |√b L| ≤ j is held
as ±L ≤ j/√b, whose right-hand side is convex in b, by its tangent at the iterate's b̄ (its
jerk-limited timing at the knots) — a restriction, as in stage 1's jerk-limited timing:

    ±(L_i(b) + Σ_j ∂L_i/∂c_j Δc_j) + ½ j_i b̄^{−3/2} b_k ≤ (3/2) j_i / √b̄,

L exact in b (linear in it for a fixed path) and linearised in the control points at b̄
(∂L/∂c_j = a′B′_j + 3a B″_j + b B‴_j, B_j the B-spline's basis). The model's optimum is a
direction, not a timing: every trial path is timed exactly under every limit
(:func:`~nearopt.timing.time_with_jerk_limits`, on the iterate grid) and accepted where its J is
lower; the trust region follows the ratio of that gain to the model's own (its optimum against
its value with the path held). Every accepted iterate is therefore a path timed under the
limits, its J below the one before. Torque-rate limits have no rows here: their trials are
timed under them.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from ..cost import TorqueCost
from ..errors import ConfigurationError, InfeasiblePathError, SolverError
from ..path import BSplinePath
from ..timing import Discretisation, optimal_timing, time_with_jerk_limits
from .linearisation import path_basis
from .records import Iteration, StopReason
from .scp import (
    IterateParts,
    after_failure,
    iterate_model,
    new_radius,
    solve_model,
    trust_scale,
)

if TYPE_CHECKING:
    from collections.abc import Callable

    from numpy.typing import NDArray

    from ..collision import CollisionModel
    from ..cost import Cost
    from ..robot import Robot
    from ..timing import JerkTimingResult
    from .records import Run, SCPOptions

__all__ = ["SmoothOutcome", "jerk_rows", "smooth_iterations"]

HELD = 1e-9
"""The trust radius (of each joint's scale) of the model solved with the path held: its value
there, against which its optimum's gain is measured."""


@dataclass(frozen=True)
class SmoothOutcome:
    """Where :func:`smooth_iterations` stopped: the best path, its jerk-limited timing on the
    iterate grid, the accepted iterates, and why it stopped."""

    path: BSplinePath
    judged: JerkTimingResult
    iterations: int
    message: str
    reason: StopReason = StopReason.CONVERGED


def jerk_rows(
    disc: Discretisation,
    path: BSplinePath,
    b: NDArray[np.float64],
    jerk: NDArray[np.float64],
) -> tuple[sp.csr_matrix, NDArray[np.float64], NDArray[np.float64]]:
    """The jerk at the inner knots of ``disc``'s grid as rows of stage 2's model, at the path
    and at b (its values at all N + 1 knots, b_0 and b_N fixed): over (z, Δp) — z = b_1 …
    b_{N−1} and the interior control points' change, point-major — with lower and upper
    bounds (each row divided by its right-hand side). Joints without a limit and knots where
    b is 0 get none.

    |√b L| ≤ j with L = θ‴b + 3θ″a + θ′a′ is held as ±L ≤ j/√b, whose right-hand side is convex
    in b: by its tangent at b̄ = b, ±L + ½ j b̄^{−3/2} b ≤ (3/2) j/√b̄ (a restriction, as in the
    jerk-limited timing), L exact in b (a, a′ by three-point differences) and linearised in the
    path at b̄ (∂L/∂c_j = a′B′_j + 3a B″_j + b B‴_j)."""
    sigma = disc.problem.sigma
    big_n = sigma.size - 1
    columns = big_n - 1 + (path.control_points.shape[0] - 2) * path.dof
    k = np.arange(1, big_n)
    k = k[b[k] > 1e-12 * max(float(np.max(b)), 1e-300)]
    limited = np.flatnonzero(np.isfinite(jerk))
    if not k.size or not limited.size:
        return sp.csr_matrix((0, columns)), np.zeros(0), np.zeros(0)
    lo, hi = sigma[k] - sigma[k - 1], sigma[k + 1] - sigma[k]
    both = lo + hi
    alpha = 0.5 * np.stack([-hi / (lo * both), (hi - lo) / (lo * hi), lo / (hi * both)], axis=1)
    beta = np.stack([1.0 / (lo * both), -1.0 / (lo * hi), 1.0 / (hi * both)], axis=1)
    near = np.stack([b[k - 1], b[k], b[k + 1]], axis=1)
    a, da, bk = np.sum(alpha * near, axis=1), np.sum(beta * near, axis=1), b[k]
    d1, d2, d3 = (path(sigma[k], order)[:, limited] for order in (1, 2, 3))
    # ∂L/∂b_m, m = k − 1, k, k + 1: (M, 3, J)
    dz = 3.0 * d2[:, None, :] * alpha[:, :, None] + d1[:, None, :] * beta[:, :, None]
    dz[:, 1, :] += d3
    # ∂L/∂c_j of the interior control points at b̄: (M, K)
    basis = [path.basis(sigma[k], order)[:, 1:-1] for order in (1, 2, 3)]
    dp = da[:, None] * basis[0] + 3.0 * a[:, None] * basis[1] + bk[:, None] * basis[2]
    n, count, nz = path.dof, basis[0].shape[1], big_n - 1
    rows_m, joints = k.size, limited.size
    rhs = 1.5 * jerk[limited][None, :] / np.sqrt(bk)[:, None]  # (M, J)
    tangent = 0.5 * jerk[limited][None, :] / (bk**1.5)[:, None]
    parts = []
    for sign in (1.0, -1.0):
        row = np.arange(rows_m * joints).reshape(rows_m, joints)
        entries_r, entries_c, entries_v = [], [], []
        fixed = np.zeros((rows_m, joints))  # L's terms in the fixed b_0, b_N
        for c in range(3):
            m = k - 1 + c
            coef = sign * dz[:, c, :] + (tangent if c == 1 else 0.0)
            take = (m >= 1) & (m <= nz)
            entries_r.append(row[take].ravel())
            entries_c.append(np.repeat(m[take] - 1, joints))
            entries_v.append((coef[take] / rhs[take]).ravel())
            fixed[~take] += coef[~take] * near[~take, c][:, None]
        for j in range(count):
            used = dp[:, j] != 0.0
            entries_r.append(row[used].ravel())
            entries_c.append(np.broadcast_to(nz + j * n + limited, row[used].shape).ravel())
            entries_v.append((sign * dp[used, j][:, None] / rhs[used]).ravel())
        matrix = sp.csr_matrix(
            (np.concatenate(entries_v), (np.concatenate(entries_r), np.concatenate(entries_c))),
            shape=(rows_m * joints, columns),
        )
        parts.append((matrix, (1.0 - fixed / rhs).ravel()))
    upper = np.concatenate([part[1] for part in parts])
    return sp.vstack([part[0] for part in parts]).tocsr(), np.full(upper.size, -np.inf), upper


def smooth_iterations(
    robot: Robot,
    cost: Cost,
    start: BSplinePath,
    *,
    grid: int,
    velocity_limits: bool,
    position_limits: bool,
    options: SCPOptions,
    run: Run,
    collisions: CollisionModel | None = None,
    via: tuple[float, ...] = (),
) -> SmoothOutcome:
    """Improve ``start`` (a B-spline from θ0 to θe at rest; its knots are every iterate's) for
    its J under the robot's jerk and torque-rate limits (and every other), by the model of the
    module docstring; the ends stay. ``grid``: the iterates' stage-1 grid. Every accepted
    iterate goes to ``run.accept`` (its J and t_e under the limits; iterate 0 is ``start``):
    at most ``run.max_iterations``, none started after ``run.deadline``. Raises
    InfeasiblePathError or SolverError where ``start`` itself cannot be timed."""
    weights = cost.torque_weights(robot.n) if isinstance(cost, TorqueCost) else None
    if weights is None:
        raise SolverError("stage 2 under jerk limits needs f0 = 1 + Σ w u² (a TorqueCost)")
    n, fixed, breaks = robot.n, start.control_points[[0, -1]], start.knots[4:-4]
    count = start.control_points.shape[0] - 2
    scale, lower, upper = trust_scale(robot, fixed[0], fixed[1], count, False, position_limits)

    def path_of(p: NDArray[np.float64]) -> BSplinePath:
        return BSplinePath(np.vstack([fixed[:1], p.reshape(count, n), fixed[1:]]), breaks)

    def timed(p: NDArray[np.float64]) -> JerkTimingResult:
        """The path's timing under every limit (its J)."""
        left = max(run.deadline - time.perf_counter(), 0.0)
        return time_with_jerk_limits(
            robot, path_of(p), cost, grid=grid, velocity_limits=velocity_limits, time_limit=left
        )

    def judged(p: NDArray[np.float64], limited: JerkTimingResult) -> _Judged:
        """The iterate: with its stage-1 timing, the model's (only for an accepted one)."""
        path = path_of(p)
        plain = optimal_timing(robot, path, cost, grid=grid, velocity_limits=velocity_limits)
        return _Judged(p, IterateParts(plain, path), limited)

    def report(index: int, now: _Judged, step: float | None) -> None:
        entry = Iteration(
            index, now.limited.J, step, now.limited.duration,
            time.perf_counter() - run.t_start, now.parts.path,
        )  # fmt: skip
        run.accept(entry, now.parts.timing)

    p0 = start.control_points[1:-1].ravel()
    now = judged(p0, timed(p0))
    report(0, now, None)
    radius = np.full(count, options.trust_radius)
    index, small, failures, message = 0, 0, 0, f"the iteration limit ({run.max_iterations})"
    context = (robot, weights, scale, (lower, upper), collisions, start, via)
    reason = StopReason.ITERATION_LIMIT
    try:
        while index < run.max_iterations:
            if run.out_of_time():
                reason, message = StopReason.TIME_LIMIT, "the time limit was reached"
                break
            step = _model_step(now, radius, context)
            if step is None:  # numerical trouble: a smaller step is a better-conditioned model
                failures, radius, retry = after_failure(failures, radius, options)
                if retry:
                    continue
                reason, message = StopReason.SOLVER, "the convex model could not be solved"
                break
            failures, (dp, predicted, held) = 0, step
            j0, promised = now.limited.J, held - predicted
            if promised <= options.tolerance * abs(j0):
                reason, message = StopReason.CONVERGED, _GAINS_NOTHING.format(options.tolerance)
                break
            trial = _trial(timed, judged, path_of, now.p + dp, (j0, collisions))
            gain = -np.inf if trial is None else j0 - trial.limited.J
            reach = np.max((np.abs(dp) / scale).reshape(count, n), axis=1)
            radius = new_radius(radius, gain, gain / promised, reach)
            if gain > 0.0:
                now, index = trial, index + 1
                report(index, now, float(np.max(np.abs(dp))))
                small = small + 1 if gain < options.tolerance * abs(j0) else 0
                if small == 3:
                    reason, message = StopReason.CONVERGED, _J_STOPPED.format(options.tolerance)
                    break
            if radius.max() < options.min_trust_radius:
                reason, message = StopReason.CONVERGED, _NO_STEP.format(options.min_trust_radius)
                break
    except KeyboardInterrupt:  # (Ctrl-C: the best iterate so far)
        reason, message = StopReason.INTERRUPTED, f"interrupted after {index} iteration(s)"
    return SmoothOutcome(now.parts.path, now.limited, index, message, reason)


_GAINS_NOTHING = "converged: the model finds no path that lowers J by more than {:g} relative"
_J_STOPPED = "converged: J changed by less than {:g} relative in each of the last 3 iterations"
_NO_STEP = "converged: no step longer than {:g} of the joints' scale lowers J"


@dataclass(frozen=True)
class _Judged:
    """An iterate: its control points, its path with its stage-1 timing (the model's), and its
    timing under every limit (its J)."""

    p: NDArray[np.float64]
    parts: IterateParts
    limited: JerkTimingResult
    memo: dict = field(default_factory=dict, compare=False)  # what its models share


def _model_step(
    now: _Judged, radius: NDArray[np.float64], context: tuple
) -> tuple[NDArray[np.float64], float, float] | None:
    """The model's best step Δp within the trust radius, its J there and its J with the path
    held; None where the model cannot be solved. What depends on the iterate alone (its grid,
    basis, jerk rows and the model's J with the path held) is built once per iterate, in
    ``now.memo``: a rejected step's smaller model takes it again."""
    robot, weights, scale, bounds, collisions, start, via = context
    if "inputs" not in now.memo:
        timing, path = now.parts.timing, now.parts.path
        disc = Discretisation.of(timing.problem)
        b_lin = now.limited.timing.evaluate(disc.problem.sigma)[0]
        extra = jerk_rows(disc, path, b_lin, robot.limits.jerk)
        now.memo["inputs"] = (disc, timing.b[1:-1], path_basis(path, disc), extra)
    disc, z, basis, extra = now.memo["inputs"]

    def solved(r: NDArray[np.float64]) -> tuple | None:
        bound = np.repeat(r, robot.n) * scale
        model = iterate_model(
            robot, disc, z, basis, now.p, now.parts, bound, collisions, start, (via, ()), None
        )
        model = replace(
            model,
            matrix=sp.vstack([model.matrix, extra[0]]).tocsr(),
            lower=np.concatenate([model.lower, extra[1]]),
            upper=np.concatenate([model.upper, extra[2]]),
        )
        return solve_model(disc, weights, model, z, now.p, bound, *bounds)

    if "held" not in now.memo:
        still = solved(np.full(radius.size, HELD))
        if still is None:
            return None
        now.memo["held"] = still[1]
    moved = solved(radius)
    if moved is None:
        return None
    return moved[0], moved[1], now.memo["held"]


def _trial(
    timed: Callable[[NDArray[np.float64]], JerkTimingResult],
    judged: Callable[[NDArray[np.float64], JerkTimingResult], _Judged],
    path_of: Callable[[NDArray[np.float64]], BSplinePath],
    p: NDArray[np.float64],
    against: tuple[float, CollisionModel | None],
) -> _Judged | None:
    """The trial iterate where it is certified clear, timed under the limits and of J below
    ``against[0]`` (only then its stage-1 timing too); None otherwise."""
    j0, collisions = against
    if collisions is not None and not collisions.path_is_clear(path_of(p)):
        return None
    try:
        limited = timed(p)
        return judged(p, limited) if limited.J < j0 else None
    except (InfeasiblePathError, SolverError, ConfigurationError):
        return None
