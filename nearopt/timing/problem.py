"""Stage 1's problem on a grid: the sampled path, its coefficients of eq. (10) and the limits.

:func:`build_timing_problem` samples a path θ(σ) on knots clustered at the rest ends and collects,
as plain arrays, everything the timing kernel needs (no robot model beyond this point).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from ..errors import ConfigurationError, InfeasiblePathError
from ..robot import PathCoefficients

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from ..path import Path
    from ..robot import Robot

__all__ = [
    "MAX_GRID",
    "InteriorSpeed",
    "TimingProblem",
    "build_timing_problem",
    "speed_bound",
    "check_gravity",
    "grid_knots",
]

MAX_GRID = 100_000  # segments; stage 1's memory grows linearly beyond any use


class InteriorSpeed(NamedTuple):
    """Joint speed limits at points inside the segments: b(σ_p) ≤ bound_p.

    b is linear on a segment, so at σ_p = σ_k + w_p Δσ_k this reads
    (1 − w_p) b_k + w_p b_{k+1} ≤ bound_p = min_i v_i² / θ'_i(σ_p)².
    """

    segment: NDArray[np.int64]
    weight: NDArray[np.float64]
    sigma: NDArray[np.float64]
    dtheta: NDArray[np.float64]
    bound: NDArray[np.float64]


@dataclass(frozen=True)
class TimingProblem:
    """Stage 1 on a grid, as arrays (no robot model needed: the kernel's input).

    Attributes
    ----------
    s
        Knots of the normalised path parameter σ = s / s_e, 0 = σ_0 < … < σ_N = 1, shape (N+1,).
        The kernel works in σ so that b = (dσ/dt)² is of the order of 1/t_e² whatever the unit
        of s; J does not depend on that choice.
    theta, dtheta, ddtheta
        θ(σ_k) [rad], dθ/dσ and d²θ/dσ² [rad] at the knots, shape (N+1, n).
    coef
        m, c, d, g of eq. (10) with respect to σ at the knots, each (N+1, n).
    u_lower, u_upper
        Actuator limits of eq. (2) [N·m], shape (n,).
    b_upper
        Upper bound on b = (dσ/dt)² at each knot from the joint speed limits (inf if none), (N+1,).
    joint_names
        Names of the n joints, for messages.
    margin
        Optional torque margins [N·m] at the samples, shape (2N, n): rows 0 … N−1 at the start of
        segments 0 … N−1, rows N … 2N−1 at their ends. Stage 1 keeps each sample this far inside
        both limits; :func:`optimal_timing` sets them where the torque bulges out between samples.
    interior_speed
        Joint speed limits at points inside the segments (on a curved path |θ'| peaks between
        knots); None without speed limits.
    """

    s: NDArray[np.float64]
    theta: NDArray[np.float64]
    dtheta: NDArray[np.float64]
    ddtheta: NDArray[np.float64]
    coef: PathCoefficients
    u_lower: NDArray[np.float64]
    u_upper: NDArray[np.float64]
    b_upper: NDArray[np.float64]
    joint_names: tuple[str, ...]
    margin: NDArray[np.float64] | None = None
    interior_speed: InteriorSpeed | None = None

    @property
    def segments(self) -> int:
        """N, the number of grid segments."""
        return self.s.size - 1

    @property
    def dof(self) -> int:
        """n, the number of joints."""
        return self.theta.shape[1]


def build_timing_problem(
    robot: Robot,
    path: Path,
    *,
    grid: int = 200,
    velocity_limits: bool = True,
) -> TimingProblem:
    """Sample a path on a grid clustered at the rest ends and collect what stage 1 needs.

    Parameters
    ----------
    robot
        The arm (its limits are the ones enforced).
    path
        θ(s), s ∈ [0, s_e], with ``path.dof == robot.n``.
    grid
        N, the number of segments (≥ 2).
    velocity_limits
        Enforce the robot's joint speed limits |θ̇_i| ≤ v_i.
    """
    if not isinstance(grid, int | np.integer) or not 2 <= grid <= MAX_GRID:
        raise ConfigurationError(f"grid must be an integer ≥ 2 and ≤ {MAX_GRID}, got {grid!r}")
    if path.dof != robot.n:
        raise ConfigurationError(f"the path has {path.dof} joints, {robot.name} has {robot.n}")
    sigma = grid_knots(grid)
    s = sigma * path.s_end
    theta = path(s, 0)
    dtheta = path(s, 1) * path.s_end  # d/dσ = s_e d/ds
    ddtheta = path(s, 2) * path.s_end**2
    coef = robot.path_coefficients(theta, dtheta, ddtheta)
    b_upper = np.full(s.size, np.inf)
    interior = None
    v = robot.limits.velocity
    if velocity_limits and np.any(np.isfinite(v)):
        b_upper = speed_bound(dtheta, v)
        # three points inside every segment, where |θ'| of a curved path may peak
        segment = np.repeat(np.arange(grid), 3)
        weight = np.tile([0.25, 0.5, 0.75], grid)
        at = sigma[segment] + weight * np.diff(sigma)[segment]
        d_at = path(at * path.s_end, 1) * path.s_end
        bound = speed_bound(d_at, v)
        # b(σ_p) is a convex combination of b_k and b_{k+1}: a row is redundant where the knots'
        # own bounds already imply it (always, on a straight line)
        keep = bound < np.maximum(b_upper[segment], b_upper[segment + 1])
        interior = InteriorSpeed(segment[keep], weight[keep], at[keep], d_at[keep], bound[keep])
    return TimingProblem(
        s=sigma,
        theta=theta,
        dtheta=dtheta,
        ddtheta=ddtheta,
        coef=coef,
        u_lower=np.array(robot.limits.effort_lower),
        u_upper=np.array(robot.limits.effort_upper),
        b_upper=b_upper,
        joint_names=tuple(robot.joint_names),
        interior_speed=interior,
    )


def speed_bound(dtheta: NDArray[np.float64], velocity: NDArray[np.float64]) -> NDArray[np.float64]:
    """min_i v_i² / θ'_i² per row (inf where no joint moves or no limit is finite)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(dtheta != 0, velocity**2 / dtheta**2, np.inf)
    return np.min(np.where(np.isnan(ratio), np.inf, ratio), axis=1)


def check_gravity(
    problem: TimingProblem,
    g: NDArray[np.float64] | None = None,
    sigma: NDArray[np.float64] | None = None,
    theta: NDArray[np.float64] | None = None,
) -> None:
    """Raise InfeasiblePathError where gravity alone leaves the torque limits (b → 0 ⇒ u → g).

    By default at the problem's knots; ``g``, ``sigma``, ``theta`` give other points of the path
    (sorted by σ), e.g. those between the knots.
    """
    if g is None:
        g, sigma, theta = problem.coef.g, problem.s, problem.theta
    margin = 1e-9 * (problem.u_upper - problem.u_lower)
    over = g - (problem.u_upper - margin)
    under = (problem.u_lower + margin) - g
    excess = np.maximum(over, under)
    if np.any(excess > 0):
        k, i = np.unravel_index(np.argmax(excess), excess.shape)
        side = "upper" if over[k, i] >= under[k, i] else "lower"
        limit = problem.u_upper[i] if side == "upper" else problem.u_lower[i]
        bad = sigma[np.any(excess > 0, axis=1)]
        raise InfeasiblePathError(
            f"no timing of this path respects the torque limits: gravity alone needs "
            f"u = {g[k, i]:.6g} at joint {problem.joint_names[i]!r}, beyond its {side} limit "
            f"{limit:.6g} by {excess[k, i]:.6g}, at s/s_e = {sigma[k]:.6g} "
            f"(θ = {np.round(theta[k], 6).tolist()}); the path is infeasible for "
            f"s/s_e ∈ [{bad.min():.6g}, {bad.max():.6g}]",
            joint=problem.joint_names[i],
            s=float(sigma[k]),
            excess=float(excess[k, i]),
        )


def grid_knots(segments: int) -> NDArray[np.float64]:
    """Knots σ_k = ½(1 − cos(πk/N)) (Chebyshev-Lobatto), O(1/N²) apart at the rest ends.

    At rest b ∝ σ, so λ = √b varies fastest next to σ = 0 and 1: there the trapezoidal weights of
    a segment's two torque samples are least accurate (the time spent in the first segment lies
    mostly near its start). Clustering the knots there makes the discretised J converge much
    faster than on a uniform grid (measured on the paper's example: 0.02 % instead of 0.3 % at
    N = 200 on a curved path).
    """
    return 0.5 * (1.0 - np.cos(np.pi * np.arange(segments + 1) / segments))
