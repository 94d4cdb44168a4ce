"""Stage 1 (MCTP, Section 4): the optimal timing of a given path θ(s).

For a path θ(s), find λ(s) = ds/dt ≥ 0 that minimises J = ∫ f0 dt = ∫ f0/λ ds (eq. 11) under the
torque limits u_min ≤ u ≤ u_max (eq. 2) and, optionally, the joint speed limits |θ̇_i| ≤ v_i, at rest
at both ends (λ(0) = λ(s_e) = 0, eq. 3).

Representation. The paper writes λ(s) as a cubic B-spline with λ(0) = 0 (eqs. 12-15); then λ grows
linearly in s at the ends and t = ∫ ds/λ diverges, so the "J" it reports depends on the quadrature.
nearopt uses b = λ² instead, piecewise linear on a grid s_0 < … < s_N (constant path acceleration
a = ½ db/ds on each segment; Verscheure et al., "Time-optimal path tracking for robots: a convex
optimization approach", IEEE TAC 2009). Then λ ∝ √s at rest, segment times are exact,
Δt_k = 2Δs_k / (λ_k + λ_{k+1}), and eq. (10) is linear in (a, b) but for the damping:

    u = m(s)·a + c(s)·b + d(s)·λ + g(s),   m = Hθ', c = Hθ'' + h(θ, θ'), d = Dθ', g = g(θ).

The discretised problem (variables b_1 … b_{N−1}; b_0 = b_N = 0):

    minimise   Σ_k Δt_k · ½ [f0(sample k⁺) + f0(sample (k+1)⁻)]
    subject to u_min ≤ u ≤ u_max at both ends of every segment (k⁺ and (k+1)⁻, with that
               segment's a), and b_k θ'_i(s_k)² ≤ v_i² (joint speed limits).

For f0 = 1 + Σ w_i u_i² (time, the paper's eq. 32, per-joint weights) and D = 0 this is convex:
u is affine in b and u²/(√b_k + √b_{k+1}) is convex, so its global optimum is found:

1. Feasibility is decided exactly: some timing exists iff gravity alone is within the limits
   along the path (b → 0 gives u → g), checked at the knots and at the points between them that
   :func:`optimal_timing` checks; otherwise :class:`InfeasiblePathError` says where.
2. Without damping, the problem is a second-order cone program (see :func:`_socp`; f0 = 1
   included), solved by Clarabel.
3. With damping, HiGHS (``scipy.optimize.linprog``) first maximises Σ b_k: the greatest feasible
   speed profile, which is the time-optimal timing when the feasible set is a lattice (as for
   pairwise constraints); for f0 = 1 a second LP checks the KKT conditions at that profile (a
   certificate of optimality), and otherwise the SOCP starts from it.
4. Any other f0 (:class:`~nearopt.CallableCost`) goes to SciPy's ``trust-constr`` interior-point
   method from 0.7 times the greatest profile (strictly inside the limits), with the exact
   gradient and the (tridiagonal) Hessian from differences of that gradient: a local optimum.

Damping makes u depend on λ = √b. It is handled, not dropped: the LPs and the SOCP linearise √b at
the previous profile until a fixed point (where the linearisation is exact), and ``trust-constr``
takes the torque limits as nonlinear constraints. The problem is then not convex in general (local
optimum).

:func:`optimal_timing` then checks the torques and joint speeds between the samples (inside the
segments and next to the rest ends); where they leave a limit, it either slows the whole motion
down uniformly (b → αb) when that costs less than 1e-5 of b, or tightens the offending segments
and solves again.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
import scipy.sparse as sp
from scipy.optimize import Bounds, LinearConstraint, NonlinearConstraint, linprog, minimize

from .cost import Cost, TimeCost, TorqueCost
from .errors import ConfigurationError, InfeasiblePathError, SolverError
from .robot import PathCoefficients
from .trajectory import Trajectory, segment_times

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from .path import Path
    from .robot import Robot

MAX_GRID = 100_000  # segments; stage 1's memory grows linearly beyond any use

__all__ = [
    "TimingProblem",
    "TimingSolution",
    "TimingResult",
    "build_timing_problem",
    "solve_timing",
    "optimal_timing",
]


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


@dataclass(frozen=True)
class TimingSolution:
    """The kernel's answer: b = λ² at the knots and how it was found.

    Attributes
    ----------
    b
        λ² at the knots, shape (N+1,), b_0 = b_N = 0.
    objective
        The discretised cost at b.
    status
        ``"optimal"`` (KKT conditions met to tolerance) or ``"iteration_limit"``.
    solver
        The method that produced b (``"clarabel-socp"``, ``"highs-lp"`` or ``"trust-constr"``).
    iterations
        Iterations of that method.
    message
        The solver's own words.
    """

    b: NDArray[np.float64]
    objective: float
    status: str
    solver: str
    iterations: int
    message: str


@dataclass(frozen=True)
class TimingResult:
    """The optimal timing of a path: a trajectory and its cost.

    Attributes
    ----------
    trajectory
        θ(t), θ̇(t), θ̈(t), u(t) for t ∈ [0, duration].
    J
        ∫ f0 dt of the returned motion [s·(unit of f0)], by Gauss-Legendre quadrature per segment.
    duration
        t_e [s].
    objective
        The discretised cost the solver minimised (differs from J by the discretisation, O(Δs²)).
    status, solver, iterations, message
        As in :class:`TimingSolution`.
    wall_time
        Time spent [s], building the problem included.
    """

    trajectory: Trajectory
    J: float
    duration: float
    objective: float
    status: str
    solver: str
    iterations: int
    message: str
    wall_time: float


# ----------------------------------------------------------------------------- building
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
    sigma = _grid(grid)
    s = sigma * path.s_end
    theta = path(s, 0)
    dtheta = path(s, 1) * path.s_end  # d/dσ = s_e d/ds
    ddtheta = path(s, 2) * path.s_end**2
    coef = robot.path_coefficients(theta, dtheta, ddtheta)
    b_upper = np.full(s.size, np.inf)
    interior = None
    v = robot.limits.velocity
    if velocity_limits and np.any(np.isfinite(v)):
        b_upper = _speed_bound(dtheta, v)
        # three points inside every segment, where |θ'| of a curved path may peak
        segment = np.repeat(np.arange(grid), 3)
        weight = np.tile([0.25, 0.5, 0.75], grid)
        at = sigma[segment] + weight * np.diff(sigma)[segment]
        d_at = path(at * path.s_end, 1) * path.s_end
        bound = _speed_bound(d_at, v)
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


def _speed_bound(dtheta: NDArray[np.float64], velocity: NDArray[np.float64]) -> NDArray[np.float64]:
    """min_i v_i² / θ'_i² per row (inf where no joint moves or no limit is finite)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(dtheta != 0, velocity**2 / dtheta**2, np.inf)
    return np.min(np.where(np.isnan(ratio), np.inf, ratio), axis=1)


