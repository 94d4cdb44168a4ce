"""Jerk-limited timing of a path: |θ⃛_i(t)| ≤ j_i for all t, by sequential convex programming
whose every iterate is feasible.

The timing is b(s) = ṡ², C¹ in s, so that θ̈ = θ''b + θ'a (a = b'/2) is continuous and
θ⃛ = √b · L with L = θ'''b + 3θ''a + θ'a' is bounded. On each segment [s_k, s_{k+1}] of the grid,
σ = (s − s_k)/Δ_k:

- inside, b is quadratic: the Bézier form (b_k, m_k, b_{k+1}), with the C¹ condition
  (b_{k+1} − m_k)/Δ_k = (m_{k+1} − b_{k+1})/Δ_{k+1} at every inner knot;
- the first and last segments leave and reach rest with a constant path jerk, s ∝ t³:
  b = β σ^{4/3} (resp. β (1 − σ)^{4/3}), β = b_1 (resp. b_{N−1}), so that θ̇ = θ̈ = 0 at both
  ends (a smooth start and stop) and each end segment takes 3Δ/√β.

The grid includes the path's breakpoints, so that θ is one cubic polynomial on each segment (the
paths of :mod:`nearopt.path` are piecewise cubic; a user's path must be too). Then every quantity
but the torque is a polynomial in σ whose Bernstein coefficients are linear in the segment's
variables, and bounds on the coefficients hold the quantity for all σ (a polynomial lies within
the hull of its Bernstein coefficients):

- speed: θ'_i² b (degree 6, written in degree 8) within v_i²;
- acceleration: θ̈_i (degree 3, written in degree 4) within ±A_i;
- jerk: b ≤ B_k on the segment (B_k ≥ its Bézier coefficients), and
  |θ⃛_i| = √b |L_i| ≤ √B_k |L_i| ≤ j_i ⇐ the coefficients of L_i (degree 2, written in degree 4)
  within ±j_i / √B_k: a convex function of B_k, bounded from below by its tangent at the previous
  iterate's B̄_k — a convex restriction (the convex–concave procedure of Debrouwere et al.,
  2013). Its solution is feasible for the true constraint and the previous iterate is feasible
  for it, so every iterate holds the limits and the duration never increases;
- torque: at the knots and the segments' midpoints, and wherever a check at 32 points inside
  every segment finds it beyond a limit (those points become rows and the timing is solved
  again, :data:`REFINEMENTS` times at most; stage 1's bounds between the samples are not built
  for this timing yet).

The end segments' quantities are β^p times known functions of σ (speed and acceleration p = 1,
jerk p = 3/2): each gives a bound on β. The duration Σ_k Δ_k ∫ dσ/√b is 4-point Gauss–Legendre
quadrature inside and exact at the ends.

Each convex restriction is solved by the banded interior-point kernel of
:mod:`nearopt.timing.banded`: with every segment's m as a variable and every inner knot's b the
Δ-weighted mean of its two neighbouring m (the C¹ condition, by construction; the end segments'
conditions fix the first and last m to β), each row and each term of J touches 5 consecutive
variables (a segment's m, its neighbours' and its B_k), so a Newton step is a banded Cholesky
factorisation, O(N); rows another row of the same segment implies (for b ≥ 0) are left out.
Clarabel's second-order cone program of the same restriction (τ ≥ 1/√b as w ≤ √b, τ w ≥ 1: two
cones per point; the C¹ conditions as equalities) is the reference (``method=SOCP``) and the
fallback where the kernel does not converge.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from functools import cached_property
from math import comb

import clarabel
import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from ..cost import Cost, TimeCost, TorqueCost
from ..errors import ConfigurationError, SolverError
from ..path import Path
from ..robot import Robot
from ..trajectory import InverseDynamics, Motion, MotionCost
from ..validate import is_number
from ._banded_kernels import implied_rows
from .banded import BandedProgram, solve_banded, windows
from .rates import TorqueRateCoefficients, torque_rate_coefficients
from .solvers import TimingMethod

__all__ = [
    "JerkTiming",
    "JerkTimingResult",
    "SmoothTrajectory",
    "jerk_limited_timing",
    "time_with_jerk_limits",
]

MARGIN = 1e-6
"""Every bound is tightened by this much (relative), so that the convex solver's tolerance
leaves no excess."""
REFINEMENTS = 3
"""How often the torque rows are refined at most: where the torque checked at 32 points inside
every segment is beyond a limit, those points become rows too and the timing is solved again."""


def _bernstein(degree: int, sigma: NDArray[np.float64]) -> NDArray[np.float64]:
    """B_r^d(σ), shape (len(σ), d + 1)."""
    r = np.arange(degree + 1)
    binomial = np.array([comb(degree, k) for k in r], dtype=float)
    x = sigma[:, None]
    return binomial * x**r * (1.0 - x) ** (degree - r)


def _collocation(degree: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Equidistant nodes in [0, 1] and the matrix taking a polynomial's values there to its
    Bernstein coefficients of that degree."""
    nodes = np.linspace(0.0, 1.0, degree + 1)
    return nodes, np.linalg.inv(_bernstein(degree, nodes))


_NODES4, _TO_B4 = _collocation(4)
_NODES8, _TO_B8 = _collocation(8)
_GAUSS_X, _GAUSS_W = np.polynomial.legendre.leggauss(4)
_GAUSS_X, _GAUSS_W = 0.5 * (_GAUSS_X + 1.0), 0.5 * _GAUSS_W  # on [0, 1]


