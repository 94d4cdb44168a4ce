"""The motion between stage 1's samples: torques and joint speeds inside the segments.

The limits are imposed at the samples; :class:`BetweenSamples` evaluates the motion between them and
:func:`uniform_slow_down` / :func:`tighten` bring it back within the limits where it leaves them.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from ..robot import PathCoefficients
from .problem import (
    BETWEEN_POINTS,
    SPEED_SAFETY,
    InteriorSamples,
    acceleration_coefficients,
    check_gravity,
    interior_points,
    safe_limits,
)

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from ..path import Path
    from ..robot import Robot
    from .problem import TimingProblem

__all__ = [
    "BetweenSamples",
    "uniform_slow_down",
    "tighten",
    "inherit_margins",
    "speed_envelope",
    "speed_lines",
]


class BetweenSamples:
    """The motion between the samples: inside every segment and closely next to both rest ends.

    The limits are imposed at the samples; in between, the torques, joint accelerations and joint
    speeds along the exact path can bulge out by O(Δσ²) (or O(√Δσ) next to a rest end with
    damping). Every segment is smooth inside (the grid has a knot at each of the path's
    breakpoints), so they are evaluated at ``points`` interior points of every segment, and between
    neighbouring points j, j + 1 (h apart) bounded from above by

        max(f_j, f_{j+1}) + (max(|κ_j|, |κ_{j+1}|) + |κ_{j+1} − κ_j|) / 8,

    κ ≈ h² f'' the second differences at the points (extrapolated linearly to the knots): the
    error bound of linear interpolation, h² max|f''| / 8, with f'' allowed to vary between the
    points by as much as it does from one point to the next (a peak of f'' between two points
    is then covered; without that term the bound fell short by 3 % of the bulge on a curved
    speed profile). The limits checked are those imposed at the samples (the safety margin
    included). A joint speed θ̇_i² = b θ'_i² is bounded on each interval by the product of b
    (linear there) and the line above θ'_i² that this bound gives (:func:`speed_envelope`),
    whose maximum is found in closed form. Stage 1 imposes these bounds itself (rows of the two
    knots of every segment, see :class:`~nearopt.timing.Discretisation`), so that one solve
    mostly keeps them. Next to the rest ends the quantities are also evaluated at points
    geometrically closer to σ = 0 and 1 (at rest b ∝ σ, so a damping torque d√b rises like
    √σ).
    """

    def __init__(
        self, robot: Robot, path: Path, problem: TimingProblem, points: int = BETWEEN_POINTS
    ) -> None:
        self.ds = np.diff(problem.sigma)
        inside = problem.interior
        if inside is None or inside.points != points:  # the problem's own points, if it has them
            seg, where, sigma = interior_points(problem.sigma, points)
            s = sigma * path.s_end
            theta, dtheta = path(s, 0), path(s, 1) * path.s_end
            ddtheta = path(s, 2) * path.s_end**2
            inside = InteriorSamples(
                points,
                seg,
                where,
                sigma,
                theta,
                dtheta,
                robot.path_coefficients(theta, dtheta, ddtheta),
                acceleration_coefficients(dtheta, ddtheta),
            )
        self.seg, self.where, self.sigma = inside.segment, inside.weight, inside.sigma
        self.points = points
        self.theta, self.dtheta = inside.theta, inside.dtheta
        self.coefs = [inside.torque]
        if problem.acceleration is not None:
            self.coefs.append(inside.acceleration)
        self.problem = problem
        self._slope_lines: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None
        order = np.argsort(self.sigma)  # gravity between the knots too
        check_gravity(problem, self.coefs[0].g[order], self.sigma[order], self.theta[order])

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
        margin = _margin(v)
        return (
            np.maximum(v[:, :-1], v[:, 1:]) + margin,
            np.minimum(v[:, :-1], v[:, 1:]) - margin,
        )

    def _terms(self, b: NDArray[np.float64]) -> list[tuple[list, list]]:
        """For every quantity of ``problem.quantities``, q = G + W α + D √α for the profile αb:
        (G, W, D) at the start, the points inside and the end of every segment, each
        (N, P + 2, n), and (G, W, D) at the points next to the rest ends."""
        p = self.problem
        acc = (np.diff(b) / (2.0 * self.ds))[:, None]
        acc_pts = acc[self.seg]
        b_pts = (b[self.seg] + self.where * (b[self.seg + 1] - b[self.seg]))[:, None]
        inner = p.segments * self.points
        out = []
        for quantity, coef in zip(p.quantities, self.coefs, strict=True):
            knots = quantity.coef
            parts = [
                (k.g, k.m * a + k.c * bb, k.d * np.sqrt(bb))
                for k, a, bb in (
                    (_rows(knots, slice(0, -1)), acc, b[:-1, None]),
                    (coef, acc_pts, b_pts),
                    (_rows(knots, slice(1, None)), acc, b[1:, None]),
                )
            ]
            along = [self._along(*(part[t] for part in parts)) for t in range(3)]
            out.append((along, [part[inner:] for part in parts[1]]))
        return out

    def excess(self, b: NDArray[np.float64], alpha: float = 1.0) -> list[NDArray[np.float64]]:
        """For every quantity of ``problem.quantities``, its worst excess beyond the limits
        imposed at the samples in every segment for αb, per joint, shape (N, n) [its unit]."""
        out = []
        root = np.sqrt(alpha)
        for quantity, (along, near) in zip(self.problem.quantities, self._terms(b), strict=True):
            lower, upper = safe_limits(quantity)
            hi, lo = self._envelope(along[0] + alpha * along[1] + root * along[2])
            worst = np.max(np.maximum(hi - upper, lower - lo), axis=1)
            value = near[0] + alpha * near[1] + root * near[2]
            np.maximum.at(
                worst,
                self.seg[self.problem.segments * self.points :],
                np.maximum(value - upper, lower - value),
            )
            out.append(worst)
        return out

    def scale_into_limits(self, b: NDArray[np.float64]) -> NDArray[np.float64]:
        """b scaled by the largest α ≤ 1 that keeps every quantity within its limits everywhere.

        Since q(αb) = g + α(m a + c b) + √α dλ, a uniform α restores the limits at the cost of a
        relative slow-down of the order of the bulge. The bound of :meth:`excess` on an interval
        between points (see the class) holds if and only if each of its sixteen sums
        (:func:`_envelope_crossing`) does; each is G + W α + D √α, so α is the smallest first
        crossing of a limit by one of these, found in closed form.
        """
        return self.largest_alpha(b) * b

    def largest_alpha(self, b: NDArray[np.float64]) -> float:
        """The largest α ∈ [0, 1] with every quantity of αb within its limits (see
        :meth:`scale_into_limits`; the same bound as :meth:`excess`)."""
        alpha = 1.0
        for quantity, (terms, near) in zip(self.problem.quantities, self._terms(b), strict=True):
            lower, upper = safe_limits(quantity)
            hi, lo = self._envelope(terms[0] + terms[1] + terms[2])  # at α = 1
            damped = bool(np.any(terms[2] != 0.0))
            for sign, limit, bound in ((1.0, upper, hi), (-1.0, lower, lo)):
                finite = np.isfinite(limit)
                # a sum G + W α within its limit at α = 0 (gravity) and at 1 is so in between;
                # with damping (+ D √α) it may leave it in between: then every interval counts
                over = finite & (damped | (sign * bound > sign * limit))
                if np.any(over):
                    alpha = min(alpha, _envelope_crossing(terms, over, sign, limit))
                g, w, d = (x[:, finite] for x in near)
                alpha = min(alpha, _first_crossing(sign * w, sign * d, sign * (g - limit[finite])))
        return alpha

    def _speed_squared(self, b: NDArray[np.float64]) -> NDArray[np.float64]:
        """Upper bounds of θ̇_i² = b θ'_i² on each interval between points, (N, P + 1, n): the
        largest product of b (linear there) and the line above θ'_i² of :func:`speed_envelope`
        (a quadratic in the interval's coordinate, its maximum in closed form)."""
        if self._slope_lines is None:
            p = self.problem
            self._slope_lines = speed_envelope(
                self._along(p.dtheta[:-1], self.dtheta, p.dtheta[1:]),
                (p.b_ends[0] > 0.0, p.b_ends[1] > 0.0),
            )
        g0, g1 = self._slope_lines
        frac = np.arange(self.points + 2) / (self.points + 1)
        b_pts = b[:-1, None] + frac[None, :] * (b[1:] - b[:-1])[:, None]
        x0, x1 = b_pts[:, :-1, None], b_pts[:, 1:, None]
        return _largest_product(x0, x1 - x0, g0, g1 - g0)

    def speed_excess(self, b: NDArray[np.float64]) -> NDArray[np.float64]:
        """The factor (≤ 1 where a joint speed may exceed its limit) by which b must shrink in
        every segment to keep all joint speeds within their limits, shape (N,)."""
        velocity = self.problem.velocity * np.sqrt(1.0 - 2.0 * SPEED_SAFETY)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = velocity**2 / self._speed_squared(b)
        return np.min(np.where(ratio > 0, ratio, np.inf), axis=(1, 2))

    def speed_scale(self, b: NDArray[np.float64]) -> float:
        """The largest α ≤ 1 such that αb keeps every joint speed within its limit (θ̇² ∝ α)."""
        return float(min(1.0, np.min(self.speed_excess(b))))


def _rows(coef: PathCoefficients, at: slice) -> PathCoefficients:
    return PathCoefficients(*(x[at] for x in coef))


def _curvature(v: NDArray[np.float64]) -> NDArray[np.float64]:
    """Second differences κ of values along the segments' points (axis 1), at every point: at
    the inner points as they are, at both ends extrapolated linearly from the two next ones
    (κ_0 = 2κ_1 − κ_2), so that a second derivative that grows towards an end of the segment
    is not underestimated there (the bound of an end interval uses κ at both its ends)."""
    curvature = v[:, :-2] - 2.0 * v[:, 1:-1] + v[:, 2:]
    if curvature.shape[1] < 2:
        return np.concatenate([curvature[:, :1], curvature, curvature[:, -1:]], axis=1)
    first = 2.0 * curvature[:, :1] - curvature[:, 1:2]
    last = 2.0 * curvature[:, -1:] - curvature[:, -2:-1]
    return np.concatenate([first, curvature, last], axis=1)


def speed_envelope(
    slope: NDArray[np.float64], fixed: tuple[bool, bool] = (False, False)
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Lines above θ'_i² on each interval between the points of a segment.

    ``slope`` holds θ'_i at the start, the points inside and the end of every segment,
    (N, P + 2, n). On the interval between points j and j + 1, θ'_i² lies below its chord plus
    the margin e_j = (max(|κ_j|, |κ_{j+1}|) + |κ_{j+1} − κ_j|) / 8 of
    :meth:`BetweenSamples._envelope` (κ its second differences), i.e. below the line from
    G0 = θ'_i(j)² + e_j to G1 = θ'_i(j+1)² + e_j. Returns (G0, G1), each (N, P + 1, n).

    ``fixed`` (start, end): whether b is fixed at σ = 0 (at σ = 1) — a moving end. There the
    line is exact at the end itself: θ'² lies below the chord plus 4 e t(1 − t) ≤ 4 e t (t the
    interval's coordinate from that end), so below the line from θ'_i(end)² to the other point's
    θ'_i² + 4 e. The speed at a moving end is the user's, at most the limit; with the margin
    there, a start at its speed limit could never be certified.
    """
    g = slope**2
    margin = _margin(g)
    g0, g1 = g[:, :-1] + margin, g[:, 1:] + margin
    if fixed[0]:
        g0[0, 0], g1[0, 0] = g[0, 0], g[0, 1] + 4.0 * margin[0, 0]
    if fixed[1]:
        g0[-1, -1], g1[-1, -1] = g[-1, -2] + 4.0 * margin[-1, -1], g[-1, -1]
    return g0, g1


def _margin(v: NDArray[np.float64]) -> NDArray[np.float64]:
    """(max(|κ_j|, |κ_{j+1}|) + |κ_{j+1} − κ_j|) / 8 on each interval between points (axis 1):
    how far a smooth function may leave its chord there (κ of :func:`_curvature`)."""
    curvature = _curvature(v)
    change = np.abs(np.diff(curvature, axis=1))
    curvature = np.abs(curvature)
    return (np.maximum(curvature[:, :-1], curvature[:, 1:]) + change) / 8.0


def speed_lines(
    g0: NDArray[np.float64], g1: NDArray[np.float64], fixed: tuple[bool, bool] = (False, False)
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Bounds (B0, B1) on b at both ends of an interval such that b, linear between them,
    keeps b Ĝ ≤ 1 on the whole interval, Ĝ the line from g0 to g1 (≥ 0; any shape).

    1/Ĝ is convex, so each of its tangents lies below it: b under a tangent at both ends is
    under 1/Ĝ in between. Of the tangents at the middle (off by (ΔG/Ĝ)²/4 of 1/Ĝ at both ends)
    and at the end where Ĝ is larger (exact there, off by (ΔG/Ĝ)² at the other end, never
    below 0), the one off by less at its worse end. Where Ĝ = 0 at both ends: inf (no bound).
    A speed limit v with the line above θ'² of :func:`speed_envelope` gives b ≤ v² B.

    ``fixed`` (start, end): b is fixed at σ = 0 (σ = 1), at most 1/Ĝ there; the interval next to
    it takes the tangent at that end (b may start at the limit and bend away from it along the
    tangent), unless it falls to 0 within the interval."""
    dg = g1 - g0
    best = (np.full(g0.shape, np.inf), np.full(g0.shape, np.inf))
    best_ratio = np.full(g0.shape, -np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for at in (np.full(g0.shape, 0.5), np.where(dg >= 0.0, 1.0, 0.0)):
            g_at = g0 + at * dg
            slope = -dg / g_at**2  # d(1/Ĝ)/dt there
            ends = (1.0 / g_at - at * slope, 1.0 / g_at + (1.0 - at) * slope)
            # how much of 1/Ĝ each end keeps (1 where Ĝ = 0 there: no bound needed)
            ratio = np.minimum(
                np.where(g0 > 0.0, ends[0] * g0, 1.0), np.where(g1 > 0.0, ends[1] * g1, 1.0)
            )
            better = (g_at > 0.0) & (ratio > best_ratio)
            best = tuple(np.where(better, e, old) for e, old in zip(ends, best, strict=True))
            best_ratio = np.where(better, ratio, best_ratio)
        for end, at in ((0, (0, 0)), (1, (-1, -1))):
            if not fixed[end]:
                continue
            g_end, g_other = (g0[at], g1[at]) if end == 0 else (g1[at], g0[at])
            far = 1.0 / g_end - (g_other - g_end) / g_end**2
            use = (g_end > 0.0) & (far > 0.0)
            tangent = (1.0 / g_end, far) if end == 0 else (far, 1.0 / g_end)
            for out, value in zip(best, tangent, strict=True):
                out[at] = np.where(use, value, out[at])
    return best


def _largest_product(
    x0: NDArray[np.float64],
    dx: NDArray[np.float64],
    g0: NDArray[np.float64],
    dg: NDArray[np.float64],
) -> NDArray[np.float64]:
    """max over t ∈ [0, 1] of (x0 + dx t)(g0 + dg t), elementwise."""
    a2 = dx * dg
    a1 = x0 * dg + g0 * dx
    ends = np.maximum(x0 * g0, (x0 + dx) * (g0 + dg))
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(a2 < 0.0, -a1 / (2.0 * a2), -1.0)
    inside = (t > 0.0) & (t < 1.0)
    peak = x0 * g0 + a1 * t + a2 * t * t
    return np.where(inside, np.maximum(ends, peak), ends)


def _envelope_crossing(
    terms: list[NDArray[np.float64]], where: NDArray[np.bool_], sign: float, limit: NDArray
) -> float:
    """The largest α ∈ [0, 1] with every one of the sixteen sums q_i ± κ_l / 8 ± (κ_{j+1} −
    κ_j) / 8 of every interval j between points where ``where`` ((N, P + 1, n)) holds (i, l ∈
    {j, j + 1}, κ the second differences of :func:`_curvature`) within its limit for all
    α' ≤ α, each sum formed for G, W and D of ``terms`` ((N, P + 2, n) each) and taken as
    sign · (G + W α + D √α − limit) ≤ 0: the bound of :meth:`BetweenSamples._envelope` lies
    within a limit if and only if all of them do. :func:`_first_crossing`'s arithmetic,
    compiled (:func:`~nearopt.timing._kernels.envelope_crossing`; the sums are not stored)."""
    from ._kernels import envelope_crossing

    seg, at, joint = np.nonzero(where)
    curvatures = [_curvature(v) for v in terms]
    t = envelope_crossing(*terms, *curvatures, seg, at, joint, float(sign), limit)
    return 0.0 if t < 0.0 else float(min(1.0, t**2))


def _first_crossing(
    w: NDArray[np.float64], d: NDArray[np.float64], c: NDArray[np.float64]
) -> float:
    """The largest α ∈ [0, 1] with c + d t + w t² ≤ 0 for all t = √α' ≤ √α, every element
    (0 where some c > 0 already, or c = 0 and the sum rises from there)."""
    c, d, w = c.ravel(), d.ravel(), w.ravel()
    if np.any(c > 0.0) or np.any((c == 0.0) & ((d > 0.0) | ((d == 0.0) & (w > 0.0)))):
        return 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        disc = d * d - 4.0 * w * c
        root = np.sqrt(np.maximum(disc, 0.0))
        # the roots q / w and c / q, q = −(d + sign(d) √disc) / 2 (no cancellation)
        q = -0.5 * (d + np.where(d >= 0.0, root, -root))
        t = np.stack([q / w, c / q])
    t = np.where(np.isfinite(t) & (t > 0.0) & (disc >= 0.0), t, np.inf)
    linear = (w == 0.0) & (d > 0.0)
    with np.errstate(divide="ignore"):
        t_lin = np.where(linear, -c / np.where(linear, d, 1.0), np.inf)
    t = np.where(w == 0.0, t_lin, np.min(t, axis=0))
    return float(min(1.0, np.min(t) ** 2)) if t.size else 1.0


def uniform_slow_down(between: BetweenSamples, b: NDArray[np.float64]) -> NDArray[np.float64]:
    """αb with the largest α ≤ 1 that keeps every quantity and speed within its limits."""
    b = between.scale_into_limits(b)
    return b * between.speed_scale(b)


def tighten(
    problem: TimingProblem, between: BetweenSamples, b: NDArray[np.float64]
) -> TimingProblem | None:
    """The problem tightened where the motion leaves a limit between samples; None if it does not.

    A segment whose torque (or acceleration) exceeds a limit by e between its samples gets margin
    1.5 e more at both its samples (capped so that b = 0 stays strictly inside the tightened
    limits); a segment whose joint speed would have to shrink b by a factor r < 1 gets b ≤ r b at
    both its knots.
    """
    excess = between.excess(b)
    ratio = between.speed_excess(b)
    slow = ratio < 1.0
    if not any(np.any(e > 0) for e in excess) and not np.any(slow):
        return None
    big_n = problem.segments
    node = np.concatenate([np.arange(big_n), np.arange(1, big_n + 1)])
    tightened = []
    for quantity, worst in zip(problem.quantities, excess, strict=True):
        old = np.zeros((2 * big_n, problem.dof)) if quantity.margin is None else quantity.margin
        add = 1.5 * np.maximum(worst, 0.0)
        g = quantity.coef.g[node]
        lower, upper = safe_limits(quantity)
        room = np.minimum(upper - g, g - lower)
        margin = np.minimum(old + np.vstack([add, add]), 0.9 * room)
        tightened.append(quantity._replace(margin=margin))
    b_upper = np.full(big_n + 1, np.inf) if problem.b_upper is None else problem.b_upper.copy()
    seg = np.flatnonzero(slow)
    for knots in (seg, seg + 1):
        b_upper[knots] = np.minimum(b_upper[knots], (1.0 - 1e-9) * ratio[seg] * b[knots])
    return replace(
        problem,
        torque=tightened[0],
        acceleration=tightened[1] if len(tightened) > 1 else None,
        b_upper=b_upper,
    )


def inherit_margins(problem: TimingProblem, other: TimingProblem) -> TimingProblem:
    """``problem`` with the torque and acceleration margins of ``other`` (the same grid), capped
    so that b = 0 stays strictly inside the tightened limits."""
    big_n = problem.segments
    node = np.concatenate([np.arange(big_n), np.arange(1, big_n + 1)])
    inherited = []
    for quantity, source in zip(problem.quantities, other.quantities, strict=False):
        if source.margin is None:
            inherited.append(quantity)
            continue
        g = quantity.coef.g[node]
        lower, upper = safe_limits(quantity)
        room = np.minimum(upper - g, g - lower)
        inherited.append(quantity._replace(margin=np.minimum(source.margin, 0.9 * room)))
    inherited += list(problem.quantities[len(inherited) :])
    return replace(
        problem,
        torque=inherited[0],
        acceleration=inherited[1] if len(inherited) > 1 else None,
    )
