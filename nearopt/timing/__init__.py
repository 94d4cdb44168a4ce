"""Stage 1 (MCTP, Section 4): the optimal timing of a given path θ(s).

For a path θ(s), find λ(s) = ds/dt ≥ 0 that minimises J = ∫ f0 dt = ∫ f0/λ ds (eq. 11) under the
torque limits u_min ≤ u ≤ u_max (eq. 2) and, optionally, the joint speed limits |θ̇_i| ≤ v_i and
acceleration limits |θ̈_i| ≤ a_i, at rest at both ends (λ(0) = λ(s_e) = 0, eq. 3).

Notation: σ = s / s_e ∈ [0, 1]; b = λ² = (dσ/dt)²; a = ½ db/dσ = σ̈ the path acceleration.

Representation. The paper writes λ(s) as a cubic B-spline with λ(0) = 0 (eqs. 12-15); then λ grows
linearly in s at the ends and t = ∫ ds/λ diverges, so the "J" it reports depends on the quadrature.
nearopt uses b piecewise linear on a grid σ_0 < … < σ_N (constant path acceleration a on each
segment; Verscheure et al., "Time-optimal path tracking for robots: a convex optimization
approach", IEEE TAC 2009). Then λ ∝ √σ at rest, segment times are exact,
Δt_k = 2Δσ_k / (λ_k + λ_{k+1}), and eq. (10) is linear in (a, b) but for the damping:

    u = m(σ)·a + c(σ)·b + d(σ)·λ + g(σ),   m = Hθ', c = Hθ'' + h(θ, θ'), d = Dθ', g = g(θ),

and so is the joint acceleration θ̈ = θ'·a + θ''·b (modules: ``problem`` builds the grid and
samples the path, ``discretisation`` builds every constraint row once, ``conic`` and ``solvers``
solve, ``between`` keeps the limits between samples, ``driver`` returns a motion).

The discretised problem (variables b_1 … b_{N−1}; b_0 = b_N = 0):

    minimise   Σ_k Δt_k · ½ [f0(sample k⁺) + f0(sample (k+1)⁻)]
    subject to u and θ̈ within their limits at both ends of every segment (k⁺ and (k+1)⁻, with
               that segment's a), and b θ'_i(σ)² ≤ v_i² at the knots and inside segments.

For f0 = 1 + Σ w_i u_i² (time, the paper's eq. 32, per-joint weights) and D = 0 this is convex:
u is affine in b and u²/(√b_k + √b_{k+1}) is convex, so its global optimum is found:

1. Feasibility is decided exactly: some timing exists iff gravity alone is within the limits
   along the path (b → 0 gives u → g), checked at the knots and at the points between them that
   :func:`optimal_timing` checks; otherwise :class:`InfeasiblePathError` says where.
2. Every row and every segment's share of J couple only the two knots of a segment, so the
   problem is banded: nearopt's own primal-dual interior-point method
   (:func:`~nearopt.timing.interior.solve_interior`) solves it with a tridiagonal Newton system,
   O(N) per iteration, about 20–40 iterations from 10 to 100 000 segments, the damping torque
   d√b kept exactly (a local optimum with damping: the problem is then not convex). Clarabel's
   second-order cone program (:func:`solve_conic`, f0 = 1 included) is the independent reference
   (``solve_timing(…, method=TimingMethod.SOCP)``) and the fallback where the kernel reports a
   failure (the message says so); there the damping torque is re-linearised to a fixed point.
3. Any other f0 (:class:`~nearopt.CallableCost`) goes to SciPy's ``trust-constr`` interior-point
   method from 0.7 times the time-optimal profile (strictly inside the limits), with the exact
   gradient and the (tridiagonal) Hessian from differences of that gradient: a local optimum;
   it takes the torque limits as nonlinear constraints when the arm is damped.

:func:`optimal_timing` then checks the torques, accelerations and joint speeds between the samples
(inside the segments and next to the rest ends); where they leave a limit, it either slows the
whole motion down uniformly (b → αb) when that costs less than 1e-5 of b, or tightens the
offending segments and solves again.
"""

from .between import BetweenSamples, tighten, uniform_slow_down
from .conic import ConicSolution, is_solved, solve_conic
from .discretisation import Discretisation, LinearRows, RowBlocks
from .driver import TimingResult, optimal_timing
from .duration import (
    AS_FAST,
    DURATION_TOLERANCE,
    as_fast_as,
    check_duration,
    duration_gradient,
    duration_of,
    solve_for_duration,
)
from .interior import InteriorSolution, load_kernel, solve_interior
from .jerk import (
    JerkTiming,
    JerkTimingResult,
    SmoothTrajectory,
    jerk_limited_timing,
    time_with_jerk_limits,
)
from .joint import JointSolution, solve_joint
from .problem import (
    MAX_GRID,
    SPEED_SAFETY,
    TORQUE_SAFETY,
    InteriorSamples,
    InteriorSpeed,
    PathQuantity,
    TimingProblem,
    acceleration_coefficients,
    build_timing_problem,
    check_gravity,
    grid_knots,
    safe_limits,
    with_moving_ends,
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
    "InteriorSamples",
    "InteriorSpeed",
    "TimingProblem",
    "TimingSolution",
    "TimingStatus",
    "TimingMethod",
    "TimingResult",
    "Discretisation",
    "LinearRows",
    "RowBlocks",
    "InteriorSolution",
    "solve_interior",
    "JerkTiming",
    "JerkTimingResult",
    "SmoothTrajectory",
    "jerk_limited_timing",
    "time_with_jerk_limits",
    "JointSolution",
    "solve_joint",
    "load_kernel",
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
    "AS_FAST",
    "DURATION_TOLERANCE",
    "as_fast_as",
    "check_duration",
    "duration_of",
    "duration_gradient",
    "solve_for_duration",
    "with_moving_ends",
    "into_limits",
    "largest_scale",
    "uniform_slow_down",
    "tighten",
]