@dataclass(frozen=True)
class JerkTiming:
    """A C¹ timing b(s) = ṡ² (see the module docstring).

    Attributes
    ----------
    s
        Knots [path units], shape (N + 1,).
    b
        b at the knots [(path units/s)²]; b_0 = b_N = 0.
    m
        The Bézier middle coefficients of the segments (unused, NaN, on the two end segments).
    history
        J after each convex program of the last refinement of the torque rows, by the model's
        quadrature (time-optimal: the duration [s]; non-increasing, up to the convex solver's
        tolerance); the timing is the best of them.
    solvers
        The back end of each of those programs: :attr:`TimingMethod.INTERIOR` (the banded
        kernel, :mod:`nearopt.timing.banded`) or :attr:`TimingMethod.SOCP` (Clarabel: asked
        for, or where the kernel did not converge).
    timed_out
        Whether the iterations stopped at the time limit (the timing holds every limit, but
        a further iteration would have lowered J).
    """

    s: NDArray[np.float64]
    b: NDArray[np.float64]
    m: NDArray[np.float64]
    history: tuple[float, ...]
    solvers: tuple[TimingMethod, ...] = ()
    timed_out: bool = False

    @property
    def iterations(self) -> int:
        """Convex programs solved."""
        return len(self.history)

    def evaluate(self, s: ArrayLike) -> tuple[NDArray[np.float64], ...]:
        """b, a = b'/2 and a' = da/ds at the path parameters s (at a knot: the segment after
        it), each of shape (len(s),)."""
        s = np.atleast_1d(np.asarray(s, dtype=float))
        last = self.s.size - 2
        k = np.clip(np.searchsorted(self.s, s, side="right") - 1, 0, last)
        d = self.s[k + 1] - self.s[k]
        x = np.clip((s - self.s[k]) / d, 0.0, 1.0)
        b0, b1, m = self.b[k], self.b[k + 1], np.nan_to_num(self.m[k])
        b = (1 - x) ** 2 * b0 + 2 * x * (1 - x) * m + x**2 * b1
        a = ((m - b0) * (1 - x) + (b1 - m) * x) / d
        da = (b0 - 2 * m + b1) / d**2
        for end, beta, r, sign in (
            (k == 0, self.b[1], x, 1.0),
            (k == last, self.b[last], 1.0 - x, -1.0),
        ):
            with np.errstate(divide="ignore", invalid="ignore"):
                b = np.where(end, beta * r ** (4 / 3), b)
                a = np.where(end, sign * (2 / 3) * beta * r ** (1 / 3) / d, a)
                da = np.where(end, (2 / 9) * beta * r ** (-2 / 3) / d**2, da)
        return b, a, da

    def rates(self, path: Path, s: ArrayLike) -> tuple[NDArray[np.float64], ...]:
        """θ̇, θ̈ and θ⃛ = √b (θ‴ b + 3θ″ a + θ′ a′) of ``path`` under this timing at the path
        parameters s, each of shape (len(s), n)."""
        s = np.atleast_1d(np.asarray(s, dtype=float))
        b, a, da = self.evaluate(s)
        q1, q2, q3 = np.asarray(path(s, 1)), np.asarray(path(s, 2)), _third(path, s)
        root = np.sqrt(b)[:, None]
        with np.errstate(invalid="ignore"):
            third = root * (q3 * b[:, None] + 3 * q2 * a[:, None] + q1 * da[:, None])
        return q1 * root, q2 * b[:, None] + q1 * a[:, None], third

    def segment_times(self) -> NDArray[np.float64]:
        """Each segment's duration [s]: 16-point Gauss–Legendre inside, exact at the ends."""
        x, w = np.polynomial.legendre.leggauss(16)
        x, w = 0.5 * (x + 1.0), 0.5 * w
        d = np.diff(self.s)
        b0, b1, m = self.b[:-1, None], self.b[1:, None], self.m[:, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            b = (1 - x) ** 2 * b0 + 2 * x * (1 - x) * m + x**2 * b1
            times = d * np.sum(w / np.sqrt(b), axis=1)
        times[0] = 3.0 * d[0] / np.sqrt(self.b[1])
        times[-1] = 3.0 * d[-1] / np.sqrt(self.b[-2])
        return times

    @property
    def duration(self) -> float:
        """t_e [s]."""
        return float(np.sum(self.segment_times()))

    def time_at(self, s: ArrayLike) -> NDArray[np.float64]:
        """t(s) [s]: when the motion reaches the path parameters s, shape (len(s),) (16-point
        Gauss–Legendre on the part of the segment, exact on the end segments)."""
        s = np.atleast_1d(np.asarray(s, dtype=float))
        times = self.segment_times()
        start = np.concatenate([[0.0], np.cumsum(times)])
        last = self.s.size - 2
        k = np.clip(np.searchsorted(self.s, s, side="right") - 1, 0, last)
        d = self.s[k + 1] - self.s[k]
        x = np.clip((s - self.s[k]) / d, 0.0, 1.0)
        g, w = np.polynomial.legendre.leggauss(16)
        g, w = 0.5 * (g + 1.0), 0.5 * w
        y = x[:, None] * g[None, :]
        b0, b1, m = self.b[k, None], self.b[k + 1, None], np.nan_to_num(self.m[k])[:, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            b = (1 - y) ** 2 * b0 + 2 * y * (1 - y) * m + y**2 * b1
            part = d * x * np.sum(w / np.sqrt(b), axis=1)
            part = np.where(k == 0, 3.0 * d * np.cbrt(x) / np.sqrt(self.b[1]), part)
            rest = 3.0 * d * np.cbrt(1.0 - x) / np.sqrt(self.b[last])
            part = np.where(k == last, times[last] - rest, part)
        return start[k] + part


def jerk_limited_timing(
    robot: Robot,
    path: Path,
    jerk: ArrayLike,
    cost: Cost | None = None,
    *,
    grid: int = 200,
    acceleration: ArrayLike | None = None,
    torque: bool = True,
    max_iterations: int = 30,
    tolerance: float = 1e-6,
    method: TimingMethod = TimingMethod.INTERIOR,
    time_limit: float = np.inf,
    torque_rate: ArrayLike | None = None,
) -> JerkTiming:
    """The C¹ timing of ``path`` that minimises J = ∫ f0 dt (``cost``: time, the default, or
    :class:`~nearopt.TorqueCost`'s 1 + Σ w u²), from rest to rest with θ̈ = 0 at both ends, under
    the robot's speed limits, joint acceleration limits (``acceleration`` [rad/s²], default the
    robot's), the jerk limits ``jerk`` [rad/s³] — these three for all t — and (``torque``) its
    effort limits at the knots and the segments' midpoints, joint damping included (its D θ' √b,
    where concave, by the tangent at the last iterate: every iterate stays feasible).

    Stops when an iteration lowers J (by the model's quadrature) by less than ``tolerance``
    (relative) or after ``max_iterations``. ``method``: each convex program by the banded kernel
    (:attr:`TimingMethod.INTERIOR`, Clarabel where it does not converge) or by Clarabel's SOCP
    (:attr:`TimingMethod.SOCP`); :attr:`JerkTiming.solvers` says which solved.

    ``torque_rate`` [N·m/s or N/s], default the robot's
    (:attr:`~nearopt.robot.JointLimits.torque_rate`): |u̇_i| ≤ r_i at the ends and middles of
    the inner segments and wherever the check at 38 points per segment (and at the peaks
    between them) finds it beyond, by a bound on β on the end segments (see
    :mod:`nearopt.timing.rates`).

    ``time_limit`` [s]: past it no further iteration starts, and the best iterate so far is
    returned (:attr:`JerkTiming.timed_out`) — every iterate holds every limit, so it is a
    valid timing, only a longer (costlier) one. At least one convex program is solved per
    refinement of the torque rows (at most :data:`REFINEMENTS` + 1), whatever the limit.

    Raises
    ------
    ConfigurationError
        Jerk, acceleration or torque-rate limits that are not positive numbers (one, or one
        per joint), a grid below 4 segments, ``max_iterations`` below 1, another cost or
        another method, a time limit that is not a number ≥ 0.
    SolverError
        If a convex program fails.
    """
    n = robot.n
    # the robot's checks of limits: one number or one per joint, > 0, inf for none
    checked = robot.with_limits(
        jerk=jerk,
        acceleration=robot.limits.acceleration if acceleration is None else acceleration,
        torque_rate=robot.limits.torque_rate if torque_rate is None else torque_rate,
    )
    jerk, acc = checked.limits.jerk, checked.limits.acceleration
    rate = checked.limits.torque_rate if np.any(np.isfinite(checked.limits.torque_rate)) else None
    for name, value, low in (("grid", grid, 4), ("max_iterations", max_iterations, 1)):
        if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < low:
            raise ConfigurationError(f"{name} must be an integer ≥ {low}, got {value!r}")
    if not is_number(time_limit) or not time_limit >= 0.0:
        raise ConfigurationError(f"time_limit must be a number of seconds ≥ 0, got {time_limit!r}")
    deadline = time.perf_counter() + float(time_limit)
    timed_out = False
    if method not in (TimingMethod.INTERIOR, TimingMethod.SOCP):
        raise ConfigurationError(
            f"the jerk-limited timing's method is TimingMethod.INTERIOR or SOCP, got {method!r}"
        )
    if cost is None or isinstance(cost, TimeCost):
        weights = None
    elif isinstance(cost, TorqueCost):
        weights = cost.torque_weights(n)
    else:
        raise ConfigurationError(
            "the jerk-limited timing minimises time (TimeCost) or 1 + Σ w u² (TorqueCost), "
            f"got {type(cost).__name__}"
        )
    s = _grid(path, grid)
    model = _Model(robot, path, s, jerk, acc, torque, weights, rate=rate)
    bbar = model.first_linearisation()
    x: NDArray[np.float64] | None = None
    none = (np.zeros(0, dtype=np.int64), np.zeros(0))
    rate_none = (*none, np.zeros(0))
    extra, rate_extra = rate_none, rate_none
    checks: dict[str, TorqueRateCoefficients] = {}  # the torque rate's check points, once
    fallback: tuple[float, NDArray[np.float64]] | None = None
    history: list[float] = []
    solvers: list[TimingMethod] = []
    for _ in range(1 + REFINEMENTS):
        best = fallback
        if fallback is None:
            history, solvers = [], []
        for _ in range(max_iterations):
            try:
                x, value = model.solve(bbar, x, method)
            except SolverError:
                if best is None:  # (no iterate of these rows yet)
                    raise
                x = best[1]
                break  # every iterate so far (or the slowed-down last one) holds every row
            history.append(value)
            solvers.append(model.solver)
            if best is None or value < best[0]:  # (equal up to the solver's 1e-8)
                best = (value, x)
            if len(history) > 1 and history[-2] - value <= tolerance * abs(value):
                break
            if time.perf_counter() >= deadline:
                timed_out = True
                break
            bbar = _floored(x[model.iB])
        assert best is not None
        x = best[1]
        more = rate_none if model.tq is None else model.torque_excess(robot, path, x)
        faster = rate_none if model.rp is None else model.rate_excess(robot, path, x, checks)
        if not more[0].size and not faster[0].size:
            break
        extra = tuple(np.concatenate(pair) for pair in zip(extra, more, strict=True))
        rate_extra = tuple(np.concatenate(pair) for pair in zip(rate_extra, faster, strict=True))
        last_z = model.last_z
        model = _Model(robot, path, s, jerk, acc, torque, weights, extra, rate, rate_extra)
        model.last_z = last_z  # (for the banded kernel's screening of rows)
        x = model.within_rates(x[: model.iB[-1] + 1])  # b, m and B keep their places
        bbar = _floored(x[model.iB])
        # with new torque-rate points only, the slowed-down x holds every row of the new model:
        # where its first program fails, it is the timing (its J above the last program's)
        fallback = (np.inf, x) if not more[0].size else None
    timing = model.timing(x, tuple(history), tuple(solvers), timed_out)
    return _finite(_slowed_down(timing, robot, path, acc, jerk), jerk)


def _finite(timing: JerkTiming, jerk: NDArray[np.float64]) -> JerkTiming:
    """The timing, or a SolverError where it is not finite (a NaN timing was returned at a jerk
    limit of 1e-9 rad/s³)."""
    inner = timing.m[1:-1]
    if not (np.all(np.isfinite(timing.b)) and np.all(np.isfinite(inner)) and timing.duration > 0):
        raise SolverError(
            "the jerk-limited timing is not finite: its limits are too far below what the "
            f"path needs at its scale (jerk limits down to {np.min(jerk):.3g}, the duration "
            f"came out {timing.duration:.3g} s)"
        )
    return timing


def _floored(bbar: NDArray[np.float64]) -> NDArray[np.float64]:
    """B̄ for the next restriction: each B_k at least 1e-12 of the largest, so that the
    tangent's B̄^{-3/2} stays within floating point (a floor of 1e-300 overflows it)."""
    return np.maximum(bbar, 1e-12 * max(float(np.max(bbar)), 1e-300))


def _slowed_down(
    timing: JerkTiming, robot: Robot, path: Path, acc: NDArray, jerk: NDArray
) -> JerkTiming:
    """The timing scaled down uniformly (b → κ b: θ̇ by √κ, θ̈ by κ, θ⃛ by κ^{3/2}) where a check
    at 32 points inside every segment finds the speed, acceleration or jerk beyond a limit:
    what the convex solver's tolerance, amplified on short segments, left. Each ratio to its
    limit then at most 1 − 1e-9."""
    x = np.concatenate([[1e-9], np.linspace(0.0, 1.0, 34)[1:-1], [1.0 - 1e-9]])  # both ends too
    s = (timing.s[:-1, None] + x[None, :] * np.diff(timing.s)[:, None]).ravel()
    qd, qdd, qddd = timing.rates(path, s)
    with np.errstate(divide="ignore", invalid="ignore"):
        speed = np.nanmax(np.abs(qd) / robot.limits.velocity)
        accel = np.nanmax(np.abs(qdd) / acc)
        jerks = np.nanmax(np.abs(qddd) / jerk)
    keep = 1.0 - 1e-9
    ratios = np.array([speed**2, accel, jerks ** (2 / 3)])  # each ∝ κ: what κ = 1 leaves
    kappa = min(1.0, keep / max(float(np.max(ratios)), 1e-300))
    if kappa >= 1.0:
        return timing
    return JerkTiming(
        timing.s,
        kappa * timing.b,
        kappa * timing.m,
        timing.history,
        timing.solvers,
        timing.timed_out,
    )


def _jerk_tangent(
    jerk: NDArray[np.float64] | float, bbar: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The jerk row's tangent at B̄: j/√B ≥ 1.5 j/√B̄ − ½ j B̄^{-3/2} B, as B's coefficient
    (½ j B̄^{-3/2}) and the bound (1.5 j/√B̄, tightened by :data:`MARGIN`)."""
    return 0.5 * jerk * bbar**-1.5, (1.0 - MARGIN) * 1.5 * jerk / np.sqrt(bbar)


_WIDTH = 5
_START_SHARE = 0.9  # the banded kernel starts a later program at this share of the last optimum
"""The banded kernel's window: a segment's rows touch its own and its neighbours' m (and its
B), 5 consecutive variables of z (see :attr:`_Model.reduction`)."""

END_LEVELS = 5
"""The first and last segments are halved this many times (knots at Δ/2, Δ/4, … from each end):
the s ∝ t³ start and stop take one segment, and a short one costs little time where the jerk
limit does not bind there."""


def _grid(path: Path, segments: int) -> NDArray[np.float64]:
    """Uniform knots with the path's breakpoints on knots (the nearest inner knot moves onto a
    breakpoint within 0.3 of a segment of it, else the breakpoint is added: no segment shorter
    than 0.3 of the others but near the ends), and the end segments halved
    :data:`END_LEVELS` times."""
    step = path.s_end / segments
    s = np.linspace(0.0, path.s_end, segments + 1)
    moved = np.zeros(s.size, dtype=bool)
    extra = []
    for x in np.asarray(path.breakpoints, dtype=float):
        k = int(np.argmin(np.abs(s - x)))
        if 0 < k < segments and not moved[k] and abs(s[k] - x) <= 0.3 * step:
            s[k], moved[k] = x, True
        else:
            extra.append(x)
    s = np.unique(np.concatenate([s, extra]))
    halves = 0.5 ** np.arange(1, END_LEVELS + 1)
    return np.unique(np.concatenate([s, s[1] * halves, s[-1] - (s[-1] - s[-2]) * halves]))


def _third(path: Path, s: NDArray[np.float64]) -> NDArray[np.float64]:
    """θ‴(s), shape (len(s), n); 0 for a path that has no third derivative (a straight line)."""
    try:
        return np.asarray(path(s, 3))  # type: ignore[arg-type]
    except ValueError:
        return np.zeros((np.size(s), path.dof))


def _derivatives(path: Path, s0: NDArray, d: NDArray, nodes: NDArray) -> tuple[NDArray, ...]:
    """θ', θ'', θ''' of each segment's cubic at the σ nodes, shape (N, P, n) each, from its
    derivatives at the segment's midpoint (exact for a cubic; away from its breakpoints)."""
    mid = s0 + 0.5 * d
    p1, p2, p3 = np.asarray(path(mid, 1)), np.asarray(path(mid, 2)), _third(path, mid)
    u = ((nodes[None, :] - 0.5) * d[:, None])[..., None]  # (N, P, 1)
    d1 = p1[:, None, :] + p2[:, None, :] * u + 0.5 * p3[:, None, :] * u**2
    d2 = p2[:, None, :] + p3[:, None, :] * u
    d3 = np.broadcast_to(p3[:, None, :], d1.shape)
    return d1, d2, d3


class _Rows:
    """Rows h − A x ≥ 0 (or = 0) gathered block by block."""

    def __init__(self) -> None:
        self.rows: list[NDArray] = []
        self.cols: list[NDArray] = []
        self.vals: list[NDArray] = []
        self.h: list[NDArray] = []
        self.count = 0

    def add(self, cols: NDArray, vals: NDArray, h: NDArray) -> None:
        """Rows with the coefficients vals[r, :] at the columns cols[r, :] (A) and h[r]."""
        cols, vals = np.atleast_2d(cols), np.atleast_2d(vals)
        cols, vals = np.broadcast_arrays(cols, vals)
        h = np.broadcast_to(np.asarray(h, dtype=float), (cols.shape[0],))
        at = self.count + np.arange(cols.shape[0])
        self.rows.append(np.repeat(at, cols.shape[1]))
        self.cols.append(cols.ravel())
        self.vals.append(vals.ravel().astype(float))
        self.h.append(h.copy())
        self.count += cols.shape[0]

    def matrix(self, columns: int) -> tuple[sp.csr_matrix, NDArray[np.float64]]:
        if not self.rows:
            return sp.csr_matrix((0, columns)), np.zeros(0)
        a = sp.csr_matrix(
            (np.concatenate(self.vals), (np.concatenate(self.rows), np.concatenate(self.cols))),
            shape=(self.count, columns),
        )
        return a, np.concatenate(self.h)


@dataclass(frozen=True)
class _Points:
    """Points of the path where the torque is needed: u = A x + g + δ √b, with b = bw · x[cols],
    A x = (m aw + c bw) · x[cols] (per joint), δ = D θ' (the damping's share of u / √b).

    ``root`` is what w ≤ √root bounds there: b itself inside, β on an end segment, where
    √b = κ √β (κ = r^{2/3}); ``kappa`` is 1 inside."""

    cols: NDArray[np.int64]  # (P, 3)
    bw: NDArray[np.float64]  # (P, 3)
    aw: NDArray[np.float64]  # (P, 3)
    m: NDArray[np.float64]  # (P, n)
    c: NDArray[np.float64]
    g: NDArray[np.float64]
    delta: NDArray[np.float64]
    kappa: NDArray[np.float64]  # (P,)
    root_w: NDArray[np.float64]  # (P, 3): root = root_w · x[cols]
    seg: NDArray[np.int64]  # (P,)

    def affine(self) -> NDArray[np.float64]:
        """A: (P, n, 3)."""
        return self.m[:, :, None] * self.aw[:, None, :] + self.c[:, :, None] * self.bw[:, None, :]


@dataclass(frozen=True)
class _RatePoints:
    """Points of the inner segments where the torque rate is held: u̇ = √b (L·x[cols] + g')
    + E·x[cols] (:mod:`nearopt.timing.rates`), b = bw·x[cols]."""

    cols: NDArray[np.int64]  # (P, 3): b_k, m_k, b_{k+1}
    bw: NDArray[np.float64]  # (P, 3)
    margin: NDArray[np.float64]  # (P,): the limit there is r (1 − margin)
    lin: NDArray[np.float64]  # L, (P, n, 3)
    damped: NDArray[np.float64]  # E, (P, n, 3)
    coef: TorqueRateCoefficients
    seg: NDArray[np.int64]  # (P,)


@dataclass(frozen=True)
class _Peaks:
    """Each segment's and joint's largest sample of a normalised load (1 at the limit) where it
    is a local maximum above :data:`NEAR`: the segment's index, the vertex σ of the parabola
    through it and its two neighbours, and |load''| there (per unit σ²)."""

    index: NDArray[np.int64]
    sigma: NDArray[np.float64]
    bend: NDArray[np.float64]


NEAR = 0.99
"""A sample's load (1 at a limit) from which the peak between it and its neighbours is checked."""


def _peaks(grid: NDArray[np.float64], load: NDArray[np.float64]) -> _Peaks:
    """:class:`_Peaks` of ``load`` (K segments, S samples at σ = ``grid``, n joints)."""
    size = grid.size
    top = np.clip(np.argmax(load, axis=1), 1, size - 2)  # (K, n)
    k_index = np.arange(load.shape[0])[:, None]
    y0, y1, y2 = (load[k_index, top + o, np.arange(load.shape[2])] for o in (-1, 0, 1))
    x0, x1, x2 = grid[top - 1], grid[top], grid[top + 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        den = (x1 - x0) * (y1 - y2) - (x1 - x2) * (y1 - y0)
        vertex = x1 - 0.5 * ((x1 - x0) ** 2 * (y1 - y2) - (x1 - x2) ** 2 * (y1 - y0)) / den
        bend = 2 * np.abs((y2 - y1) / (x2 - x1) - (y1 - y0) / (x1 - x0)) / (x2 - x0)
    keep = (y1 >= y0) & (y1 >= y2) & (y1 > NEAR) & np.isfinite(vertex)
    index = np.broadcast_to(np.arange(load.shape[0])[:, None], top.shape)[keep]
    return _Peaks(index, np.clip(vertex[keep], x0[keep], x2[keep]), bend[keep])


def _dense_rows(
    grid: NDArray[np.float64], seg: NDArray[np.int64], bend: NDArray[np.float64]
) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
    """Rows at every sample of each segment with a peak beyond a limit, with a margin: the
    optimum puts its peaks between its rows, above them by about |load''| h²/8 (h the rows'
    spacing; a row at the peak alone only moves the next peak next to it, a few times smaller
    per refinement). The margin is twice that, the largest over the segment's peaks: segments,
    σ and margins."""
    spacing = float(np.max(np.diff(grid)))
    dense, where = np.unique(seg, return_inverse=True)
    margins = np.zeros(dense.size)
    np.maximum.at(margins, where, 2.0 * bend * spacing**2 / 8.0)
    size = grid.size
    return np.repeat(dense, size), np.tile(grid, dense.size), np.repeat(margins, size)


def _rate_coefficients(
    robot: Robot, path: Path, s0: NDArray, d: NDArray, x: NDArray
) -> TorqueRateCoefficients:
    """The torque rate's coefficients at σ = x of the segments [s0, s0 + d] (each (P,)), from
    each segment's own cubic (θ', θ'', θ‴ from its midpoint: one-sided on a breakpoint)."""
    mid = s0 + 0.5 * d
    p1, p2, p3 = np.asarray(path(mid, 1)), np.asarray(path(mid, 2)), _third(path, mid)
    u = ((x - 0.5) * d)[:, None]
    q = np.asarray(path(s0 + x * d, 0))
    return torque_rate_coefficients(
        robot, q, p1 + p2 * u + 0.5 * p3 * u**2, p2 + p3 * u, p3, path.s_end
    )


class _Model:
    """The convex restriction at B̄ (see the module docstring): every row but the jerk rows'
    B_k coefficients and bounds is built once."""

    def __init__(
        self,
        robot: Robot,
        path: Path,
        s: NDArray[np.float64],
        jerk: NDArray[np.float64],
        acc: NDArray[np.float64],
        torque: bool,
        weights: NDArray[np.float64] | None = None,
        extra: tuple[NDArray, NDArray, NDArray] | None = None,
        rate: NDArray[np.float64] | None = None,
        rate_extra: tuple[NDArray, NDArray, NDArray] | None = None,
    ) -> None:
        self.s, self.d = s, np.diff(s)
        self.extra = extra
        self.rate, self.rate_extra = rate, rate_extra
        self.jerk = jerk
        big_n = self.d.size
        if big_n < 4:
            raise ConfigurationError(f"the jerk-limited timing needs ≥ 4 segments, got {big_n}")
        # variables: b_0..b_N, m_0..m_{N−1}, B_0..B_{N−1}, τ and w (4 per segment)
        self.ib = np.arange(big_n + 1)
        self.im = big_n + 1 + np.arange(big_n)
        self.iB = 2 * big_n + 1 + np.arange(big_n)
        self.it = (3 * big_n + 1 + np.arange(4 * big_n)).reshape(big_n, 4)
        self.iw = (7 * big_n + 1 + np.arange(4 * big_n)).reshape(big_n, 4)
        self.nv = 11 * big_n + 1
        inner = np.arange(1, big_n - 1)
        self.inner = inner
        d, lim = self.d, robot.limits
        cols3 = np.stack([self.ib[inner], self.im[inner], self.ib[inner + 1]], axis=1)
        self.cols3 = cols3
        bern2_4 = _bernstein(2, _NODES4)  # b at the degree-4 nodes, (5, 3)
        a_of = np.stack([-(1 - _NODES4), 1 - 2 * _NODES4, _NODES4], axis=1)  # Δ·a at the nodes
        d1, d2, d3 = (x[inner] for x in _derivatives(path, s[:-1], d, _NODES4))
        di = d[inner][:, None, None, None]
        self.slope_peak = np.max(np.abs(d1), axis=1)  # max |θ'| on each inner segment, (K, n)
        # L_i at the nodes, (K, 5, n, 3) → its Bernstein coefficients
        values = (
            d3[..., None] * bern2_4[None, :, None, :]
            + 3 * d2[..., None] * a_of[None, :, None, :] / di
            + d1[..., None] * np.array([1.0, -2.0, 1.0]) / di**2
        )
        self.l_coef = np.einsum("pq,kqnc->kpnc", _TO_B4, values)

        self.eq = self._equalities()
        ineq = _Rows()
        # inner segments: 0 ≤ each Bézier coefficient ≤ B_k
        for c in range(3):
            ineq.add(cols3[:, c : c + 1], -1.0, 0.0)
            ineq.add(np.stack([cols3[:, c], self.iB[inner]], axis=1), np.array([[1.0, -1.0]]), 0.0)
        keep = 1.0 - MARGIN
        # speed: θ'_i² b in degree 8
        v1 = _derivatives(path, s[:-1], d, _NODES8)[0][inner]  # (K, 9, n)
        bern2_8 = _bernstein(2, _NODES8)
        speed = np.einsum("pq,kqnc->kpnc", _TO_B8, v1[..., None] ** 2 * bern2_8[None, :, None, :])
        for j in np.flatnonzero(np.isfinite(lim.velocity)):
            rows = speed[:, :, j, :].reshape(-1, 3)
            ineq.add(np.repeat(cols3, 9, axis=0), rows, keep * lim.velocity[j] ** 2)
        # acceleration: θ''b + θ'a in degree 4
        accel = np.einsum(
            "pq,kqnc->kpnc",
            _TO_B4,
            d2[..., None] * bern2_4[None, :, None, :] + d1[..., None] * a_of[None, :, None, :] / di,
        )
        for j in np.flatnonzero(np.isfinite(acc)):
            rows = accel[:, :, j, :].reshape(-1, 3)
            for sign in (1.0, -1.0):
                ineq.add(np.repeat(cols3, 5, axis=0), sign * rows, keep * acc[j])
        self._end_rows(ineq, robot, path, acc)
        self.limits, self.weights = lim, weights
        self.damped = bool(np.any(robot.damping))
        self.tq: _Points | None = None
        self.last_z: NDArray[np.float64] | None = None  # the banded kernel's last start or optimum
        if torque and np.any(np.isfinite(lim.effort_upper) | np.isfinite(lim.effort_lower)):
            self.tq = self._torque_points(robot, path)
            if self.damped:  # w ≤ √b at every torque point
                self.iwt = self.nv + np.arange(self.tq.seg.size)
                self.nv += self.tq.seg.size
            else:
                self._torque_rows(ineq, np.ones(self.tq.seg.size))
        self.cp: _Points | None = None
        if weights is not None:
            self.cp = self._cost_points(robot, path)
            self.ieps = self.nv + np.arange(self.cp.seg.size)
            self.nv += self.cp.seg.size
        self.rp: _RatePoints | None = None
        if rate is not None:
            self.rp = self._rate_points(robot, path)
        self.fixed = ineq
        # the jerk rows: [Bézier coefficients, B_k] ≤ rhs, coefficients of B_k and rhs per B̄
        rows = []
        for j in np.flatnonzero(np.isfinite(jerk)):
            for sign in (1.0, -1.0):
                coef = sign * self.l_coef[:, :, j, :]  # (K, 5, 3)
                rows.append((j, coef.reshape(-1, 3)))
        self.jerk_rows = rows
        self.cones = self._cones()

    def _end_rows(self, rows: _Rows, robot: Robot, path: Path, acc: NDArray) -> None:
        """The end segments' bounds on β (speed, acceleration, jerk, torque rate)."""
        last = self.d.size - 1
        for k, beta, sign in ((0, self.ib[1], 1.0), (last, self.ib[last], -1.0)):
            cap = (1.0 - MARGIN) * min(
                self._end_cap(robot, path, k, sign, acc), self._end_rate_cap(robot, path, k, sign)
            )
            if np.isfinite(cap):
                rows.add(np.array([[beta]]), np.ones((1, 1)), cap)

    def _equalities(self) -> _Rows:
        """b_0 = b_N = 0, the unused variables of the end segments 0, and C¹ at the inner
        knots (the end segments' power laws included)."""
        big_n, d = self.d.size, self.d
        eq = _Rows()
        one = np.ones((1, 1))
        pinned = [self.ib[0], self.ib[big_n], self.im[0], self.im[big_n - 1]]
        pinned += [self.iB[0], self.iB[big_n - 1]]
        pinned += [*self.it[[0, -1], 1:].ravel(), *self.iw[[0, -1], 1:].ravel()]
        eq.add(np.array(pinned)[:, None], one, 0.0)
        # C¹ at the inner knots
        k = np.arange(2, big_n - 1)
        eq.add(
            np.stack([self.ib[k], self.im[k - 1], self.im[k]], axis=1),
            np.stack([1 / d[k - 1] + 1 / d[k], -1 / d[k - 1], -1 / d[k]], axis=1),
            0.0,
        )
        eq.add(
            np.array([[self.ib[1], self.im[1]]]),
            np.array([[4 / 3 / d[0] + 2 / d[1], -2 / d[1]]]),
            0.0,
        )
        last = big_n - 1
        eq.add(
            np.array([[self.ib[last], self.im[last - 1]]]),
            np.array([[4 / 3 / d[last] + 2 / d[last - 1], -2 / d[last - 1]]]),
            0.0,
        )
        return eq

    def _end_cap(self, robot: Robot, path: Path, k: int, sign: float, acc: NDArray) -> float:
        """The largest β of end segment k under the speed, acceleration and jerk limits (its
        quantities are β^p times functions of σ, their largest magnitudes from 401 points
        and 0.1 % more)."""
        d = self.d[k]
        x = np.linspace(0.0, 1.0, 401)
        x = x[1:] if sign > 0 else x[:-1]  # not at rest, where b = 0
        r = x if sign > 0 else 1.0 - x
        at = self.s[k] + x * d
        q1, q2, q3 = np.asarray(path(at, 1)), np.asarray(path(at, 2)), _third(path, at)
        r = r[:, None]
        lim = robot.limits
        caps = [np.inf]
        with np.errstate(divide="ignore"):
            speed = 1.001 * np.max(q1**2 * r ** (4 / 3), axis=0)
            caps.append(float(np.min(lim.velocity**2 / speed)))
            accel = 1.001 * np.max(
                np.abs(q2 * r ** (4 / 3) + sign * q1 * (2 / 3) * r ** (1 / 3) / d), 0
            )
            caps.append(float(np.min(acc / accel)))
            shape = (2 / 9) * q1 / d**2 + sign * 2 * q2 * r / d + q3 * r**2
            jerk = 1.001 * np.max(np.abs(shape), axis=0)
            caps.append(float(np.min((self.jerk / jerk) ** (2 / 3))))
        return min(caps)

    def _end_rate_cap(self, robot: Robot, path: Path, k: int, sign: float) -> float:
        """The largest β of end segment k under the torque-rate limits: there u̇ = β^{3/2} F +
        β E + √β G with F, E, G functions of σ (b = β r^{4/3}, a = ±⅔ β r^{1/3}/Δ,
        a' = 2/9 β r^{−2/3}/Δ²), |u̇| ≤ β^{3/2}|F| + β|E| + √β|G| increasing in β: the β where
        its largest value over 400 points, 0.1 % more, reaches the limit (by bisection)."""
        if self.rate is None:
            return np.inf
        d = self.d[k]
        x = np.linspace(0.0, 1.0, 401)
        x = x[1:] if sign > 0 else x[:-1]
        r = (x if sign > 0 else 1.0 - x)[:, None]
        coef = _rate_coefficients(robot, path, np.full(x.size, self.s[k]), np.full(x.size, d), x)
        a, da = sign * (2 / 3) * r ** (1 / 3) / d, (2 / 9) * r ** (-2 / 3) / d**2
        root = r ** (2 / 3)
        big_f = np.abs(root * (coef.dm * a + coef.m * da + coef.dc * r ** (4 / 3) + 2 * coef.c * a))
        big_e = np.abs(coef.ddelta * r ** (4 / 3) + coef.delta * a)
        big_g = np.abs(root * coef.dg)
        finite = np.isfinite(self.rate)

        def worst(beta: float) -> float:
            value = beta**1.5 * big_f + beta * big_e + np.sqrt(beta) * big_g
            return float(np.max(1.001 * value[:, finite] / self.rate[finite]))

        lo, hi = 0.0, 1.0
        while worst(hi) <= 1.0 and hi < 1e300:
            lo, hi = hi, hi * 1e3
        if hi >= 1e300:
            return np.inf
        for _ in range(200):
            mid = np.sqrt(lo * hi) if lo > 0.0 else 0.5 * hi
            lo, hi = (mid, hi) if worst(mid) <= 1.0 else (lo, mid)
            if hi - lo <= 1e-12 * hi:
                break
        return lo

    def _rate_points(self, robot: Robot, path: Path) -> _RatePoints:
        """The torque rate's points: both ends (u̇ jumps at a knot with a') and the middle of
        every inner segment, and where a denser check found it beyond a limit (with the margin
        :meth:`rate_excess` gives them)."""
        inner = self.inner
        seg = np.repeat(inner, 3)
        sig = np.tile([0.0, 0.5, 1.0], inner.size)
        margin = np.zeros(seg.size)
        if self.rate_extra is not None:
            seg = np.concatenate([seg, self.rate_extra[0]]).astype(np.int64)
            sig = np.concatenate([sig, self.rate_extra[1]])
            margin = np.concatenate([margin, self.rate_extra[2]])
        d = self.d[seg]
        coef = _rate_coefficients(robot, path, self.s[seg], d, sig)
        bw = np.stack([(1 - sig) ** 2, 2 * sig * (1 - sig), sig**2], axis=1)
        aw = np.stack([-(1 - sig), 1 - 2 * sig, sig], axis=1) / d[:, None]
        daw = np.array([1.0, -2.0, 1.0])[None, :] / d[:, None] ** 2
        lin, damped = coef.forms(bw, aw, daw)
        cols = np.stack([self.ib[seg], self.im[seg], self.ib[seg + 1]], axis=1)
        return _RatePoints(cols, bw, margin, lin, damped, coef, seg)

    def _rate_rows(
        self, rows: _Rows, bbar: NDArray[np.float64], previous: NDArray[np.float64] | None
    ) -> None:
        """|u̇_i| ≤ r_i at the rate points, for each sign: ±(L x + g') ≤ e/√b with b = bw·x
        the point's own (e/√b is convex in x: bounded below by its tangent at the last iterate's
        b̄, at first the segment's B̄ — a restriction the last iterate holds, as the jerk rows')
        and, for a damped arm, ±E x ≤ r − e, with e the share of the limit left to
        √b (L x + g'): r without damping, else at first r/2 and then the middle of what keeps
        the last iterate feasible for both rows (:meth:`within_rates` makes it feasible)."""
        pts, keep = self.rp, 1.0 - MARGIN
        last = None if previous is None else previous[pts.cols]  # (P, 3)
        bb = bbar[pts.seg] if last is None else np.einsum("pc,pc->p", pts.bw, last)
        bb = np.maximum(bb, 1e-12 * float(np.max(bbar)))  # (b̄^{-3/2} finite)
        for j in np.flatnonzero(np.isfinite(self.rate)):
            r = self.rate[j] * (1.0 - pts.margin)
            for sign in (1.0, -1.0):
                lin, const = sign * pts.lin[:, j, :], sign * pts.coef.dg[:, j]
                share = r.copy()
                if self.damped:
                    damped = sign * pts.damped[:, j, :]
                    share = 0.5 * share
                    if last is not None:
                        low = np.sqrt(bb) * (np.einsum("pc,pc->p", lin, last) + const) / keep
                        used = np.einsum("pc,pc->p", damped, last) / keep
                        low, used = np.maximum(low, 0.0), np.maximum(used, 0.0)
                        with np.errstate(divide="ignore", invalid="ignore"):
                            part = np.clip(used / (low + used), 0.05, 0.95)
                        part = np.where(np.isfinite(part), part, 0.5)
                        share = np.clip(low + (1.0 - part) * (r - used - low), 0.0, r)
                    rows.add(pts.cols, damped, keep * (r - share))
                slope, rhs = _jerk_tangent(share, bb)
                rows.add(pts.cols, lin + slope[:, None] * pts.bw, rhs - const)

    def within_rates(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """x slowed down uniformly (b, m, B times κ ≤ 1: the speed, acceleration and jerk only
        fall, the undamped torque moves toward g) until the torque rate holds at every rate
        point — after a refinement the last iterate breaks the new points' rows, and a
        restriction linearised there might hold no timing at all. As κ → 0, u̇ → √κ √b g' → 0:
        the first κ of a geometric sequence (ratio 0.9) that holds them, then bisection
        toward the one before it (the largest κ there that holds them, to 1e-6)."""
        if self.rp is None:
            return x
        pts, keep = self.rp, 1.0 - MARGIN
        columns = x[pts.cols]
        b = np.maximum(np.einsum("pc,pc->p", pts.bw, columns), 0.0)
        lin = np.einsum("pnc,pc->pn", pts.lin, columns)
        damped = np.einsum("pnc,pc->pn", pts.damped, columns)
        limit = keep * self.rate[None, :] * (1.0 - pts.margin)[:, None]
        finite = np.isfinite(self.rate)

        def holds(kappa: float) -> bool:
            rate = np.sqrt(kappa * b)[:, None] * (kappa * lin + pts.coef.dg) + kappa * damped
            return bool(np.all(np.abs(rate[:, finite]) <= limit[:, finite]))

        kappa = 1.0
        for _ in range(400):
            if holds(kappa):
                break
            kappa *= 0.9
        high = min(kappa / 0.9, 1.0)
        while kappa < 1.0 and high - kappa > 1e-6 * high:
            middle = 0.5 * (kappa + high)
            kappa, high = (middle, high) if holds(middle) else (kappa, middle)
        return x * kappa

    def rate_excess(
        self,
        robot: Robot,
        path: Path,
        x: NDArray[np.float64],
        cache: dict[str, TorqueRateCoefficients],
        per_segment: int = 32,
    ) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
        """Where the solution's torque rate is beyond a limit (more than half the margin into
        it): segments, σ and the relative margin of the rows there (see below). Checked at
        ``per_segment`` points inside every inner segment and 3 more near each of its ends
        (u̇'s slope may carry it beyond a limit just past a knot row), and at each joint's
        largest |u̇| between them (the vertex of the parabola through the largest sample and
        its neighbours: rows at points only leave u̇ free to bulge between them). The points'
        coefficients are kept in ``cache`` for the next refinement."""
        near = np.array([0.003, 0.01, 0.02])
        grid = np.sort(
            np.concatenate([near, np.linspace(0.0, 1.0, per_segment + 2)[1:-1], 1.0 - near])
        )
        seg = np.repeat(self.inner, grid.size)
        sig = np.tile(grid, self.inner.size)
        if "check" not in cache:
            cache["check"] = _rate_coefficients(robot, path, self.s[seg], self.d[seg], sig)
        rate = self._rates_at(cache["check"], x, seg, sig)
        limit = (1.0 - 0.5 * MARGIN) * self.rate
        over = np.any(rate > limit, axis=1)
        # the peaks between the samples, where a sample comes near the limit
        peaks = _peaks(grid, (rate / self.rate).reshape(self.inner.size, grid.size, -1))
        peak_seg, peak_sig = self.inner[peaks.index], peaks.sigma
        beyond = np.zeros(0, dtype=bool)
        if peak_seg.size:
            coef = _rate_coefficients(robot, path, self.s[peak_seg], self.d[peak_seg], peak_sig)
            beyond = np.any(self._rates_at(coef, x, peak_seg, peak_sig) > limit, axis=1)
        dense = _dense_rows(grid, peak_seg[beyond], peaks.bend[beyond])
        return (
            np.concatenate([seg[over], peak_seg[beyond], dense[0]]).astype(np.int64),
            np.concatenate([sig[over], peak_sig[beyond], dense[1]]),
            np.concatenate([np.zeros(over.sum() + beyond.sum()), dense[2]]),
        )

    def _rates_at(
        self, coef: TorqueRateCoefficients, x: NDArray[np.float64], seg: NDArray, sig: NDArray
    ) -> NDArray[np.float64]:
        """|u̇| of the solution x at σ = sig (inside) of the inner segments seg, shape (P, n)."""
        at = self.s[seg] + sig * self.d[seg]
        return np.abs(coef.rate(*self.timing(x, ()).evaluate(at)))

    def _points(self, robot: Robot, path: Path, seg: NDArray, x: NDArray) -> _Points:
        """The torque's pieces at σ = x on segments seg (on an end segment x is the distance
        from the knot next to it in σ, ..., see :class:`_Points`)."""
        big_n, last, d = self.d.size, self.d.size - 1, self.d
        cols = np.stack([self.ib[seg], self.im[seg], self.ib[np.minimum(seg + 1, big_n)]], 1)
        dk = d[seg][:, None]
        bw = np.stack([(1 - x) ** 2, 2 * x * (1 - x), x**2], axis=1)
        aw = np.stack([-(1 - x), 1 - 2 * x, x], axis=1) / dk
        root_w, kappa = bw.copy(), np.ones(seg.size)
        for end, beta, sign in ((seg == 0, self.ib[1], 1.0), (seg == last, self.ib[last], -1.0)):
            r = x[end] if sign > 0 else 1.0 - x[end]
            cols[end] = beta
            zero = np.zeros_like(r)
            bw[end] = np.stack([r ** (4 / 3), zero, zero], 1)
            aw[end] = np.stack([sign * (2 / 3) * r ** (1 / 3), zero, zero], 1) / dk[end]
            root_w[end] = np.stack([np.ones_like(r), zero, zero], 1)
            kappa[end] = r ** (2 / 3)
        at = self.s[seg] + x * d[seg]
        q, q1, q2 = (np.asarray(path(at, order)) for order in (0, 1, 2))
        zero = np.zeros_like(q1)
        g = robot._rnea_columns(q, zero, zero)
        return _Points(
            cols,
            bw,
            aw,
            robot._rnea_columns(q, zero, q1) - g,
            robot._rnea_columns(q, q1, q2) - g,
            g,
            robot.damping * q1,
            kappa,
            root_w,
            seg,
        )

    def _cost_points(self, robot: Robot, path: Path) -> _Points:
        """The quadrature points of ∫ Σ w_j u_j² / √b ds: 4-point Gauss–Legendre inside; on an
        end segment in y, σ = y³ (resp. 1 − σ = y³), which takes away the 1/σ^{2/3}."""
        big_n = self.d.size
        inner = self.inner
        seg = np.concatenate([np.repeat(inner, 4), [0] * 4, [big_n - 1] * 4])
        y3 = _GAUSS_X**3
        x = np.concatenate([np.tile(_GAUSS_X, inner.size), y3, 1.0 - y3])
        points = self._points(robot, path, seg, x)
        d = self.d[seg]
        self.cost_omega = (
            np.concatenate([np.tile(_GAUSS_W, inner.size), 3.0 * _GAUSS_W, 3.0 * _GAUSS_W]) * d
        )
        self.cost_root = np.concatenate(
            [self.iw[inner].ravel(), [self.iw[0, 0]] * 4, [self.iw[big_n - 1, 0]] * 4]
        )
        return points

    def _torque_points(self, robot: Robot, path: Path) -> _Points:
        """The knots and the segments' midpoints, but the rest positions (u = g there)."""
        big_n = self.d.size
        seg = np.concatenate([np.repeat(np.arange(big_n), 2), [big_n - 1]])
        sig = np.concatenate([np.tile([0.0, 0.5], big_n), [1.0]])
        keep = ~(((seg == 0) & (sig == 0.0)) | ((seg == big_n - 1) & (sig == 1.0)))
        seg, sig = seg[keep], sig[keep]
        self.tq_margin = np.zeros(seg.size)
        if self.extra is not None:  # where a denser check found the torque beyond a limit
            seg, sig = np.concatenate([seg, self.extra[0]]), np.concatenate([sig, self.extra[1]])
            self.tq_margin = np.concatenate([self.tq_margin, self.extra[2]])
        return self._points(robot, path, seg, sig)

    def torque_excess(
        self, robot: Robot, path: Path, x: NDArray[np.float64], per_segment: int = 32
    ) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
        """Where the solution's torque is beyond a limit (more than half the margin into it):
        segments, σ and the relative margin of the rows there. Checked at ``per_segment``
        points inside every segment and at each joint's largest load between them (the vertex
        of a parabola, as :meth:`rate_excess`); a segment with such a peak gets rows at every
        point with the margin of :func:`_dense_rows`."""
        big_n = self.d.size
        grid = np.linspace(0.0, 1.0, per_segment + 2)[1:-1]
        seg = np.repeat(np.arange(big_n), grid.size)
        sig = np.tile(grid, big_n)
        u = self._torques_at(robot, path, x, seg, sig)
        lim, keep = self.limits, 1.0 - 0.5 * MARGIN
        over = np.any((u > keep * lim.effort_upper) | (u < keep * lim.effort_lower), axis=1)
        scale = np.maximum(np.abs(lim.effort_upper), np.abs(lim.effort_lower))
        load = 1.0 + np.maximum(u - lim.effort_upper, lim.effort_lower - u) / scale
        peaks = _peaks(grid, load.reshape(big_n, grid.size, -1))
        beyond = np.zeros(0, dtype=bool)
        if peaks.index.size:
            v = self._torques_at(robot, path, x, peaks.index, peaks.sigma)
            beyond = np.any((v > keep * lim.effort_upper) | (v < keep * lim.effort_lower), 1)
        dense = _dense_rows(grid, peaks.index[beyond], peaks.bend[beyond])
        return (
            np.concatenate([seg[over], peaks.index[beyond], dense[0]]).astype(np.int64),
            np.concatenate([sig[over], peaks.sigma[beyond], dense[1]]),
            np.concatenate([np.zeros(over.sum() + beyond.sum()), dense[2]]),
        )

    def _torques_at(
        self, robot: Robot, path: Path, x: NDArray[np.float64], seg: NDArray, sig: NDArray
    ) -> NDArray[np.float64]:
        """u of the solution x at σ = sig of the segments seg, shape (P, n)."""
        pts = self._points(robot, path, seg, sig)
        columns = x[pts.cols]  # (P, 3)
        root = np.maximum(np.einsum("pc,pc->p", pts.root_w, columns), 0.0)
        u = np.einsum("pnc,pc->pn", pts.affine(), columns) + pts.g
        return u + pts.delta * (pts.kappa * np.sqrt(root))[:, None]

    def _torque_rows(self, rows: _Rows, bbar: NDArray[np.float64]) -> None:
        """u within the effort limits at the torque points: A x + δ√b ≤ U − g and the lower
        side; δ√b, where it is concave on the side bounded, by its tangent at b̄ (the last
        iterate's b there: an upper bound, so the row is a restriction), else through
        w ≤ √root (then exact)."""
        pts, lim, keep = self.tq, self.limits, 1.0 - MARGIN
        a = pts.affine()  # (P, n, 3)
        root_b = np.maximum(bbar, 1e-300)
        for sign, bound in ((1.0, lim.effort_upper), (-1.0, -lim.effort_lower)):
            finite = np.isfinite(bound)
            for j in np.flatnonzero(finite):
                delta = sign * pts.delta[:, j] * pts.kappa  # its share of sign·u / √root
                vals = sign * a[:, j, :]
                scale = max(abs(lim.effort_upper[j]), abs(lim.effort_lower[j]))
                h = keep * bound[j] - self.tq_margin * scale - sign * pts.g[:, j]
                if not np.any(delta):
                    rows.add(pts.cols, vals, h)
                    continue
                concave = delta > 0
                # concave: δ√r ≤ δ(√r̄ + (r − r̄)/(2√r̄)) with r = root_w · x
                rbar = root_b
                tangent = vals + (delta / (2 * np.sqrt(rbar)))[:, None] * pts.root_w
                h_tangent = h - delta * np.sqrt(rbar) / 2
                rows.add(pts.cols[concave], tangent[concave], h_tangent[concave])
                # convex: δ√r = −|δ|√r ≤ −|δ| w with w ≤ √r
                w = self.iwt[~concave][:, None]
                rows.add(
                    np.hstack([pts.cols[~concave], w]),
                    np.hstack([vals[~concave], delta[~concave][:, None]]),
                    h[~concave],
                )

    def _cones(self) -> tuple[sp.csr_matrix, NDArray[np.float64], NDArray[np.float64], list]:
        """τ ≥ 1/√b at every quadrature point (two second-order cones of 3: ‖(2w, b − 1)‖ ≤
        b + 1 and ‖(2, τ − w)‖ ≤ τ + w), and the objective Σ Δ w_q τ (3Δ τ at the ends)."""
        last = self.d.size - 1
        rows = _Rows()
        objective = np.zeros(self.nv)
        inner = self.inner
        tau = np.concatenate([self.it[inner].ravel(), self.it[[0, last], 0]])
        w = np.concatenate([self.iw[inner].ravel(), self.iw[[0, last], 0]])
        b_cols, b_vals, objective[tau] = self._time_points()
        points = tau.size
        block = np.zeros((points, 6, 3), dtype=np.int64)  # columns of the 6 rows of a point
        value = np.zeros((points, 6, 3))
        bound = np.zeros((points, 6))
        block[:, 0], value[:, 0], bound[:, 0] = b_cols, -b_vals, 1.0  # b + 1
        block[:, 1, 0], value[:, 1, 0] = w, -2.0  # 2w
        block[:, 2], value[:, 2], bound[:, 2] = b_cols, -b_vals, -1.0  # b − 1
        block[:, 3, :2], value[:, 3, :2] = np.stack([tau, w], 1), -1.0  # τ + w
        block[:, 4, 0], bound[:, 4] = tau, 2.0  # 2
        block[:, 5, :2], value[:, 5, :2] = np.stack([tau, w], 1), [-1.0, 1.0]  # τ − w
        rows.add(block.reshape(-1, 3), value.reshape(-1, 3), bound.ravel())
        if self.tq is not None and self.damped:  # ‖(2w, r − 1)‖ ≤ r + 1 at every torque point
            pts, count = self.tq, self.tq.seg.size
            block = np.zeros((count, 3, 3), dtype=np.int64)
            value = np.zeros((count, 3, 3))
            block[:, 0], value[:, 0] = pts.cols, -pts.root_w
            block[:, 1, 0], value[:, 1, 0] = self.iwt, -2.0
            block[:, 2], value[:, 2] = pts.cols, -pts.root_w
            bound = np.tile([1.0, 0.0, -1.0], count)
            rows.add(block.reshape(-1, 3), value.reshape(-1, 3), bound)
        a, h = rows.matrix(self.nv)
        cones = [clarabel.SecondOrderConeT(3)] * (a.shape[0] // 3)
        objective[self.iB] = 1e-9 * float(np.sum(self.d))  # B_k no larger than its rows need
        if self.cp is not None:
            a_cost, h_cost, linear = self._cost_cones()
            a, h = sp.vstack([a, a_cost]), np.concatenate([h, h_cost])
            cones += [clarabel.SecondOrderConeT(self.cp.m.shape[1] + 2)] * self.cp.seg.size
            objective += linear
        return a.tocsr(), h, objective, cones

    def _time_points(self) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
        """The duration's quadrature: Σ ω / √b over 4 Gauss points on every inner segment (b
        from its 3 Bézier coefficients) and the 2 ends' exact 3Δ/√β: columns, weights of b at
        each point, and ω."""
        last, d, inner, ib = self.d.size - 1, self.d, self.inner, self.ib
        b_cols = np.vstack(
            [np.repeat(self.cols3, 4, axis=0), [[ib[1], ib[1], ib[1]], [ib[last]] * 3]]
        )
        b_vals = np.vstack(
            [np.tile(_bernstein(2, _GAUSS_X), (inner.size, 1)), [[1.0, 0, 0], [1.0, 0, 0]]]
        )
        omega = np.concatenate(
            [(d[inner][:, None] * _GAUSS_W[None, :]).ravel(), [3.0 * d[0], 3.0 * d[last]]]
        )
        return b_cols, b_vals, omega

    def _cost_cones(self) -> tuple[sp.csr_matrix, NDArray[np.float64], NDArray[np.float64]]:
        """Σ_j w_j (A_j x + g_j)² ≤ ε ρ at every cost point (ρ ≤ √root: ε ≥ the undamped
        part of Σ w u² / √b), as ‖(2√w_j (A_j x + g_j), ε − ρ)‖ ≤ ε + ρ; and the objective's
        linear part: Σ ω (ε + 2 Σ_j w_j δ_j κ A_j x)."""
        pts, w = self.cp, self.weights
        count, n = pts.seg.size, pts.m.shape[1]
        a_aff = pts.affine()  # (P, n, 3)
        root_w = np.sqrt(w)
        rows = _Rows()
        width = n + 2
        block = np.zeros((count, width, 3), dtype=np.int64)
        value = np.zeros((count, width, 3))
        bound = np.zeros((count, width))
        eps, rho = self.ieps, self.cost_root
        block[:, 0, :2], value[:, 0, :2] = np.stack([eps, rho], 1), -1.0
        block[:, 1 : n + 1] = pts.cols[:, None, :]
        value[:, 1 : n + 1] = -2.0 * root_w[None, :, None] * a_aff
        bound[:, 1 : n + 1] = 2.0 * root_w[None, :] * pts.g
        block[:, n + 1, :2], value[:, n + 1, :2] = np.stack([eps, rho], 1), [-1.0, 1.0]
        rows.add(block.reshape(-1, 3), value.reshape(-1, 3), bound.ravel())
        a, h = rows.matrix(self.nv)
        linear = np.zeros(self.nv)
        np.add.at(linear, eps, self.cost_omega)
        share = 2.0 * np.einsum("pn,pnc->pc", w * pts.delta * pts.kappa[:, None], a_aff)
        np.add.at(linear, pts.cols.ravel(), (self.cost_omega[:, None] * share).ravel())
        self.cost_constant = float(
            np.sum(self.cost_omega * 2.0 * np.sum(w * pts.delta * pts.g, axis=1) * pts.kappa)
        )
        return a, h, linear

    def first_linearisation(self) -> NDArray[np.float64]:
        """B̄ at first: per segment, the b of a constant ṡ² that the speed, acceleration and
        jerk limits allow at the segment's nodes (any B̄ > 0 gives a feasible restriction; a
        good one fewer iterations)."""
        peak = np.max(np.abs(self.l_coef.sum(axis=3)), axis=1)  # L of b ≡ 1: θ''', (K, n)
        # a rest-to-rest ramp over the whole path, s ∝ t³ to its middle: a′ ≈ 4b/S², so
        # |θ⃛| ≈ b^{3/2} |θ'| 4/S² ≤ j
        ramp = self.s[-1] ** 2 / (4.0 * np.maximum(self.slope_peak, 1e-300))
        with np.errstate(divide="ignore"):
            jcap = np.min((self.jerk / np.maximum(peak, 1e-300)) ** (2 / 3), axis=1)
            jcap = np.minimum(jcap, np.min((self.jerk * ramp) ** (2 / 3), axis=1))
        bbar = np.ones(self.d.size)
        bbar[self.inner] = np.clip(jcap, 1e-8, 1e6)
        if self.rp is not None:  # √b |g'|, |c'| b^{3/2} and |D θ''| b each within r/4
            coef, rate = self.rp.coef, self.rate
            with np.errstate(divide="ignore"):
                caps = np.minimum(
                    (0.25 * rate / np.abs(coef.dg)) ** 2,
                    (0.25 * rate / np.abs(coef.dc)) ** (2 / 3),
                )
                caps = np.minimum(caps, 0.25 * rate / np.abs(coef.ddelta))
            np.minimum.at(bbar, self.rp.seg, np.maximum(np.min(caps, axis=1), 1e-300))
        # and the speed limits' (else, with no jerk limit, B̄ = 1e6 sets the solver's units far
        # from b: kinova's b ~ 1e-4 came out at 1e-10 of them)
        with np.errstate(divide="ignore", over="ignore"):  # (a joint that does not move: inf)
            speed = np.min((self.limits.velocity / np.maximum(self.slope_peak, 1e-300)) ** 2, 1)
        bbar[self.inner] = np.minimum(bbar[self.inner], np.maximum(speed, 1e-300))
        return bbar

    def roots(self, points: _Points, x: NDArray[np.float64] | None, bbar: NDArray) -> NDArray:
        """The root (b inside, β at the ends) at the points: the last iterate's, or at first B̄
        of their segment (any positive value keeps every row a restriction)."""
        if x is None:  # the neighbouring inner segment's B̄ on an end segment
            seg = np.clip(points.seg, 1, self.d.size - 2)
            first = bbar[seg]
            if self.damped:  # small enough that the tangent leaves the torque room at b → 0
                lim = self.limits
                room = np.minimum(lim.effort_upper - points.g, points.g - lim.effort_lower)
                with np.errstate(divide="ignore", invalid="ignore"):
                    cap = np.min((np.maximum(room, 0.0) / np.abs(points.delta)) ** 2, axis=1)
                first = np.minimum(first, np.where(np.isfinite(cap), cap, first))
            return np.maximum(first, 1e-12)
        return np.maximum(np.einsum("pc,pc->p", points.root_w, x[points.cols]), 1e-12)

    def solve(
        self,
        bbar: NDArray[np.float64],
        previous: NDArray[np.float64] | None = None,
        method: TimingMethod = TimingMethod.INTERIOR,
    ) -> tuple[NDArray[np.float64], float]:
        """The convex restriction at B̄ (and, for a damped arm's torques and an energy cost,
        at the previous solution's b): the solution vector and the objective (J by the
        model's quadrature, a majorant of it where the damping enters). ``method``: the banded
        interior-point kernel (:mod:`nearopt.timing.banded`; Clarabel where it does not
        converge) or Clarabel's SOCP."""
        torque = _Rows()  # a damped arm's torque rows, at the last b
        roots = None if self.tq is None or not self.damped else self.roots(self.tq, previous, bbar)
        if roots is not None:
            self._torque_rows(torque, roots)
        if self.rp is not None:
            self._rate_rows(torque, bbar, previous)
        objective, offset = self._objective(bbar, previous)
        if method is TimingMethod.INTERIOR:
            answer = self._solve_banded(bbar, previous, torque, objective)
            if answer is not None:
                self.solver = TimingMethod.INTERIOR
                return answer[0], answer[1] + offset
        self.solver = TimingMethod.SOCP
        per_iteration = self._jerk_rows(bbar)
        if roots is not None:
            self._torque_rows(per_iteration, roots)
        if self.rp is not None:
            self._rate_rows(per_iteration, bbar, previous)
        x, value = self._solve_conic(bbar, per_iteration, objective)
        return x, value + offset

    def _jerk_rows(self, bbar: NDArray[np.float64]) -> _Rows:
        """The jerk rows at B̄: coef · (b_k, m_k, b_{k+1}) + ½ j B̄^{-3/2} B_k ≤ 1.5 j / √B̄."""
        inner = self.inner
        rows = _Rows()
        bb = bbar[inner]
        cols = np.hstack([np.repeat(self.cols3, 5, axis=0), np.repeat(self.iB[inner], 5)[:, None]])
        for j, coef in self.jerk_rows:
            slope, rhs = _jerk_tangent(self.jerk[j], bb)
            rows.add(cols, np.hstack([coef, np.repeat(slope, 5)[:, None]]), np.repeat(rhs, 5))
        return rows

    def _objective(
        self, bbar: NDArray[np.float64], previous: NDArray[np.float64] | None
    ) -> tuple[NDArray[np.float64], float]:
        """The conic program's linear objective (the damped energy's δ²√b by its tangent at
        the last b) and the constant it leaves out."""
        objective = self.cones[2].copy()
        offset = 0.0
        if self.cp is not None and self.damped:  # Σ ω w_j δ_j² κ² √root by its tangent
            pts = self.cp
            rbar = self.roots(pts, previous, bbar)
            c = self.cost_omega * np.sum(self.weights * pts.delta**2, axis=1) * pts.kappa**2
            np.add.at(
                objective,
                pts.cols.ravel(),
                ((c / (2 * np.sqrt(rbar)))[:, None] * pts.root_w).ravel(),
            )
            offset = float(np.sum(c * np.sqrt(rbar) / 2))
        if self.cp is not None:
            offset += self.cost_constant  # Σ ω 2 Σ w δ κ g: no variable in it
        return objective, offset

    def _solve_conic(
        self, bbar: NDArray[np.float64], per_iteration: _Rows, objective: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], float]:
        """Clarabel's SOCP of the restriction (every variable of the module docstring)."""
        a_eq, h_eq = self.eq.matrix(self.nv)
        a_fix, h_fix = self.fixed.matrix(self.nv)
        a_it, h_it = per_iteration.matrix(self.nv)
        a_cone, h_cone, _, cone_list = self.cones
        # the variables in units where b is about 1 (the solver's tolerances have an absolute
        # floor: with b ~ 1e-5 they would leave ~1 % of a jerk row), and each linear row's
        # largest coefficient 1
        columns = self.units(bbar)
        linear = sp.vstack([a_eq, a_fix, a_it]).tocsr() @ sp.diags(columns)
        h_linear = np.concatenate([h_eq, h_fix, h_it])
        scale = 1.0 / np.maximum(abs(linear).max(axis=1).toarray().ravel(), 1e-300)
        linear = sp.diags(scale) @ linear
        a = sp.vstack([linear, a_cone @ sp.diags(columns)]).tocsc()
        h = np.concatenate([h_linear * scale, h_cone])
        objective = objective * columns
        cones = [
            clarabel.ZeroConeT(a_eq.shape[0]),
            clarabel.NonnegativeConeT(a_fix.shape[0] + a_it.shape[0]),
            *cone_list,
        ]
        settings = clarabel.DefaultSettings()
        settings.verbose = False
        solution = clarabel.DefaultSolver(
            sp.csc_matrix((self.nv, self.nv)), objective, a, h, cones, settings
        ).solve()
        if str(solution.status) not in ("Solved", "AlmostSolved"):
            raise SolverError(f"the jerk-limited timing's convex program: {solution.status}")
        return columns * np.asarray(solution.x), float(solution.obj_val)

    @cached_property
    def reduction(self) -> sp.csr_matrix:
        """T: x = T z, the model's b, m and B from the banded kernel's variables z, which hold
        the C¹ conditions by construction: per inner segment k (in order) its middle Bézier
        coefficient m_k and B_k, where the first and the last inner segment's m stand for β
        (m_1 = κ β, κ = 1 + ⅔ Δ_1/Δ_0, and likewise at the end), and every inner knot's
        b_k = (Δ_k m_{k−1} + Δ_{k−1} m_k)/(Δ_{k−1} + Δ_k). Every other variable is 0."""
        big_n, d, last = self.d.size, self.d, self.d.size - 1
        inner = self.inner  # 1 … N − 2
        zm = 2 * (inner - 1)  # z's column of segment k's m
        zb = zm + 1
        kappa = np.ones(inner.size)
        kappa[0] = 1.0 + (2.0 / 3.0) * d[1] / d[0]
        kappa[-1] = 1.0 + (2.0 / 3.0) * d[last - 1] / d[last]
        rows = [self.im[inner], self.iB[inner], [self.ib[1]], [self.ib[last]]]
        cols = [zm, zb, [zm[0]], [zm[-1]]]
        vals = [kappa, np.ones(inner.size), [1.0], [1.0]]
        k = np.arange(2, big_n - 1)  # knots between two inner segments
        total = d[k - 1] + d[k]
        for side, weight in ((k - 1, d[k] / total), (k, d[k - 1] / total)):
            rows.append(self.ib[k])
            cols.append(zm[side - 1])
            vals.append(weight * kappa[side - 1])
        t = sp.csr_matrix(
            (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
            shape=(self.nv, 2 * inner.size),
        )
        return t

    def _window_rows(
        self, rows: _Rows, unit: float, prune: bool
    ) -> tuple[NDArray[np.int64], NDArray, NDArray, NDArray, NDArray]:
        """``rows`` over z (x = T·unit·z) in window form, each scaled so that its largest
        coefficient is 1, without the rows another one implies (``prune``) and without those
        on pinned variables only: start, a, e, ℓ, h. A damped arm's torque rows δ w (w ≤ √root,
        see :meth:`_torque_rows`) become δ √(root)."""
        t = self.reduction * unit
        a, h = rows.matrix(self.nv)
        e = np.zeros(h.size)
        ell_rows = sp.csr_matrix((h.size, self.nv))
        if self.tq is not None and self.damped:
            pts = self.tq
            a = a.tocsc()
            by_w = a[:, self.iwt].tocoo()  # at most one w per row
            e[by_w.row] = by_w.data
            roots = sp.csr_matrix(
                (pts.root_w.ravel(), (np.repeat(np.arange(pts.seg.size), 3), pts.cols.ravel())),
                shape=(pts.seg.size, self.nv),
            )
            pick = sp.csr_matrix(
                (np.ones(by_w.row.size), (by_w.row, by_w.col)), shape=(h.size, pts.seg.size)
            )
            ell_rows = pick @ roots
            without_w = np.ones(self.nv)
            without_w[self.iwt] = 0.0
            a = (a @ sp.diags(without_w)).tocsr()
        start, (a_w, ell_w) = windows([(a @ t).tocsr(), (ell_rows @ t).tocsr()], _WIDTH)
        scale = np.max(np.abs(a_w), axis=1)
        keep = (scale > 0.0) | (e != 0.0)
        if np.any(~keep & (h < 0.0)):
            raise SolverError("the jerk-limited timing: a row without variables is violated")
        scale = np.where(scale > 0.0, scale, 1.0)
        a_w, e, h = a_w / scale[:, None], e / scale, h / scale
        if prune:
            order = np.argsort(start, kind="stable")
            group = np.flatnonzero(np.diff(start[order], prepend=-1, append=-2))
            keep &= ~implied_rows(order, group, a_w, np.where(e == 0.0, h, -np.inf))
        return start[keep], a_w[keep], e[keep], ell_w[keep], h[keep]

    @cached_property
    def _fixed_windows(self) -> tuple[NDArray, ...]:
        """The fixed rows in window form, once (the same for every B̄ but h ∝ 1/unit: built at
        unit 1)."""
        return self._window_rows(self.fixed, 1.0, prune=True)

    @cached_property
    def _window_terms(self) -> tuple[NDArray, ...]:
        """The kernel's terms over z (x = T z): the duration at its Gauss points (c0 = 1), then
        the energy's cost points (c0 = 0, the squares w_j (A_j x + g_j)²): start, ℓ, ω, c0, α, g
        and the squares' weights. Built once."""
        t = self.reduction
        b_cols, b_vals, omega = self._time_points()
        count = omega.size
        index = np.repeat(np.arange(count), 3)
        ell = sp.csr_matrix((b_vals.ravel(), (index, b_cols.ravel())), shape=(count, self.nv))
        n = self.weights.size if self.cp is not None else 0
        start, (ell_w,) = windows([(ell @ t).tocsr()], _WIDTH)
        parts = [(start, ell_w, omega, np.ones(count), np.zeros((count, n, _WIDTH)))]
        g = [np.zeros((count, n))]
        if self.cp is not None:
            pts = self.cp
            count = pts.seg.size
            index = np.repeat(np.arange(count), 3)
            roots = sp.csr_matrix(
                (pts.root_w.ravel(), (index, pts.cols.ravel())), shape=(count, self.nv)
            )
            start, (ell_w,) = windows([(roots @ t).tocsr()], _WIDTH)
            affine = pts.affine()  # (P, n, 3)
            alphas = [
                sp.csr_matrix(
                    (affine[:, j, :].ravel(), (index, pts.cols.ravel())), shape=(count, self.nv)
                )
                @ t
                for j in range(n)
            ]
            _, dense = windows([a.tocsr() for a in alphas], _WIDTH, start=start)
            parts.append((start, ell_w, self.cost_omega, np.zeros(count), np.stack(dense, axis=1)))
            g.append(pts.g)
        weights = np.asarray(self.weights, dtype=float) if self.cp is not None else np.zeros(0)
        fields = tuple(np.concatenate(field) for field in zip(*parts, strict=True))
        return (*fields, np.concatenate(g), weights)

    def _window_jerk_rows(
        self, bbar: NDArray[np.float64], unit: float
    ) -> tuple[NDArray[np.int64], NDArray, NDArray, NDArray, NDArray]:
        """:meth:`_jerk_rows` over z (x = T·unit·z) in window form, each scaled so that its
        largest coefficient is 1 (none implies another: each joint's rows bound a second
        difference of b of its own sign). Their coefficients on b and m are the same for every
        B̄: their windows are built once and B_k's coefficient and the bound set per B̄."""
        start, coef, offset, seg, joint = self._jerk_windows
        bb, jerk = bbar[seg], self.jerk[joint]
        a = coef.copy()
        a[np.arange(a.shape[0]), offset], h = _jerk_tangent(jerk, bb)
        scale = np.max(np.abs(a), axis=1)
        h = h / (unit * scale)
        zero = np.zeros(h.size)
        return start, a / scale[:, None], zero, np.zeros_like(a), h

    @cached_property
    def _jerk_windows(self) -> tuple[NDArray, ...]:
        """The jerk rows' b and m coefficients over z in window form, once: start, coefficients,
        B_k's place in each window, the segment and the joint of each row."""
        if not self.jerk_rows:  # torque-rate limits only
            none = np.zeros(0, dtype=np.int64)
            return none, np.zeros((0, _WIDTH)), none, none, none
        rows = _Rows()
        joint = []
        for j, coef in self.jerk_rows:
            rows.add(np.repeat(self.cols3, 5, axis=0), coef, 0.0)
            joint.append(np.full(coef.shape[0], j))
        a, _ = rows.matrix(self.nv)
        seg = np.tile(np.repeat(self.inner, 5), len(self.jerk_rows))
        zb = 2 * (seg - 1) + 1  # B_k's column in z
        start = np.clip(zb - 3, 0, 2 * self.inner.size - _WIDTH)
        _, (coef,) = windows([(a @ self.reduction).tocsr()], _WIDTH, start=start)
        return start, coef, zb - start, seg, np.concatenate(joint)

    def _solve_banded(
        self,
        bbar: NDArray[np.float64],
        previous: NDArray[np.float64] | None,
        torque: _Rows,
        objective: NDArray[np.float64],
    ) -> tuple[NDArray[np.float64], float] | None:
        """The restriction by the banded interior-point kernel, in z (:attr:`reduction`): the
        duration's (and the energy's) epigraph cones become the kernel's terms Σ ω u/√b, the
        damped torque rows' w ≤ √b its rows' √ terms, and rows another row of the same segment
        implies are left out. None where it does not converge."""
        unit = float(np.max(bbar[self.inner]))  # z in units where b is about 1
        parts = [self._fixed_windows, self._window_jerk_rows(bbar, unit)]
        if torque.count:
            parts.append(self._window_rows(torque, unit, prune=False))
        rows = [np.concatenate([part[k] for part in parts]) for k in range(4)]
        h = np.concatenate([parts[0][4] / unit, *(part[4] for part in parts[1:])])
        start, ell, omega, c0, alpha, g, weights = self._window_terms
        lin = objective.copy()
        lin[self.it.ravel()] = 0.0  # in the terms
        if self.cp is not None:
            lin[self.ieps] = 0.0
        program = BandedProgram(
            rows[0].astype(np.int64), np.ascontiguousarray(rows[1]), rows[2],
            np.ascontiguousarray(rows[3]), h,
            start.astype(np.int64), ell * unit, omega, c0, alpha * unit, g, weights,
            unit * (self.reduction.T @ lin),
        )  # fmt: skip
        last = None if previous is None else self._as_z(previous)
        z0 = self._banded_start(bbar, last) / unit
        reference = change = None
        if last is not None:  # the last optimum and the step that led to it, for screening
            reference = last / unit
            if self.last_z is not None:
                change = reference - self.last_z / unit
        self.last_z = z0 * unit if reference is None else reference * unit
        solution = solve_banded(program, z0, tolerance=1e-9, reference=reference, change=change)
        stalled = previous is not None and solution.primal <= 1e-9 and solution.iterations > 0
        if not solution.converged and not (stalled and np.isfinite(solution.value)):
            # (a later program that stalls on its optimality test at a feasible point gives a
            # feasible iterate: the iterations keep the best)
            return None
        return unit * (self.reduction @ solution.z), solution.value

    def _banded_start(
        self, bbar: NDArray[np.float64], last: NDArray[np.float64] | None
    ) -> NDArray[np.float64]:
        """z to start from: 0.9 times the last solution (``last``, in z, :meth:`_as_z`;
        strictly inside its rows where they scale with b), or B̄ for every m and B at first."""
        if last is None:
            z = np.zeros(2 * self.inner.size)
            z[0::2] = bbar[self.inner]
            z[1::2] = bbar[self.inner]
            return z
        return _START_SHARE * np.maximum(last, 1e-12 * float(np.max(bbar)))

    def _as_z(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """The banded kernel's variables of a solution x (in x's units): m_k and B_k of each
        inner segment, b_1 and b_{N−1} for the first and last m (see :attr:`reduction`)."""
        inner, last = self.inner, self.d.size - 1
        z = np.zeros(2 * inner.size)
        z[0::2] = x[self.im[inner]]
        z[0] = x[self.ib[1]]
        z[-2] = x[self.ib[last]]
        z[1::2] = x[self.iB[inner]]
        return z

    def units(self, bbar: NDArray[np.float64]) -> NDArray[np.float64]:
        """Each variable's unit: S = the largest B̄ for b, m and B, √S for the w ≤ √b, 1/√S for
        the τ ≥ 1/√b; 1 for the rest."""
        unit = float(np.max(bbar[self.inner]))
        columns = np.ones(self.nv)
        columns[np.concatenate([self.ib, self.im, self.iB])] = unit
        columns[self.iw.ravel()] = np.sqrt(unit)
        columns[self.it.ravel()] = 1.0 / np.sqrt(unit)
        if self.tq is not None and self.damped:
            columns[self.iwt] = np.sqrt(unit)
        return columns

    def timing(
        self,
        x: NDArray[np.float64],
        history: tuple[float, ...],
        solvers: tuple[TimingMethod, ...] = (),
        timed_out: bool = False,
    ) -> JerkTiming:
        b = np.maximum(x[self.ib], 0.0)
        b[0] = b[-1] = 0.0
        m = x[self.im].copy()
        m[[0, -1]] = np.nan
        return JerkTiming(self.s, b, m, history, solvers, timed_out)


class SmoothTrajectory(Motion):
    """A path followed with a C¹ timing (:class:`JerkTiming`): θ̈ continuous, θ⃛ bounded.

    Parameters
    ----------
    path
        The spatial path θ(s).
    timing
        Its timing b(s).
    inverse_dynamics
        u(θ, θ̇, θ̈) for arrays of shape (M, n) (e.g. ``Robot.inverse_dynamics_batch``).
    """

    def __init__(self, path: Path, timing: JerkTiming, inverse_dynamics: InverseDynamics) -> None:
        self.path, self.timing = path, timing
        self.s = timing.s
        self.t = np.concatenate([[0.0], np.cumsum(timing.segment_times())])
        self.t.setflags(write=False)
        self._inverse_dynamics = inverse_dynamics

    @property
    def dof(self) -> int:
        """Number of joints n."""
        return self.path.dof

    def path_parameter(self, t: ArrayLike) -> NDArray[np.float64]:
        """s(t) at the given times (clipped to [0, t_e]), shape (M,): in closed form on the end
        segments, by safeguarded Newton steps on t(s) inside (to ~1e-14 of a segment)."""
        t = np.clip(np.atleast_1d(np.asarray(t, dtype=float)), 0.0, self.duration)
        timing, last = self.timing, self.s.size - 2
        k = np.clip(np.searchsorted(self.t, t, side="right") - 1, 0, last)
        d = self.s[k + 1] - self.s[k]
        tau = t - self.t[k]
        span = self.t[k + 1] - self.t[k]
        lo, hi = np.zeros_like(t), np.ones_like(t)
        x = np.clip(tau / span, 0.0, 1.0)
        for _ in range(60):
            s = self.s[k] + x * d
            f = timing.time_at(s) - self.t[k] - tau  # increasing in x
            lo, hi = np.where(f < 0, x, lo), np.where(f >= 0, x, hi)
            speed = np.sqrt(np.maximum(timing.evaluate(s)[0], 0.0))
            with np.errstate(divide="ignore", invalid="ignore"):
                step = x - f * speed / d
            bad = ~np.isfinite(step) | (step <= lo) | (step >= hi)
            new = np.where(bad, 0.5 * (lo + hi), step)
            if np.max(np.abs(new - x)) <= 1e-14:
                x = new
                break
            x = new
        beta0, beta1 = timing.b[1], timing.b[last]
        first = 3.0 * d / np.sqrt(beta0)
        x = np.where(k == 0, np.clip(tau / first, 0.0, 1.0) ** 3, x)
        rest = np.clip((span - tau) / (3.0 * d / np.sqrt(beta1)), 0.0, 1.0)
        x = np.where(k == last, 1.0 - rest**3, x)
        return np.minimum(self.s[k] + x * d, self.s[-1])

    def time_at(self, s: ArrayLike) -> NDArray[np.float64]:
        """t(s): when the motion reaches the path parameters s [s], shape (M,)."""
        s = np.clip(np.atleast_1d(np.asarray(s, dtype=float)), 0.0, self.s[-1])
        return self.timing.time_at(s)

    def states(self, t: ArrayLike) -> tuple[NDArray[np.float64], ...]:
        """θ(t), θ̇(t), θ̈(t) in one pass, each of shape (M, n). On the end segments b and a
        come from the time to rest ρ in closed form (b = β ρ⁴, a = ±⅔ β ρ/Δ, ρ = √β τ/(3Δ)):
        within ~1e-5 s of the end, s_e − s ∝ ρ³ falls below s's rounding."""
        t = np.clip(np.atleast_1d(np.asarray(t, dtype=float)), 0.0, self.duration)
        s = self.path_parameter(t)
        b, a, _ = self.timing.evaluate(s)
        d, beta, last = np.diff(self.s), self.timing.b, self.s.size - 2
        for segment, tau, sign, k in ((0, t, 1.0, 1), (last, self.duration - t, -1.0, last)):
            rho = np.clip(tau * np.sqrt(beta[k]) / (3.0 * d[segment]), 0.0, 1.0)
            on = tau <= self.t[1] - self.t[0] if segment == 0 else t >= self.t[-2]
            b = np.where(on, beta[k] * rho**4, b)
            a = np.where(on, sign * (2 / 3) * beta[k] * rho / d[segment], a)
        d1 = self.path(s, 1)
        return (
            self.path(s, 0),
            d1 * np.sqrt(b)[:, None],
            self.path(s, 2) * b[:, None] + d1 * a[:, None],
        )

    def jerk(self, t: ArrayLike) -> NDArray[np.float64]:
        """θ⃛(t) = √b (θ‴ b + 3θ″ a + θ′ a′) [rad/s³ or m/s³], shape (M, n); 0 before and after
        the motion (at rest)."""
        t = np.atleast_1d(np.asarray(t, dtype=float)).ravel()
        outside = (t < 0.0) | (t > self.duration)
        s = self.path_parameter(t)
        # at rest √b → 0 and a′ → ∞ with a finite product: its limit from just inside
        ends = 1e-9 * np.diff(self.s)[[0, -1]]
        s = np.clip(s, self.s[0] + ends[0], self.s[-1] - ends[1])
        return np.where(outside[:, None], 0.0, self.timing.rates(self.path, s)[2])


@dataclass(frozen=True)
class JerkTimingResult(MotionCost):
    """A path's jerk-limited timing as a plan returns it (the counterpart of
    :class:`~nearopt.timing.TimingResult`).

    Attributes
    ----------
    trajectory
        The motion (:class:`SmoothTrajectory`).
    cost
        The running cost f0 that was minimised.
    timing
        The timing b(s).
    wall_time
        Time spent [s].
    """

    trajectory: SmoothTrajectory
    cost: Cost
    timing: JerkTiming
    wall_time: float


def time_with_jerk_limits(
    robot: Robot,
    path: Path,
    cost: Cost,
    *,
    grid: int = 200,
    velocity_limits: bool = True,
    time_limit: float = np.inf,
) -> JerkTimingResult:
    """The robot's jerk limits (:attr:`~nearopt.robot.JointLimits.jerk`) held on ``path``: its
    :func:`jerk_limited_timing` for ``cost`` under the robot's other limits (its speed limits
    only with ``velocity_limits``; ``time_limit`` [s] as there), as a motion."""
    start = time.perf_counter()
    limited = robot if velocity_limits else robot.with_limits(velocity=np.inf)
    # (limits far below a path's own scale overflow on the way: the timing is checked to be
    # finite at the end, a SolverError otherwise, so numpy's warnings would say it twice)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        timing = jerk_limited_timing(
            limited, path, robot.limits.jerk, cost, grid=grid, time_limit=time_limit
        )
    motion = SmoothTrajectory(path, timing, robot.inverse_dynamics_batch)
    return JerkTimingResult(motion, cost, timing, time.perf_counter() - start)
