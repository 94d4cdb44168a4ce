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

from .between import BetweenSamples, tighten, uniform_slow_down
from .conic import ConicSolution, is_solved, solve_conic
from .discretisation import Discretisation, LinearRows, RowBlocks
from .driver import TimingResult, optimal_timing
from .problem import (
    MAX_GRID,
    SPEED_SAFETY,
    TORQUE_SAFETY,
    InteriorSpeed,
    PathQuantity,
    TimingProblem,
    acceleration_coefficients,
    build_timing_problem,
    check_gravity,
    grid_knots,
    safe_limits,
)
from .solvers import (
    TimingMethod,
    TimingSolution,
    TimingStatus,
    into_limits,
    largest_scale,
    solve_timing,
)

__all__ = [
    "MAX_GRID",
    "SPEED_SAFETY",
    "TORQUE_SAFETY",
    "PathQuantity",
    "InteriorSpeed",
    "TimingProblem",
    "TimingSolution",
    "TimingStatus",
    "TimingMethod",
    "TimingResult",
    "Discretisation",
    "LinearRows",
    "RowBlocks",
    "ConicSolution",
    "solve_conic",
    "is_solved",
    "BetweenSamples",
    "safe_limits",
    "acceleration_coefficients",
    "build_timing_problem",
    "check_gravity",
    "grid_knots",
    "solve_timing",
    "optimal_timing",
    "into_limits",
    "largest_scale",
    "uniform_slow_down",
    "tighten",
]