# ----------------------------------------------------------------------------- the kernel
class _Discretisation:
    """Torque samples and the cost as functions of the free variables z = b_1 … b_{N−1}."""

    def __init__(self, problem: TimingProblem) -> None:
        p = problem
        big_n, n = p.segments, p.dof
        ds = np.diff(p.s)
        # sample r: node[r], segment seg[r]; r < N: start of segment r, r ≥ N: end of segment r − N
        self.node = np.concatenate([np.arange(big_n), np.arange(1, big_n + 1)])
        self.seg = np.concatenate([np.arange(big_n), np.arange(big_n)])
        self.ds = ds
        self.problem = p
        rows = np.arange(2 * big_n)
        blocks = []
        for i in range(n):
            m, c = p.coef.m[self.node, i], p.coef.c[self.node, i]
            slope = m / (2.0 * ds[self.seg])
            blocks.append(
                sp.coo_matrix(
                    (
                        np.concatenate([-slope, slope, c]),
                        (np.tile(rows, 3), np.concatenate([self.seg, self.seg + 1, self.node])),
                    ),
                    shape=(2 * big_n, big_n + 1),
                )
            )
        # rows joint-major (i·2N + r); columns: the free knots 1 … N−1
        self.k_full = sp.vstack(blocks).tocsr()
        self.k = self.k_full[:, 1:-1].tocsc()
        self.u0 = p.coef.g[self.node].T.ravel()
        self.damp = p.coef.d[self.node].T.ravel()
        self.has_damping = bool(np.any(self.damp != 0.0))
        self.lower = np.repeat(p.u_lower, 2 * big_n)
        self.upper = np.repeat(p.u_upper, 2 * big_n)
        # interior speed limits as rows S z ≤ bound (S ≥ 0)
        speed = p.interior_speed
        count = 0 if speed is None else speed.bound.size
        cols = np.concatenate([speed.segment, speed.segment + 1]) if count else np.zeros(0, int)
        vals = np.concatenate([1.0 - speed.weight, speed.weight]) if count else np.zeros(0)
        self.speed = sp.csr_matrix(
            (vals, (np.tile(np.arange(count), 2), cols)), shape=(count, big_n + 1)
        )[:, 1:-1].tocsr()
        self.speed_bound = speed.bound if count else np.zeros(0)
        if p.margin is not None:
            self.lower = self.lower + p.margin.T.ravel()
            self.upper = self.upper - p.margin.T.ravel()

    def b(self, z: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.concatenate([[0.0], z, [0.0]])

    def torque(self, z: NDArray[np.float64]) -> NDArray[np.float64]:
        """All torque samples, joint-major, shape (n·2N,)."""
        u = self.k @ z + self.u0
        if self.has_damping:
            u += self.damp * np.tile(np.sqrt(self.b(z))[self.node], self.problem.dof)
        return u

    def torque_jacobian(self, z: NDArray[np.float64]) -> sp.csc_matrix:
        if not self.has_damping:
            return self.k
        return (self.k + sp.diags(self.damp) @ self._sqrt_b_jacobian(z)).tocsc()

    def _sqrt_b_jacobian(self, z: NDArray[np.float64]) -> sp.csr_matrix:
        """∂√b(node[r]) / ∂z for every sample row (tiled over joints)."""
        big_n = self.problem.segments
        col = self.node - 1
        free = (col >= 0) & (col < big_n - 1)
        vals = np.zeros(self.node.size)
        vals[free] = 0.5 / np.sqrt(z[col[free]])
        j = sp.coo_matrix(
            (vals[free], (np.arange(self.node.size)[free], col[free])),
            shape=(self.node.size, big_n - 1),
        )
        return sp.vstack([j] * self.problem.dof).tocsr()

    def segment_times(self, z: NDArray[np.float64]) -> NDArray[np.float64]:
        return segment_times(self.problem.s, self.b(z))

    def objective(self, z: NDArray[np.float64], cost: Cost) -> tuple[float, NDArray[np.float64]]:
        """The discretised J and its gradient with respect to z."""
        p = self.problem
        n, big_n = p.dof, p.segments
        b = self.b(z)
        lam = np.sqrt(b)
        dt = segment_times(p.s, b)
        u = self.torque(z).reshape(n, 2 * big_n).T
        q = p.theta[self.node]
        qd = p.dtheta[self.node] * lam[self.node, None]
        f = cost(q, qd, u)
        _, df_dqd, df_du = cost.gradients(q, qd, u)
        fbar = 0.5 * (f[:big_n] + f[big_n:])
        value = float(np.sum(dt * fbar))
        # ∂/∂b of every knot (b_0 and b_N are dropped at the end)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv2lam = np.where(lam > 0, 0.5 / lam, 0.0)
        ddt = -dt / (lam[:-1] + lam[1:])  # ∂Δt_k/∂λ, the same for both ends
        grad = np.zeros(b.size)
        np.add.at(grad, np.arange(big_n), ddt * inv2lam[:-1] * fbar)
        np.add.at(grad, np.arange(1, big_n + 1), ddt * inv2lam[1:] * fbar)
        weight = 0.5 * dt[self.seg]  # each sample's share of its segment's time
        du = weight[:, None] * df_du  # ∂J/∂u at every sample, (2N, n)
        grad += np.asarray(self.k_full.T @ du.T.ravel()).ravel()
        # through λ = √b of the sample's knot: θ̇ = λθ' and the damping torque dλ
        node_term = weight * np.sum(df_dqd * p.dtheta[self.node], axis=1) + np.sum(
            du * p.coef.d[self.node], axis=1
        )
        np.add.at(grad, self.node, node_term * inv2lam[self.node])
        return value, grad[1:-1]


def _tridiagonal_hessian(
    grad: callable, x: NDArray[np.float64], g0: NDArray[np.float64]
) -> sp.csr_matrix:
    """Hessian of a chain-structured function from three forward differences of its gradient."""
    p = x.size
    h = 1e-7 * np.maximum(np.abs(x), 1e-3)
    rows, cols, vals = [], [], []
    idx = np.arange(p)
    for colour in range(3):
        e = np.where(idx % 3 == colour, h, 0.0)
        dg = grad(x + e) - g0
        j = idx + ((colour - idx + 1) % 3) - 1  # the column of this colour next to row i
        ok = (j >= 0) & (j < p)
        rows.append(idx[ok])
        cols.append(j[ok])
        vals.append(dg[ok] / h[j[ok]])
    hess = sp.coo_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(p, p)
    ).tocsr()
    return 0.5 * (hess + hess.T)


