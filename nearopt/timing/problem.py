"""Stage 1's problem on a grid: the sampled path, its coefficients of eq. (10) and the limits.

:func:`build_timing_problem` samples a path θ(σ) on knots clustered at the rest ends and collects,
as plain arrays, everything the timing kernel needs (no robot model beyond this point).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from ..errors import ConfigurationError, InfeasiblePathError
from ..robot import PathCoefficients
from ..validate import real_array

if TYPE_CHECKING:
    from numpy.typing import ArrayLike, NDArray

    from ..path import Path
    from ..robot import Robot

__all__ = [
    "MAX_GRID",
    "TORQUE_SAFETY",
    "SPEED_SAFETY",
    "PathQuantity",
    "InteriorSpeed",
    "InteriorSamples",
    "BETWEEN_POINTS",
    "interior_points",
    "TimingProblem",
    "acceleration_coefficients",
    "build_timing_problem",
    "safe_limits",
    "check_gravity",
    "grid_knots",
    "with_moving_ends",
]

MAX_GRID = 100_000  # segments; stage 1's memory grows linearly beyond any use


class PathQuantity(NamedTuple):
    """A per-joint quantity along the path that is affine in the timing, with its limits.

    q = m·a + c·b + d·λ + g with b = λ² = (dσ/dt)² and a = ½ db/dσ: the torque of eq. (10)
    (m = Hθ', c = Hθ'' + h(θ, θ'), d = Dθ', g = g(θ)) and the joint acceleration
    θ̈ = θ'·a + θ''·b (m = θ', c = θ'', d = g = 0) are of this form.

    Attributes
    ----------
    coef
        m, c, d, g at the knots, each of shape (N+1, n).
    lower, upper
        Its limits, shape (n,) (±inf where a joint has none).
    margin
        Optional margins at the samples, shape (2N, n): rows 0 … N−1 at the start of segments
        0 … N−1, rows N … 2N−1 at their ends. Stage 1 keeps each sample this far inside both
        limits; :func:`~nearopt.timing.optimal_timing` sets them where the quantity bulges out
        between samples.
    """

    coef: PathCoefficients
    lower: NDArray[np.float64]
    upper: NDArray[np.float64]
    margin: NDArray[np.float64] | None = None


class InteriorSpeed(NamedTuple):
    """Points inside the segments where the joint speed limits are imposed too.

    b is linear on a segment, so at σ_p = σ_k + w_p Δσ_k the limit of joint i reads
    ((1 − w_p) b_k + w_p b_{k+1}) θ'_i(σ_p)² ≤ v_i².
    """

    segment: NDArray[np.int64]
    weight: NDArray[np.float64]
    sigma: NDArray[np.float64]
    dtheta: NDArray[np.float64]


BETWEEN_POINTS = 4  # points inside every segment where the torques are held and checked


class InteriorSamples(NamedTuple):
    """Points inside the segments where the torques (and limited accelerations) are held too.

    ``points`` evenly spaced points inside every segment and 8 geometrically closer to each rest
    end (inside the first and the last segment, where a damping torque d√b rises like √σ): at
    σ_p = σ_k + w_p Δσ_k, b = (1 − w_p) b_k + w_p b_{k+1} and a = a_k, so each quantity there,
    m a + c b + d √b + g, is a row of the segment's two knots, like those at its samples. The
    same points are where :class:`~nearopt.timing.BetweenSamples` bounds the motion between them.

    Attributes
    ----------
    points
        Evenly spaced points per segment (the first ``points · N`` rows below, segment-major).
    segment, weight, sigma
        Segment k, weight w_p and σ_p of every point, shape (P,).
    theta, dtheta
        θ(σ_p) and dθ/dσ there, shape (P, n).
    torque
        The torque's coefficients m, c, d, g there, each (P, n).
    acceleration
        The joint acceleration's coefficients there (θ'(σ_p), θ''(σ_p)).
    """

    points: int
    segment: NDArray[np.int64]
    weight: NDArray[np.float64]
    sigma: NDArray[np.float64]
    theta: NDArray[np.float64]
    dtheta: NDArray[np.float64]
    torque: PathCoefficients
    acceleration: PathCoefficients


def interior_points(
    sigma: NDArray[np.float64], points: int = BETWEEN_POINTS
) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
    """Segment, weight and σ of the points of :class:`InteriorSamples` on knots ``sigma``."""
    big_n = sigma.size - 1
    frac = np.arange(1, points + 1) / (points + 1)
    near = np.geomspace(1e-6, 0.5 / (points + 1), 8)
    segment = np.concatenate(
        [np.repeat(np.arange(big_n), points), np.zeros(8, int), np.full(8, big_n - 1)]
    )
    weight = np.concatenate([np.tile(frac, big_n), near, 1.0 - near])
    return segment, weight, sigma[segment] + weight * np.diff(sigma)[segment]


@dataclass(frozen=True)
class TimingProblem:
    """Stage 1 on a grid, as arrays (no robot model needed: the kernel's input).

    Attributes
    ----------
    sigma
        Knots of the normalised path parameter σ = s / s_e, 0 = σ_0 < … < σ_N = 1, shape (N+1,).
        The kernel works in σ so that b = (dσ/dt)² is of the order of 1/t_e² whatever the unit
        of s; J does not depend on that choice.
    theta, dtheta, ddtheta
        θ(σ_k) [rad], dθ/dσ and d²θ/dσ² [rad] at the knots, shape (N+1, n).
    torque
        The actuator torques u of eq. (10) [N·m or N] with the limits of eq. (2).
    velocity
        Joint speed limits |θ̇_i| ≤ v_i [rad/s or m/s], shape (n,); inf where none is enforced.
        At every knot b_k θ'_i(σ_k)² ≤ v_i², one row per joint.
    joint_names
        Names of the n joints, for messages.
    acceleration
        Joint accelerations θ̈ [rad/s² or m/s²] with their limits, or None when no joint has one.
    interior_speed
        Points inside the segments where the speed limits are imposed too (on a curved path |θ'|
        peaks between knots); None without speed limits.
    b_upper
        Extra upper bounds on b at the knots, shape (N+1,) (inf where none), set where the speed
        bulges out between samples.
    interior
        Points inside the segments where the torque (and acceleration) rows are imposed too, so
        that one solve mostly holds the limits between the samples; None: at the samples only.
    b_ends
        b = (dσ/dt)² at σ = 0 and σ = 1 [1/s²], fixed: (0, 0) at rest (the paper's case), else
        the path speed of a motion that starts or ends moving (θ̇ = θ'·√b there).
    """

    sigma: NDArray[np.float64]
    theta: NDArray[np.float64]
    dtheta: NDArray[np.float64]
    ddtheta: NDArray[np.float64]
    torque: PathQuantity
    velocity: NDArray[np.float64]
    joint_names: tuple[str, ...]
    acceleration: PathQuantity | None = None
    interior_speed: InteriorSpeed | None = None
    b_upper: NDArray[np.float64] | None = None
    interior: InteriorSamples | None = None
    b_ends: tuple[float, float] = (0.0, 0.0)

    @property
    def segments(self) -> int:
        """N, the number of grid segments."""
        return self.sigma.size - 1

    @property
    def dof(self) -> int:
        """n, the number of joints."""
        return self.theta.shape[1]

    @property
    def at_rest(self) -> bool:
        """Whether the motion starts and ends at rest (b_0 = b_N = 0)."""
        return self.b_ends[0] == 0.0 and self.b_ends[1] == 0.0

    def with_ends(self, z: NDArray[np.float64]) -> NDArray[np.float64]:
        """b at every knot from the free knots' z = b_1 … b_{N−1}, shape (N+1,)."""
        return np.concatenate([[self.b_ends[0]], z, [self.b_ends[1]]])

    @property
    def quantities(self) -> tuple[PathQuantity, ...]:
        """The limited quantities affine in the timing: the torque first, then θ̈ if limited."""
        return (self.torque,) if self.acceleration is None else (self.torque, self.acceleration)


# the relative safety margins of the limits imposed at the samples: the motion between samples is
# bounded from samples (see between.py) and this small margin absorbs the error of that bound, so
# that what stage 1 returns passes verify() at its default tolerances (1e-6 relative for torques,
# 1e-9 for speeds) [fraction of the limit]
TORQUE_SAFETY = 1e-8
SPEED_SAFETY = 1e-11


def build_timing_problem(
    robot: Robot,
    path: Path,
    *,
    grid: int = 200,
    velocity_limits: bool = True,
) -> TimingProblem:
    """Sample a path on a grid and collect what stage 1 needs.

    The knots are clustered at the rest ends (:func:`grid_knots`) and include the path's own
    breakpoints (``path.breakpoints``: a spline's knots, where θ'' jumps), so that the path is
    smooth inside every segment.

    Parameters
    ----------
    robot
        The arm: its torque limits, its joint acceleration limits (if any) and, if
        ``velocity_limits``, its joint speed limits are enforced.
    path
        θ(s), s ∈ [0, s_e], with ``path.dof == robot.n``.
    grid
        N, the number of segments (≥ 2); one more per breakpoint that needs its own segment.
    velocity_limits
        Enforce the robot's joint speed limits |θ̇_i| ≤ v_i.
    """
    if not isinstance(grid, int | np.integer) or not 2 <= grid <= MAX_GRID:
        raise ConfigurationError(f"grid must be an integer ≥ 2 and ≤ {MAX_GRID}, got {grid!r}")
    if path.dof != robot.n:
        raise ConfigurationError(f"the path has {path.dof} joints, {robot.name} has {robot.n}")
    breaks = np.asarray(getattr(path, "breakpoints", ()), dtype=float) / path.s_end
    sigma = grid_knots(int(grid), breaks)
    # the path and its dynamics at the knots and at the interior points, in one batch
    segment, weight, at = interior_points(sigma)
    both = np.concatenate([sigma, at]) * path.s_end
    count = sigma.size
    theta_all = path(both, 0)
    dtheta_all = path(both, 1) * path.s_end  # d/dσ = s_e d/ds
    ddtheta_all = path(both, 2) * path.s_end**2
    coef_all = robot.path_coefficients(theta_all, dtheta_all, ddtheta_all)
    theta, dtheta, ddtheta = theta_all[:count], dtheta_all[:count], ddtheta_all[:count]
    lim = robot.limits
    torque = PathQuantity(
        PathCoefficients(*(x[:count] for x in coef_all)),
        np.array(lim.effort_lower),
        np.array(lim.effort_upper),
    )
    interior = InteriorSamples(
        BETWEEN_POINTS,
        segment,
        weight,
        at,
        theta_all[count:],
        dtheta_all[count:],
        PathCoefficients(*(x[count:] for x in coef_all)),
        acceleration_coefficients(dtheta_all[count:], ddtheta_all[count:]),
    )
    acceleration = None
    if np.any(np.isfinite(lim.acceleration)):
        acceleration = PathQuantity(
            acceleration_coefficients(dtheta, ddtheta),
            -np.array(lim.acceleration),
            np.array(lim.acceleration),
        )
    velocity = np.array(lim.velocity) if velocity_limits else np.full(robot.n, np.inf)
    interior_speed = None
    if np.any(np.isfinite(velocity)):
        # three points inside every segment, where |θ'| of a curved path may peak
        big_n = sigma.size - 1
        segment = np.repeat(np.arange(big_n), 3)
        weight = np.tile([0.25, 0.5, 0.75], big_n)
        at = sigma[segment] + weight * np.diff(sigma)[segment]
        interior_speed = InteriorSpeed(segment, weight, at, path(at * path.s_end, 1) * path.s_end)
    return TimingProblem(
        sigma=sigma,
        theta=theta,
        dtheta=dtheta,
        ddtheta=ddtheta,
        torque=torque,
        velocity=velocity,
        joint_names=tuple(robot.joint_names),
        acceleration=acceleration,
        interior_speed=interior_speed,
        interior=interior,
    )


def acceleration_coefficients(
    dtheta: NDArray[np.float64], ddtheta: NDArray[np.float64]
) -> PathCoefficients:
    """θ̈ = θ'·a + θ''·b as coefficients m = θ', c = θ'', d = g = 0, each of the shape of θ'."""
    zero = np.zeros_like(dtheta)
    return PathCoefficients(dtheta, ddtheta, zero, zero.copy())


def safe_limits(quantity: PathQuantity) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The limits of a quantity less the safety margin (what stage 1 holds its samples to)."""
    scale = np.maximum(np.abs(quantity.lower), np.abs(quantity.upper))
    margin = TORQUE_SAFETY * np.where(np.isfinite(scale), scale, 0.0)
    return quantity.lower + margin, quantity.upper - margin


def check_gravity(
    problem: TimingProblem,
    g: NDArray[np.float64] | None = None,
    sigma: NDArray[np.float64] | None = None,
    theta: NDArray[np.float64] | None = None,
) -> None:
    """Raise InfeasiblePathError where gravity alone leaves the torque limits (b → 0 ⇒ u → g),
    less the safety margin.

    By default at the problem's knots and its points inside the segments (``interior``);
    ``g``, ``sigma``, ``theta`` give other points of the path (sorted by σ).
    """
    if g is None:
        g, sigma, theta = problem.torque.coef.g, problem.sigma, problem.theta
        inside = problem.interior
        if inside is not None:  # and at the points inside the segments, in order of σ
            order = np.argsort(np.concatenate([sigma, inside.sigma]), kind="stable")
            g = np.concatenate([g, inside.torque.g])[order]
            sigma = np.concatenate([sigma, inside.sigma])[order]
            theta = np.concatenate([theta, inside.theta])[order]
    lower, upper = problem.torque.lower, problem.torque.upper
    safe_lower, safe_upper = safe_limits(problem.torque)
    over = g - safe_upper
    under = safe_lower - g
    excess = np.maximum(over, under)
    if np.any(excess > 0):
        k, i = np.unravel_index(np.argmax(excess), excess.shape)
        side = "upper" if over[k, i] >= under[k, i] else "lower"
        limit = upper[i] if side == "upper" else lower[i]
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


def grid_knots(segments: int, breakpoints: ArrayLike = ()) -> NDArray[np.float64]:
    """Knots clustered at the rest ends that include the given breakpoints.

    Without breakpoints σ_k = ½(1 − cos(πk/N)) (Chebyshev-Lobatto), O(1/N²) apart at the rest ends.
    At rest b ∝ σ, so λ = √b varies fastest next to σ = 0 and 1: there the trapezoidal weights of
    a segment's two torque samples are least accurate (the time spent in the first segment lies
    mostly near its start). Clustering the knots there makes the discretised J converge much
    faster than on a uniform grid (measured on the paper's example: 0.02 % instead of 0.3 % at
    N = 200 on a curved path).

    Breakpoints σ_b ∈ (0, 1) (where θ'' of the path jumps) split x = arccos(1 − 2σ)/π, in which
    the Chebyshev knots are uniform, into pieces; each piece gets a share of the N segments in
    proportion to its length (at least one), uniform in x, so every breakpoint is a knot and no
    segment straddles one. With B breakpoints in distinct places the grid has max(N, B + 1)
    segments.

    Parameters
    ----------
    segments
        N, the number of segments.
    breakpoints
        σ of the breakpoints (any order; those outside (0, 1) are ignored).
    """
    sigma_break = np.unique(np.asarray(breakpoints, dtype=float).ravel())
    sigma_break = sigma_break[(sigma_break > 0.0) & (sigma_break < 1.0)]
    ends = np.concatenate([[0.0], np.arccos(1.0 - 2.0 * sigma_break) / np.pi, [1.0]])
    width = np.diff(ends)
    share = np.maximum(1, np.floor(segments * width).astype(int))
    # hand out what is left by the largest remainders, so that Σ share = max(N, pieces)
    left = max(segments, width.size) - int(share.sum())
    if left > 0:
        remainder = segments * width - np.floor(segments * width)
        share[np.argsort(-remainder, kind="stable")[:left]] += 1
    x = np.concatenate(
        [a + (b - a) * np.arange(k) / k for a, b, k in zip(ends[:-1], ends[1:], share, strict=True)]
        + [[1.0]]
    )
    sigma = 0.5 * (1.0 - np.cos(np.pi * x))
    sigma[np.cumsum(share)[:-1]] = sigma_break  # the breakpoints exactly, not via cos(arccos(·))
    return sigma


def with_moving_ends(
    problem: TimingProblem,
    qd0: ArrayLike | None = None,
    qde: ArrayLike | None = None,
    *,
    tolerance: float = 1e-8,
) -> TimingProblem:
    """``problem`` starting with the joint velocity ``qd0`` and ending with ``qde`` (None or 0:
    at rest) [rad/s or m/s, shape (n,)].

    A moving end's velocity must point along the path there: θ̇ = θ'(σ)·√b, so b_0 =
    (qd0·θ'_0 / |θ'_0|²)² and qd0 − √b_0 θ'_0 must vanish (to ``tolerance`` relative to |qd0|);
    and it must be within the joint speed limits the problem enforces.

    Raises
    ------
    ConfigurationError
        Naming the joint: a velocity of the wrong shape or not finite, beyond a speed limit,
        across or against the path's direction, or on a path that does not move there.
    """
    ends = []
    for name, qd, k, word in (("qd0", qd0, 0, "start"), ("qde", qde, -1, "end")):
        if qd is None:
            ends.append(0.0)
            continue
        given, qd = qd, real_array(qd)
        if qd is None or qd.shape != (problem.dof,):
            got = repr(given)[:80] if qd is None else f"{qd.size} value{'s' * (qd.size != 1)}"
            raise ConfigurationError(
                f"{name} must be {problem.dof} joint velocities (one per joint), got {got}"
            )
        names = problem.joint_names
        if not np.all(np.isfinite(qd)):
            i = int(np.argmax(~np.isfinite(qd)))
            raise ConfigurationError(f"{name} of joint {names[i]!r} is {qd[i]}", joint=names[i])
        over = np.abs(qd) - problem.velocity * (1.0 + 1e-12)  # (a limit × a ratio rounds)
        if np.any(over > 0.0):
            i = int(np.argmax(over))
            raise ConfigurationError(
                f"{name} of joint {names[i]} is {qd[i]:.6g} rad/s: beyond its speed limit "
                f"{problem.velocity[i]:.6g} rad/s"
            )
        tangent = problem.dtheta[k]
        size = float(np.max(np.abs(qd)))
        if size == 0.0:
            ends.append(0.0)
            continue
        lam = float(qd @ tangent) / float(tangent @ tangent) if np.any(tangent) else 0.0
        across = np.abs(qd - lam * tangent)
        if lam <= 0.0 or np.max(across) > tolerance * size:
            if not np.any(tangent):
                along = "does not move there"
            elif np.max(across) > tolerance * size:
                along = "points elsewhere"
            else:
                along = "goes the other way"
            lam = max(lam, 0.0)
            i = int(np.argmax(np.abs(qd - lam * tangent)))
            raise ConfigurationError(
                f"{name} must point along the path at its {word}, and the path {along}: "
                f"joint {names[i]} would move at {qd[i]:.9g} rad/s where the path's direction "
                f"gives {lam * tangent[i] + 0.0:.9g} rad/s (θ̇ = θ'(s)·ṡ; off by "
                f"{float(np.max(across)) / size:.2g} of the largest |{name}|, tolerance "
                f"{tolerance:g})"
            )
        ends.append(lam * lam)
    return replace(problem, b_ends=(ends[0], ends[1]))
