"""The motion between stage 1's samples: torques and joint speeds inside the segments.

The limits are imposed at the samples; :class:`BetweenSamples` evaluates the motion between them and
:func:`uniform_slow_down` / :func:`tighten` bring it back within the limits where it leaves them.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from .problem import check_gravity
from .solvers import largest_scale

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from ..path import Path
    from ..robot import Robot
    from .problem import TimingProblem

__all__ = ["BetweenSamples", "uniform_slow_down", "tighten"]


class BetweenSamples:
    """The motion between the samples: inside every segment and closely next to both rest ends.

    The limits are imposed at the samples; in between, the torque and the joint speeds along the
    exact path can bulge out by O(Δs²) (or O(√Δs) next to a rest end with damping). They are
    evaluated at ``points`` interior points of every segment, and between neighbouring points
    (h apart) estimated from above by max(f(a), f(c)) + h² max|f''| / 8 with h² f'' taken from
    second differences (the error bound of linear interpolation; exact where f'' varies little
    over 2h), so that the check covers the segment between its points too. Next to the rest ends
    the torque is also evaluated at points geometrically closer to σ = 0 and 1 (at rest b ∝ σ,
    so a damping torque d√b rises like √σ).
    """

    def __init__(self, robot: Robot, path: Path, problem: TimingProblem, points: int = 4) -> None:
        frac = np.arange(1, points + 1) / (points + 1)
        self.ds = np.diff(problem.s)
        big_n = problem.segments
        near = np.geomspace(1e-6, 0.5 / (points + 1), 8)
        self.seg = np.concatenate(
            [np.repeat(np.arange(big_n), points), np.zeros(8, int), np.full(8, big_n - 1)]
        )
        self.where = np.concatenate([np.tile(frac, big_n), near, 1.0 - near])
        self.sigma = problem.s[self.seg] + self.where * self.ds[self.seg]
        s = self.sigma * path.s_end
        self.points = points
        self.theta = path(s, 0)
        self.dtheta = path(s, 1) * path.s_end
        self.coef = robot.path_coefficients(self.theta, self.dtheta, path(s, 2) * path.s_end**2)
        self.problem = problem
        order = np.argsort(self.sigma)  # gravity between the knots too
        check_gravity(problem, self.coef.g[order], self.sigma[order], self.theta[order])

    def _along(
        self, first: NDArray[np.float64], inner: NDArray[np.float64], last: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """Values at the start, the interior points and the end of every segment, (N, P + 2, n)."""
        big_n, points = self.problem.segments, self.points
        inner = inner[: big_n * points].reshape(big_n, points, -1)
        return np.concatenate([first[:, None], inner, last[:, None]], axis=1)

    @staticmethod
    def _envelope(v: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Upper and lower bounds of a smooth function on each interval between points."""
        curvature = np.abs(v[:, :-2] - 2.0 * v[:, 1:-1] + v[:, 2:])
        curvature = np.concatenate([curvature[:, :1], curvature, curvature[:, -1:]], axis=1)
        margin = np.maximum(curvature[:, :-1], curvature[:, 1:]) / 8.0
        return (
            np.maximum(v[:, :-1], v[:, 1:]) + margin,
            np.minimum(v[:, :-1], v[:, 1:]) - margin,
        )

    def _torques(self, b: NDArray[np.float64], alpha: float) -> NDArray[np.float64]:
        """u at every point (interior, then near the rest ends) for the profile αb, (M, n)."""
        seg, c = self.seg, self.coef
        acc = (np.diff(b) / (2.0 * self.ds))[seg, None]
        bb = (b[seg] + self.where * (b[seg + 1] - b[seg]))[:, None]
        return c.g + alpha * (c.m * acc + c.c * bb) + np.sqrt(alpha) * c.d * np.sqrt(bb)

    def excess(self, b: NDArray[np.float64], alpha: float = 1.0) -> NDArray[np.float64]:
        """The worst of u − u_max and u_min − u in every segment for αb, per joint, (N, n)."""
        p = self.problem
        k = p.coef
        acc = (np.diff(b) / (2.0 * self.ds))[:, None]

        def knot(at: slice) -> NDArray[np.float64]:
            bk = b[at][:, None]
            lin = k.m[at] * acc + k.c[at] * bk
            return k.g[at] + alpha * lin + np.sqrt(alpha) * k.d[at] * np.sqrt(bk)

        u = self._torques(b, alpha)
        hi, lo = self._envelope(self._along(knot(slice(0, -1)), u, knot(slice(1, None))))
        worst = np.max(np.maximum(hi - p.u_upper, p.u_lower - lo), axis=1)
        near = u[p.segments * self.points :]
        near_excess = np.maximum(near - p.u_upper, p.u_lower - near)
        np.maximum.at(worst, self.seg[p.segments * self.points :], near_excess)
        return worst

    def scale_into_limits(self, b: NDArray[np.float64]) -> NDArray[np.float64]:
        """b scaled by the largest α ≤ 1 that keeps the torques within the limits everywhere.

        Since u(αb) = g + α(m a + c b) + √α dλ, a uniform α (found by bisection) restores the
        limits at the cost of a relative slow-down of the order of the bulge.
        """
        return largest_scale(lambda alpha: float(np.max(self.excess(b, alpha)))) * b

    def _speed_squared(self, b: NDArray[np.float64]) -> NDArray[np.float64]:
        """Upper bounds of θ̇_i² = b θ'_i² on each interval between points, (N, P + 1, n)."""
        p = self.problem
        frac = np.arange(self.points + 2) / (self.points + 1)
        b_pts = b[:-1, None] + frac[None, :] * (b[1:] - b[:-1])[:, None]
        slope = self._along(p.dtheta[:-1], self.dtheta, p.dtheta[1:])
        return self._envelope(b_pts[:, :, None] * slope**2)[0]

    def speed_excess(
        self, b: NDArray[np.float64], velocity: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """The factor (≤ 1 where a joint speed may exceed its limit) by which b must shrink in
        every segment to keep all joint speeds within their limits, shape (N,)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = velocity**2 / self._speed_squared(b)
        return np.min(np.where(ratio > 0, ratio, np.inf), axis=(1, 2))

    def speed_scale(self, b: NDArray[np.float64], velocity: NDArray[np.float64]) -> float:
        """The largest α ≤ 1 such that αb keeps every joint speed within its limit (θ̇² ∝ α)."""
        return float(min(1.0, np.min(self.speed_excess(b, velocity))))


def uniform_slow_down(
    between: BetweenSamples, b: NDArray[np.float64], velocity: NDArray[np.float64] | None
) -> NDArray[np.float64]:
    """αb with the largest α ≤ 1 that keeps torques (and speeds) within the limits everywhere."""
    b = between.scale_into_limits(b)
    return b if velocity is None else b * between.speed_scale(b, velocity)


def tighten(
    problem: TimingProblem,
    between: BetweenSamples,
    b: NDArray[np.float64],
    velocity: NDArray[np.float64] | None,
) -> TimingProblem | None:
    """The problem tightened where the motion leaves a limit between samples; None if it does not.

    A segment whose torque exceeds a limit by e between its samples gets margin 1.5 e more at
    both its samples (capped so gravity stays strictly inside the tightened limits); a segment
    whose joint speed would have to shrink b by a factor r < 1 gets b ≤ r b at both its knots.
    """
    worst = between.excess(b)
    ratio = np.ones(problem.segments) if velocity is None else between.speed_excess(b, velocity)
    slow = ratio < 1.0
    if not np.any(worst > 0) and not np.any(slow):
        return None
    big_n = problem.segments
    old = np.zeros((2 * big_n, problem.dof)) if problem.margin is None else problem.margin
    add = 1.5 * np.maximum(worst, 0.0)
    margin = old + np.vstack([add, add])
    node = np.concatenate([np.arange(big_n), np.arange(1, big_n + 1)])
    g = problem.coef.g[node]
    room = np.minimum(problem.u_upper - g, g - problem.u_lower)
    b_upper = problem.b_upper.copy()
    seg = np.flatnonzero(slow)
    for knots in (seg, seg + 1):
        b_upper[knots] = np.minimum(b_upper[knots], (1.0 - 1e-9) * ratio[seg] * b[knots])
    return replace(problem, margin=np.minimum(margin, 0.9 * room), b_upper=b_upper)