def _check_gravity(
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


def _lp(
    disc: _Discretisation, c: NDArray[np.float64], z_lin: NDArray[np.float64] | None = None
) -> tuple[NDArray[np.float64], float]:
    """minimise c·z over the torque polytope with HiGHS.

    The damping torque d·√b is linearised at ``z_lin`` (tangent, exact at z_lin), or left out
    when ``z_lin`` is None (to find a first profile to linearise at).
    """
    k, u0 = disc.k, disc.u0
    if disc.has_damping and z_lin is not None:
        jac = disc.torque_jacobian(z_lin)
        u0 = disc.torque(z_lin) - jac @ z_lin
        k = jac
    ub = disc.problem.b_upper[1:-1]
    res = linprog(
        c,
        A_ub=sp.vstack([k, -k, disc.speed]).tocsr(),
        b_ub=np.concatenate([disc.upper - u0, u0 - disc.lower, disc.speed_bound]),
        bounds=np.column_stack([np.zeros(ub.size), np.where(np.isfinite(ub), ub, np.nan)]),
        method="highs",
    )
    if res.status != 0:
        raise SolverError(f"HiGHS failed on the stage-1 LP: {res.message}", status=res.status)
    return np.maximum(res.x, 0.0), float(res.fun)


def _relinearise(
    disc: _Discretisation,
    solve: Callable[[NDArray[np.float64]], NDArray[np.float64]],
    z: NDArray[np.float64],
    *,
    tolerance: float,
    max_rounds: int,
) -> tuple[NDArray[np.float64], int]:
    """Re-solve with the damping linearised at the last answer until it stops moving.

    At the fixed point the tangent of √b is taken where it touches, so the constraints hold exactly.
    Returns the answer and the number of solves, the first (given as ``z``) included.
    """
    rounds = 1
    while disc.has_damping and rounds < max_rounds:
        z_new = solve(np.maximum(z, 1e-12 * max(z.max(), 1e-12)))
        rounds += 1
        change = np.max(np.abs(z_new - z)) / max(z_new.max(), 1e-300)
        z = z_new
        if change < tolerance:
            break
    return z, rounds


def _greatest_profile(disc: _Discretisation) -> tuple[NDArray[np.float64], int]:
    """The greatest feasible b (maximise Σ b), damping linearised to a fixed point."""
    weights = -np.ones(disc.problem.segments - 1)
    z, _ = _lp(disc, weights)
    return _relinearise(
        disc, lambda z_lin: _lp(disc, weights, z_lin)[0], z, tolerance=1e-10, max_rounds=51
    )


def _largest_scale(excess: Callable[[float], float]) -> float:
    """The largest α ∈ [0, 1] with excess(α) ≤ 0 (1 if feasible as it is), to 1e-9.

    Without damping the torque is u(αb) = g + α(u(b) − g), a convex combination of gravity and a
    torque within the limits, so every α below a feasible one is feasible too. excess is nearly
    linear in α, so false position (Illinois variant) brackets the root in a few evaluations;
    the feasible end of the bracket is returned.
    """
    e_hi = excess(1.0)
    if e_hi <= 0.0:
        return 1.0
    lo, hi, e_lo, side = 0.0, 1.0, excess(0.0), 0
    if e_lo > 0.0:
        return 0.0
    for _ in range(60):
        if hi - lo < 1e-9:
            break
        mid = (lo * e_hi - hi * e_lo) / (e_hi - e_lo)
        if not lo < mid < hi:
            mid = 0.5 * (lo + hi)
        e_mid = excess(mid)
        if e_mid <= 0.0:
            lo, e_lo = mid, e_mid
            e_hi, side = (0.5 * e_hi, side) if side == -1 else (e_hi, -1)
        else:
            hi, e_hi = mid, e_mid
            e_lo, side = (0.5 * e_lo, side) if side == 1 else (e_lo, 1)
    return lo


def _into_limits(disc: _Discretisation, z: NDArray[np.float64]) -> NDArray[np.float64]:
    """Scale b by the largest α ≤ 1 that puts every torque sample within the limits."""
    z = np.minimum(z, disc.problem.b_upper[1:-1])
    if disc.speed_bound.size:  # the interior speed rows S z ≤ bound, S ≥ 0
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = disc.speed_bound / (disc.speed @ z)
        z = z * min(1.0, float(np.nanmin(np.where(ratio > 0, ratio, np.inf))))

    def excess(alpha: float) -> float:
        u = disc.torque(alpha * z)
        return float(max(np.max(u - disc.upper), np.max(disc.lower - u)))

    return _largest_scale(excess) * z


def _socp(
    disc: _Discretisation,
    weights: NDArray[np.float64],
    z_lin: NDArray[np.float64] | None,
    tolerance: float,
) -> tuple[NDArray[np.float64], object]:
    """The convex problem for f0 = 1 + Σ w_i u_i² as a second-order cone program, with Clarabel.

    Variables x = (b_1…b_{N−1}, c_1…c_{N−1}, t_0…t_{N−1}, e_0…e_{N−1}) with c_k ≤ √b_k (tight at
    the optimum), y_k = c_k + c_{k+1} (c_0 = c_N = 0):

        minimise Σ t_k + e_k   s.t.  c_k² ≤ b_k,  t_k y_k ≥ 2Δσ_k,
                                     e_k y_k ≥ Δσ_k Σ_i w_i (u_{k⁺,i}² + u_{(k+1)⁻,i}²),
                                     u_min ≤ u ≤ u_max,  0 ≤ b ≤ b_upper,

    i.e. Σ Δt_k (1 + ½ Σ w (u_{k⁺}² + u_{(k+1)⁻}²)). Rotated cones x·y ≥ ‖v‖² are written as
    ‖(2v, x − y)‖ ≤ x + y. The damping torque is linearised at ``z_lin``.
    """
    import clarabel

    p = disc.problem
    big_n, n = p.segments, p.dof
    nz = big_n - 1
    iz, ic, it, ie = 0, nz, 2 * nz, 2 * nz + big_n
    nx = 2 * nz + 2 * big_n
    k_mat, u0 = disc.k, disc.u0
    if disc.has_damping and z_lin is not None:
        k_mat = disc.torque_jacobian(z_lin)
        u0 = disc.torque(z_lin) - k_mat @ z_lin
    ub = p.b_upper[1:-1]
    finite = np.flatnonzero(np.isfinite(ub))
    energy = bool(np.any(weights > 0))
    ds = disc.ds
    seg = np.arange(big_n)
    trip_r: list[NDArray[np.int64]] = []
    trip_c: list[NDArray[np.int64]] = []
    trip_v: list[NDArray[np.float64]] = []
    rhs: list[NDArray[np.float64]] = []
    row0 = 0

    def put(r: NDArray, c: NDArray, v: NDArray) -> None:
        trip_r.append(np.asarray(r, dtype=np.int64) + row0)
        trip_c.append(np.asarray(c, dtype=np.int64))
        trip_v.append(np.asarray(v, dtype=float))

    # 1. torque limits, b ≥ 0, b ≤ b_upper, interior speed limits: A x + s = rhs, s ≥ 0
    kk = k_mat.tocoo()
    m_rows = k_mat.shape[0]
    put(kk.row, kk.col + iz, kk.data)
    put(kk.row + m_rows, kk.col + iz, -kk.data)
    put(2 * m_rows + np.arange(nz), iz + np.arange(nz), -np.ones(nz))
    put(2 * m_rows + nz + np.arange(finite.size), iz + finite, np.ones(finite.size))
    ss = disc.speed.tocoo()
    put(2 * m_rows + nz + finite.size + ss.row, iz + ss.col, ss.data)
    rhs += [disc.upper - u0, u0 - disc.lower, np.zeros(nz), ub[finite], disc.speed_bound]
    n_lin = 2 * m_rows + nz + finite.size + ss.shape[0]
    cones: list[object] = [clarabel.NonnegativeConeT(n_lin)]
    row0 += n_lin

    # 2. c_k² ≤ b_k ⇔ ‖(2c_k, b_k − 1)‖ ≤ b_k + 1, knots 1 … N−1
    kn = np.arange(nz)
    put(3 * kn, iz + kn, -np.ones(nz))
    put(3 * kn + 1, ic + kn, -2.0 * np.ones(nz))
    put(3 * kn + 2, iz + kn, -np.ones(nz))
    rhs.append(np.tile([1.0, 0.0, -1.0], nz))
    cones += [clarabel.SecondOrderConeT(3)] * nz
    row0 += 3 * nz

    # y_k = c_k + c_{k+1} (c_0 = c_N = 0): the c columns of segment k
    y_seg = np.concatenate([seg[seg >= 1], seg[seg <= big_n - 2]])
    y_col = np.concatenate([seg[seg >= 1] - 1, seg[seg <= big_n - 2]]) + ic

    def cone_xy(width: int, var: int) -> None:
        """Rows 0 and last of per-segment cones ‖(…, x − y)‖ ≤ x + y with x = var_k."""
        put(width * seg, var + seg, -np.ones(big_n))
        put(width * y_seg, y_col, -np.ones(y_seg.size))
        put(width * seg + width - 1, var + seg, -np.ones(big_n))
        put(width * y_seg + width - 1, y_col, np.ones(y_seg.size))

    # 3. t_k y_k ≥ 2Δσ_k ⇔ ‖(2√(2Δσ_k), t_k − y_k)‖ ≤ t_k + y_k
    cone_xy(3, it)
    rhs.append(np.column_stack([np.zeros(big_n), 2.0 * np.sqrt(2.0 * ds), np.zeros(big_n)]).ravel())
    cones += [clarabel.SecondOrderConeT(3)] * big_n
    row0 += 3 * big_n

    # 4. e_k y_k ≥ Δσ_k Σ w (u_{k+}² + u_{(k+1)-}²) ⇔ ‖(2v, e_k − y_k)‖ ≤ e_k + y_k, v = √(Δσ w) u
    q_vec = np.zeros(nx)
    q_vec[it : it + big_n] = 1.0
    if energy:
        width = 2 + 2 * n
        cone_xy(width, ie)
        joint, r = np.divmod(kk.row, 2 * big_n)
        k_of = np.where(r < big_n, r, r - big_n)
        slot = np.where(r < big_n, joint, n + joint)
        scale = 2.0 * np.sqrt(ds[k_of] * weights[joint])
        put(width * k_of + 1 + slot, kk.col + iz, -scale * kk.data)
        e_rhs = np.zeros((big_n, width))
        all_rows = np.arange(m_rows)
        joint_all, r_all = np.divmod(all_rows, 2 * big_n)
        k_all = np.where(r_all < big_n, r_all, r_all - big_n)
        slot_all = np.where(r_all < big_n, joint_all, n + joint_all)
        e_rhs[k_all, 1 + slot_all] = 2.0 * np.sqrt(ds[k_all] * weights[joint_all]) * u0
        rhs.append(e_rhs.ravel())
        cones += [clarabel.SecondOrderConeT(width)] * big_n
        row0 += width * big_n
        q_vec[ie : ie + big_n] = 1.0
    else:  # no energy: pin e = 0
        put(np.arange(big_n), ie + seg, np.ones(big_n))
        rhs.append(np.zeros(big_n))
        cones.append(clarabel.ZeroConeT(big_n))
        row0 += big_n
    a_all = sp.csc_matrix(
        (np.concatenate(trip_v), (np.concatenate(trip_r), np.concatenate(trip_c))), shape=(row0, nx)
    )
    b_all = np.concatenate(rhs)
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.tol_gap_abs = settings.tol_gap_rel = settings.tol_feas = tolerance
    settings.max_iter = 200
    solver = clarabel.DefaultSolver(sp.csc_matrix((nx, nx)), q_vec, a_all, b_all, cones, settings)
    sol = solver.solve()
    return np.maximum(np.asarray(sol.x)[iz : iz + nz], 0.0), sol


def solve_timing(
    problem: TimingProblem,
    cost: Cost,
    *,
    tolerance: float = 1e-9,
    max_iterations: int = 1000,
) -> TimingSolution:
    """Solve stage 1 on a grid (the kernel: arrays in, b out).

    Parameters
    ----------
    problem
        The sampled path, its coefficients and the limits (see :func:`build_timing_problem`).
    cost
        The running cost f0.
    tolerance
        Optimality tolerance of the NLP (gradient, step and barrier tolerances).
    max_iterations
        Iteration limit of the NLP.

    Raises
    ------
    InfeasiblePathError
        If gravity alone exceeds a torque limit somewhere on the path.
    SolverError
        If HiGHS fails (it should not on a feasible problem).
    """
    _check_gravity(problem)
    disc = _Discretisation(problem)
    weights = cost.torque_weights(problem.dof) if isinstance(cost, TorqueCost) else None
    if weights is not None and not disc.has_damping:
        return _solve_convex(disc, cost, weights, None, tolerance)  # no linearisation point needed
    z_max, rounds = _greatest_profile(disc)
    z_max = _into_limits(disc, z_max)
    if np.any(z_max <= 0):
        raise SolverError("stage 1 found no positive speed profile although gravity is feasible")
    if weights is not None and not np.any(weights):
        # f0 = 1: certify the greatest profile by the KKT conditions of min Σ Δt (an LP in the
        # descent direction: no feasible z decreases the linearised time).
        _, grad = disc.objective(z_max, TimeCost())
        _, best = _lp(disc, grad, z_max)
        here = float(grad @ z_max)
        if here - best <= 1e-9 * abs(here):
            return TimingSolution(
                b=disc.b(z_max),
                objective=float(np.sum(disc.segment_times(z_max))),
                status="optimal",
                solver="highs-lp",
                iterations=rounds + 1,
                message="greatest feasible speed profile; KKT conditions certified by an LP",
            )
    if weights is not None:
        return _solve_convex(disc, cost, weights, z_max, tolerance)
    return _solve_nlp(disc, cost, z_max, tolerance, max_iterations)


def _solve_convex(
    disc: _Discretisation,
    cost: Cost,
    weights: NDArray[np.float64],
    z_max: NDArray[np.float64] | None,
    tolerance: float,
) -> TimingSolution:
    """f0 = 1 + Σ w u²: the SOCP, repeated with the damping re-linearised until a fixed point.

    ``z_max`` (the greatest profile) is the first linearisation point; None without damping.
    """
    solutions = []

    def socp(z_lin: NDArray[np.float64]) -> NDArray[np.float64]:
        # Clarabel may stop short of a 1e-9 gap ("InsufficientProgress") on badly scaled paths:
        # then the same problem is solved to 10 and 100 times looser tolerances
        for tol in (tolerance, 10.0 * tolerance, 100.0 * tolerance):
            z_new, sol = _socp(disc, weights, z_lin, tol)
            if "Solved" in str(sol.status):
                break
        solutions.append(sol)
        return z_new

    z, rounds = _relinearise(disc, socp, socp(z_max), tolerance=1e-7, max_rounds=30)
    iterations = sum(int(sol.iterations) for sol in solutions)
    status = str(solutions[-1].status)
    if "Solved" not in status:
        raise SolverError(f"Clarabel did not solve the stage-1 SOCP: {status}", status=status)
    z = _into_limits(disc, z)
    return TimingSolution(
        b=disc.b(z),
        objective=disc.objective(z, cost)[0],
        status="optimal",
        solver="clarabel-socp",
        iterations=iterations,
        message=f"{status} in {rounds} round(s)"
        + (" (damping linearised)" if disc.has_damping else ""),
    )


def _solve_nlp(
    disc: _Discretisation,
    cost: Cost,
    z_max: NDArray[np.float64],
    tolerance: float,
    max_iterations: int,
) -> TimingSolution:
    """Any f0: SciPy's trust-constr interior-point method (a local optimum), from 0.7 b_max."""
    problem = disc.problem
    # scale the cost to O(1) at the start and every torque row by its limit range
    x0 = 0.7 * z_max  # strictly inside: u(0.7 b) = g + 0.7 (u(b) − g)
    j_scale = 1.0 / disc.objective(x0, cost)[0]
    row = 2.0 / (disc.upper - disc.lower)
    ub = disc.problem.b_upper[1:-1]
    lb = np.full(ub.size, 1e-10)

    def fun(x: NDArray[np.float64]) -> tuple[float, NDArray[np.float64]]:
        value, grad = disc.objective(x, cost)
        return value * j_scale, grad * j_scale

    def hess(x: NDArray[np.float64]) -> sp.csr_matrix:
        return _tridiagonal_hessian(lambda y: fun(y)[1], x, fun(x)[1])

    if disc.has_damping:

        def c_hess(x: NDArray[np.float64], v: NDArray[np.float64]) -> sp.csr_matrix:
            # ∂²(d·√b)/∂b² = −d / (4 b^{3/2}) on the sample's own knot
            b = disc.b(x)
            col = np.tile(disc.node, problem.dof)
            w = v * row * disc.damp * -0.25 * np.where(b[col] > 0, b[col], np.inf) ** -1.5
            return sp.diags(np.bincount(col, weights=w, minlength=b.size)[1:-1])

        constraint = NonlinearConstraint(
            lambda x: row * disc.torque(x),
            row * disc.lower,
            row * disc.upper,
            jac=lambda x: sp.diags(row) @ disc.torque_jacobian(x),
            hess=c_hess,
        )
    else:
        constraint = LinearConstraint(
            sp.diags(row) @ disc.k, row * (disc.lower - disc.u0), row * (disc.upper - disc.u0)
        )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # trust-constr warns about its own heuristics
        res = minimize(
            fun,
            x0,
            jac=True,
            hess=hess,
            method="trust-constr",
            bounds=Bounds(lb, ub),
            constraints=[constraint]
            + (
                [LinearConstraint(disc.speed, -np.inf, disc.speed_bound)]
                if disc.speed.shape[0]
                else []
            ),
            options={
                "gtol": tolerance,
                "xtol": tolerance,
                "barrier_tol": tolerance,
                "maxiter": max_iterations,
                "initial_barrier_parameter": 1e-4,
            },
        )
    if not np.all(np.isfinite(res.x)):
        raise SolverError(f"trust-constr returned a non-finite timing: {res.message}")
    z = _into_limits(disc, np.maximum(res.x, lb))
    return TimingSolution(
        b=disc.b(z),
        objective=disc.objective(z, cost)[0],
        status="optimal" if res.status in (1, 2) else "iteration_limit",
        solver="trust-constr",
        iterations=int(res.nit),
        message=str(res.message),
    )


class _Between:
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
        _check_gravity(problem, self.coef.g[order], self.sigma[order], self.theta[order])

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
        return _largest_scale(lambda alpha: float(np.max(self.excess(b, alpha)))) * b

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

def _uniform_slow_down(
    between: _Between, b: NDArray[np.float64], velocity: NDArray[np.float64] | None
) -> NDArray[np.float64]:
    """αb with the largest α ≤ 1 that keeps torques (and speeds) within the limits everywhere."""
    b = between.scale_into_limits(b)
    return b if velocity is None else b * between.speed_scale(b, velocity)


def _tighten(
    problem: TimingProblem,
    between: _Between,
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


def optimal_timing(
    robot: Robot,
    path: Path,
    cost: Cost | None = None,
    *,
    grid: int = 200,
    velocity_limits: bool = True,
    tolerance: float = 1e-9,
) -> TimingResult:
    """Stage 1: the timing λ(s) of a path that minimises J = ∫ f0 dt under the robot's limits.

    Parameters
    ----------
    robot
        The arm; its effort limits (and, if ``velocity_limits``, speed limits) are enforced.
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

    Returns
    -------
    TimingResult
        The trajectory, J (integrated over the returned motion) and the solver's report.

    Raises
    ------
    InfeasiblePathError
        If gravity alone exceeds a torque limit somewhere on the path (names joint, s, θ, excess).
    """
    t0 = time.perf_counter()
    cost = TimeCost() if cost is None else cost
    problem = build_timing_problem(robot, path, grid=grid, velocity_limits=velocity_limits)
    sol = solve_timing(problem, cost, tolerance=tolerance)  # gravity checked at the knots
    between = _Between(robot, path, problem)  # and between them
    velocity = robot.limits.velocity if velocity_limits else None
    for _ in range(4):
        # where the motion leaves a limit between samples: a uniform slow-down by α if that
        # costs less than 1e-5 of b (below the grid's own error), otherwise tighten and re-solve
        b = _uniform_slow_down(between, sol.b, velocity)
        if np.all(b >= (1.0 - 1e-5) * sol.b):
            break
        tighter = _tighten(problem, between, sol.b, velocity)
        if tighter is None:
            break
        problem = tighter
        sol = solve_timing(problem, cost, tolerance=tolerance)
    else:
        b = _uniform_slow_down(between, sol.b, velocity)
    # back from σ = s / s_e to the path's own s: b_s = s_e² b_σ
    traj = Trajectory(path, problem.s * path.s_end, b * path.s_end**2, robot.inverse_dynamics_batch)
    return TimingResult(
        trajectory=traj,
        J=traj.integrate(cost),
        duration=traj.duration,
        objective=sol.objective,
        status=sol.status,
        solver=sol.solver,
        iterations=sol.iterations,
        message=sol.message,
        wall_time=time.perf_counter() - t0,
    )


def _grid(segments: int) -> NDArray[np.float64]:
    """Knots σ_k = ½(1 − cos(πk/N)) (Chebyshev-Lobatto), O(1/N²) apart at the rest ends.

    At rest b ∝ σ, so λ = √b varies fastest next to σ = 0 and 1: there the trapezoidal weights of
    a segment's two torque samples are least accurate (the time spent in the first segment lies
    mostly near its start). Clustering the knots there makes the discretised J converge much
    faster than on a uniform grid (measured on the paper's example: 0.02 % instead of 0.3 % at
    N = 200 on a curved path).
    """
    return 0.5 * (1.0 - np.cos(np.pi * np.arange(segments + 1) / segments))
