"""Stage 1's own kernel: a primal-dual interior-point method whose Newton system is tridiagonal.

The discretised problem of :mod:`nearopt.timing` for f0 = 1 + Σ w_i u_i², over the free knots
z = b_1 … b_{N−1} (b_0 = b_N = 0):

    minimise   F(b) = Σ_k Δt_k (1 + Q_k),   Δt_k = 2Δσ_k / (λ_k + λ_{k+1}),  λ = √b,
               Q_k = ½ Σ_i w_i (u_{k⁺,i}² + u_{(k+1)⁻,i}²)
    subject to every row of :class:`~nearopt.timing.Discretisation` (torque, acceleration, speed
               inside segments; the knots' speed rows and ``b_upper`` as bounds on z), b > 0.

Every row and every segment's share of F touch only the two knots of one segment (the rows'
*pair form*: ``coef_left · b_k + coef_right · b_{k+1} + d·√b_node + offset``), so the Hessian of
the Lagrangian and Jᵀ (Y/S) J are tridiagonal, and one Newton step costs O(N + rows): a Cholesky
factorisation of a tridiagonal matrix (``scipy.linalg.cholesky_banded``) and two solves with it.

The method (Mehrotra's predictor-corrector, as in Nocedal & Wright, *Numerical Optimization*,
§14.2 and §19.3):

* every two-sided row is split into two one-sided rows c_j(b) ≤ 0, each divided by its largest
  finite limit (so that limits from 1e-6 to 1e300 give rows of the same size: a row whose limit
  never binds weighs nothing at the optimum), with slack s_j > 0 and multiplier y_j > 0;
* rows that another row at the same sample implies are left out first (the same problem, 3–6
  times fewer rows on 6- and 7-joint arms): at a sample every row bounds the segment's path
  acceleration from above or below by a function of the knot's b, and where one such bound lies
  below another on the whole range of b that the sample allows (up to its maximum velocity
  curve, which is then kept as a bound of its own) the other is implied;
* the start is strictly feasible: b⁰ = ½ α_max w along a shape w (under the largest constant b
  each segment allows and the largest ramps b ∝ σ from the rest ends, or the b of a close path),
  with α_max the largest scale that keeps every row (the damping's √b term included) within its
  limits, found in closed form row by row; the variables are then scaled by b⁰ and F by 1/F(b⁰),
  so that every variable and the objective start at 1;
* one step length for the primal and the dual variables (the objective is not linear), at most
  1, 0.995 of the way to the boundary of a slack or multiplier, and such that no b more than
  halves in one step (1/√b is far from its tangent below that);
* the damping torque d√b (a concave or convex term) is kept exactly: its second derivative enters
  the Hessian of the Lagrangian (on the diagonal), and the step is regularised where the
  Newton matrix is not positive definite (the problem is then not convex; a local optimum);
* it stops when the duality measure Σ s_j y_j, the scaled gradient of the Lagrangian and the
  rows' residuals are below the tolerance, all relative to F (so the discretised cost is
  within about ``tolerance`` of its optimum, relatively).

The Newton iterations are compiled by numba (:mod:`nearopt.timing._kernels`, cached beside the
source: a process's first solve loads them, about 1 s, or compiles them once, about 15 s), and
run in chunks between which the deadline is checked.

Without damping the problem is convex (u²/(λ_k + λ_{k+1}) is, with u affine in b), and this is
its global optimum — the same one Clarabel's SOCP (:mod:`nearopt.timing.conic`) finds.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from .discretisation import Discretisation

__all__ = ["InteriorSolution", "solve_interior", "load_kernel"]

STEP_TO_BOUNDARY = 0.995  # the fraction of the way to a slack's (or a multiplier's) boundary
CHUNK = 8  # Newton iterations between two looks at the clock


class InteriorSolution(NamedTuple):
    """The kernel's answer.

    Attributes
    ----------
    z
        b at the free knots, shape (N−1,).
    converged
        Whether the stopping test passed within the iteration limit.
    iterations
        Newton iterations (two solves each).
    message
        What happened, in words.
    timed_out
        Whether it stopped at the deadline.
    rows
        The number of one-sided rows it held (after leaving out the implied ones).
    """

    z: NDArray[np.float64]
    converged: bool
    iterations: int
    message: str
    timed_out: bool = False
    rows: int = 0


class _Rows(NamedTuple):
    """One-sided rows c(b) = (sign · row(b) − bound) / scale ≤ 0 in pair form, on all knots."""

    left: NDArray[np.int64]
    coef_left: NDArray[np.float64]
    coef_right: NDArray[np.float64]
    sqrt_coef: NDArray[np.float64]
    sqrt_node: NDArray[np.int64]
    const: NDArray[np.float64]  # (sign · offset − bound) / scale

    def values(self, b: NDArray[np.float64], lam: NDArray[np.float64]) -> NDArray[np.float64]:
        return (
            self.coef_left * b[self.left]
            + self.coef_right * b[self.left + 1]
            + self.sqrt_coef * lam[self.sqrt_node]
            + self.const
        )


def _one_sided(
    disc: Discretisation,
) -> tuple[_Rows, NDArray[np.float64], NDArray[np.int64]]:
    """The solver rows of ``disc`` and the bounds on z as one-sided rows, the upper bounds of z
    (inf where none), and the sample of every row (−1 for a row not at a sample)."""
    index = disc.solver_index
    lower, upper = disc.lower[index], disc.upper[index]
    scale = np.maximum(
        np.where(np.isfinite(lower), np.abs(lower), 0.0),
        np.where(np.isfinite(upper), np.abs(upper), 0.0),
    )
    scale = np.where(scale > 0.0, scale, 1.0)
    at_sample = index < disc.blocks.acceleration.stop  # torque and acceleration rows
    sample = np.where(at_sample, disc.location[index], -1)
    parts = []
    for sign, bound in ((1.0, upper), (-1.0, lower)):
        keep = np.isfinite(bound)
        k = index[keep]
        factor = sign / scale[keep]
        parts.append(
            (
                disc.left[k],
                factor * disc.coef_left[k],
                factor * disc.coef_right[k],
                factor * disc.sqrt_coef[k],
                disc.sqrt_node[k],
                factor * disc.offset[k] - sign * bound[keep] / scale[keep],
                sample[keep],
            )
        )
    cap = disc.z_cap
    finite = np.flatnonzero(np.isfinite(cap))
    one = np.ones(finite.size)
    parts.append(
        (
            finite + 1,
            1.0 / cap[finite],
            0.0 * one,
            0.0 * one,
            finite + 1,
            -one,
            np.full(finite.size, -1),
        )
    )
    rows = _Rows(*(np.concatenate([part[k] for part in parts]) for k in range(6)))
    return rows, cap, np.concatenate([part[6] for part in parts])


def _without_implied(
    disc: Discretisation, rows: _Rows, cap: NDArray[np.float64], sample: NDArray[np.int64]
) -> _Rows:
    """``rows`` less those that another row at the same sample implies, plus each sample's bound
    on b (its maximum velocity curve, which the rows left out may have helped to set)."""
    from ._kernels import redundant_rows

    grouped = np.flatnonzero(sample >= 0)
    if grouped.size == 0:
        return rows
    order = grouped[np.argsort(sample[grouped], kind="stable")]
    starts = np.concatenate([[0], np.flatnonzero(np.diff(sample[order])) + 1, [order.size]])
    node = disc.node[sample]
    cap_b = disc.problem.with_ends(cap)
    drop, b_max = redundant_rows(
        order,
        starts,
        rows.left,
        rows.coef_left,
        rows.coef_right,
        rows.sqrt_coef,
        np.ascontiguousarray(node, dtype=np.int64),
        rows.const,
        disc.ds,
        cap_b,
    )
    keep = ~drop
    knot = node[order[starts[:-1]]]
    big_n = disc.problem.segments
    bounded = np.isfinite(b_max) & (knot > 0) & (knot < big_n) & (b_max > 0.0)
    bounded &= b_max < cap_b[knot]  # no need for a bound the knot already has
    knot, b_max = knot[bounded], b_max[bounded]
    one = np.ones(knot.size)
    extra = (knot, 1.0 / b_max, 0.0 * one, 0.0 * one, knot, -one)
    return _Rows(
        *(np.concatenate([field[keep], add]) for field, add in zip(rows, extra, strict=True))
    )


def _start_scale(rows: _Rows, shape_b: NDArray[np.float64]) -> float:
    """The largest α with every row ≤ 0 along b = α' · shape for all α' ∈ [0, α) (inf if none
    binds). Row j along the ray is A t² + B t + C with t = √α; C < 0 at b = 0."""
    lam = np.sqrt(shape_b)
    a = rows.coef_left * shape_b[rows.left] + rows.coef_right * shape_b[rows.left + 1]
    bb = rows.sqrt_coef * lam[rows.sqrt_node]
    c = rows.const
    if np.any(c >= 0.0):
        return 0.0
    disc = bb * bb - 4.0 * a * c
    with np.errstate(divide="ignore", invalid="ignore"):
        root = np.sqrt(np.maximum(disc, 0.0))
        q = -0.5 * (bb + np.where(bb >= 0.0, root, -root))
        t1, t2 = q / a, c / q
    big = np.inf
    t1 = np.where(np.isfinite(t1) & (t1 > 0.0) & (disc >= 0.0), t1, big)
    t2 = np.where(np.isfinite(t2) & (t2 > 0.0) & (disc >= 0.0), t2, big)
    linear = (a == 0.0) & (bb > 0.0)  # B t + C = 0
    with np.errstate(divide="ignore"):
        t_lin = np.where(linear, -c / np.where(linear, bb, 1.0), big)
    t = np.minimum(np.where(a == 0.0, t_lin, np.minimum(t1, t2)), big)
    return float(np.min(t)) ** 2 if t.size else np.inf


def solve_interior(
    disc: Discretisation,
    weights: NDArray[np.float64],
    *,
    tolerance: float = 1e-10,
    max_iterations: int = 300,
    deadline: float = np.inf,
    guess: NDArray[np.float64] | None = None,
    reduce: bool = True,
    price: NDArray[np.float64] | None = None,
) -> InteriorSolution:
    """Minimise F of this module's docstring over b.

    Parameters
    ----------
    disc
        The rows (see :class:`~nearopt.timing.Discretisation`).
    weights
        w_i of the cost, shape (n,) [1/(N·m)²] (all 0: time-optimal).
    tolerance
        Relative accuracy of F at the answer (duality measure and residuals relative to F).
    max_iterations
        Newton iterations before giving up (``converged`` False).
    deadline
        ``time.perf_counter()`` value at which to stop (``timed_out``).
    guess
        b at the knots of a close path, shape (N+1,): the shape of the start.
    reduce
        Leave out the rows that other rows at their sample imply (the same problem, fewer rows;
        at rest at both ends only).
    price
        A linear term Σ_k price_k b_k added to F, shape (N+1,) (the ends' entries unused), or
        None (see :mod:`nearopt.timing.duration`: durations beyond every optimum of F).
    """
    problem = disc.problem
    big_n = problem.segments
    sigma = problem.sigma
    ds = disc.ds
    rows, cap, sample = _one_sided(disc)
    if reduce and problem.at_rest:
        # (with moving ends the reduced rows made the method cycle near some optima: seen on
        # panda with a set duration, converging in 21 iterations with every row kept)
        rows = _without_implied(disc, rows, cap, sample)
    free = np.arange(1, big_n)

    e_rows = _energy_rows(disc, weights)

    # ------------------------------------------------------------------ the start
    alpha, shape = _start(rows, cap, sigma, guess)
    if not np.isfinite(alpha):
        return InteriorSolution(
            np.zeros(big_n - 1),
            False,
            0,
            "no limit bounds this path's speed: the time-optimal motion is instantaneous",
        )
    if alpha <= 0.0:
        return InteriorSolution(np.zeros(big_n - 1), False, 0, "no strictly feasible start")
    z = 0.5 * alpha * shape
    scale = z.copy()  # the variables' scale: x = z / scale starts at 1
    # positivity rows −b_k ≤ 0, scaled by the start
    rows = _Rows(
        np.concatenate([rows.left, free]),
        np.concatenate([rows.coef_left, -1.0 / scale]),
        np.concatenate([rows.coef_right, np.zeros(big_n - 1)]),
        np.concatenate([rows.sqrt_coef, np.zeros(big_n - 1)]),
        np.concatenate([rows.sqrt_node, free]),
        np.concatenate([rows.const, np.zeros(big_n - 1)]),
    )
    m = rows.left.size
    b_start = problem.with_ends(z)
    s = -rows.values(b_start, np.sqrt(b_start))
    if problem.at_rest and np.any(s <= 0.0):
        return InteriorSolution(z, False, 0, "the start is not strictly feasible")
    if not problem.at_rest:
        # moving ends: the start need not hold every row (those of the end segments, say); the
        # method is an infeasible-start one in the rows (residual c + s → 0), so those start
        # with a slack of the order of the others'
        s = np.where(s > 1e-3, s, 0.1)
    price = np.zeros(big_n + 1) if price is None else np.asarray(price, dtype=float)
    f_scale = 1.0 / (disc.torque_cost(z, weights) + float(price[1:-1] @ z))
    y = (1.0 / m) / s  # centred, with a duality gap of the order of F (scaled to 1)
    args = (
        *_kernel_rows(rows),
        *_kernel_rows(e_rows[:6]),
        e_rows[6],
        ds,
        np.array(problem.b_ends, dtype=float),
        np.ascontiguousarray(price),
        scale,
        f_scale,
        tolerance,
    )
    iterate = _compiled()
    done = 0
    while done < max_iterations:
        if time.perf_counter() >= deadline:
            return InteriorSolution(z, False, done, "time limit", timed_out=True, rows=m)
        chunk = min(CHUNK, max_iterations - done)
        status, taken, _ = iterate(z, s, y, *args, chunk, STEP_TO_BOUNDARY)
        done += int(taken)
        if status == 1:
            return InteriorSolution(z, True, done, f"converged in {done} iterations", rows=m)
        if status == 2:
            return InteriorSolution(z, False, done, "the Newton matrix is singular", rows=m)
        if status == 3:
            return InteriorSolution(z, False, done, "the iterate is not finite", rows=m)
    return InteriorSolution(
        z, False, done, f"no convergence in {max_iterations} iterations", rows=m
    )


def _energy_rows(disc: Discretisation, weights: NDArray[np.float64]) -> tuple:
    """The torque samples of the energy term Σ w_i u_i² (joint-major as in Discretisation) in
    pair form, with their weights; empty when no weight is positive (time-optimal)."""
    t_rows = np.arange(disc.blocks.torque.start, disc.blocks.torque.stop)
    t_w = weights[disc.joint[t_rows]]
    t_rows, t_w = t_rows[t_w > 0.0], t_w[t_w > 0.0]
    return (
        disc.left[t_rows],
        disc.coef_left[t_rows],
        disc.coef_right[t_rows],
        disc.sqrt_coef[t_rows],
        disc.sqrt_node[t_rows],
        disc.offset[t_rows],
        t_w,
    )


def _kernel_rows(rows: tuple) -> tuple:
    """Pair-form rows (left, coef_left, coef_right, sqrt_coef, sqrt_node, const) as the kernel
    takes them (contiguous, the knots as int64)."""
    left, cl, cr, sd, sn, const = rows
    return (
        np.ascontiguousarray(left, dtype=np.int64),
        np.ascontiguousarray(cl, dtype=float),
        np.ascontiguousarray(cr, dtype=float),
        np.ascontiguousarray(sd, dtype=float),
        np.ascontiguousarray(sn, dtype=np.int64),
        np.ascontiguousarray(const, dtype=float),
    )


def _start(
    rows: _Rows,
    cap: NDArray[np.float64],
    sigma: NDArray[np.float64],
    guess: NDArray[np.float64] | None,
) -> tuple[float, NDArray[np.float64]]:
    """The start's shape at the free knots (the guess', else :func:`_shape`, under the caps) and
    the largest scale α of it the rows allow (the start is half of that)."""
    if guess is not None and np.all(np.isfinite(guess)) and np.max(guess[1:-1]) > 0.0:
        shape = np.asarray(guess, dtype=float)[1:-1].copy()
        shape = np.maximum(shape, 1e-3 * np.minimum(sigma[1:-1], 1.0 - sigma[1:-1]) * shape.max())
    else:
        shape = _shape(rows, sigma)
    shape = np.minimum(shape, np.where(np.isfinite(cap), cap, np.inf))
    return _start_scale(rows, np.concatenate([[0.0], shape, [0.0]])), shape


def load_kernel() -> None:
    """Load the compiled kernels into this process now (compiling them if no cached copy fits),
    by solving a small problem: about 1 s when cached, 10–20 s the first time on a machine
    (stage 2's joint solver's loops and the jerk-limited timing's banded kernel too).

    The first stage-1 solve of a process does this by itself; call it before forking children
    that should not touch the file system (or cannot read the package's folder after dropping
    privileges), so that they share the loaded machine code.
    """
    from ..robot import PathCoefficients
    from .discretisation import Discretisation
    from .problem import (
        InteriorSamples,
        PathQuantity,
        TimingProblem,
        acceleration_coefficients,
        interior_points,
    )

    sigma = np.linspace(0.0, 1.0, 5)  # a damped rotor with a speed limit, timed for energy
    ones = np.ones((5, 1))
    coef = PathCoefficients(ones, 0.0 * ones, 0.1 * ones, 0.0 * ones)
    segment, weight, at = interior_points(sigma)  # and its rows between the samples
    inner = np.ones((at.size, 1))
    inside = InteriorSamples(
        4,
        segment,
        weight,
        at,
        at[:, None],
        inner,
        PathCoefficients(inner, 0.0 * inner, 0.1 * inner, 0.0 * inner),
        acceleration_coefficients(inner, 0.0 * inner),
    )
    problem = TimingProblem(
        sigma=sigma,
        theta=sigma[:, None],
        dtheta=ones,
        ddtheta=0.0 * ones,
        torque=PathQuantity(coef, np.array([-1.0]), np.array([1.0])),
        velocity=np.array([1.0]),
        joint_names=("rotor",),
        interior=inside,
    )
    solve_interior(Discretisation(problem), np.array([0.1]))
    _load_joint_kernels()
    _load_banded_kernels()


def _load_banded_kernels() -> None:
    """The jerk-limited timing's compiled loops (:mod:`nearopt.timing.banded`): min 1/√z over
    two variables under z ≤ 1, one row implied by another."""
    from ._banded_kernels import implied_rows
    from .banded import BandedProgram, solve_banded

    one, two = np.ones(1), np.ones((1, 2))
    solve_banded(
        BandedProgram(
            np.zeros(2, dtype=np.int64), np.eye(2), np.zeros(2), np.zeros((2, 2)), np.ones(2),
            np.zeros(1, dtype=np.int64), two, one, one, np.zeros((1, 0, 2)), np.zeros((1, 0)),
            np.zeros(0), np.zeros(2),
        ),
        np.full(2, 0.5),
    )  # fmt: skip
    implied_rows(np.arange(2), np.array([0, 2]), np.eye(2), np.ones(2))


def _load_joint_kernels() -> None:
    """Stage 2's compiled loops (:mod:`nearopt.timing.joint`), on a one-joint example with an
    energy term: two segments, one further variable and one row over both."""
    import scipy.sparse as sp

    from .discretisation import LinearRows
    from .joint import solve_joint

    torque = (
        sp.csr_matrix(np.array([[1.0, 0.1], [0.5, 0.0], [1.0, -0.1], [0.5, 0.0]])),
        np.zeros(4),
    )
    solve_joint(
        np.array([0.5, 0.5]),
        np.array([0.1]),
        LinearRows(sp.csr_matrix(np.array([[1.0, 1.0]])), np.array([-np.inf]), np.array([5.0])),
        torque,
        np.array([np.inf]),
        p_bounds=(np.array([-1.0]), np.array([1.0])),
        torque_limits=(np.full(4, -10.0), np.full(4, 10.0)),
        start=np.array([1.0]),
    )


def _compiled():  # noqa: ANN202 - numba's dispatcher
    """The compiled Newton loop (numba is imported, and the loop loaded or compiled, on first
    use)."""
    from ._kernels import iterate

    return iterate


def _shape(rows: _Rows, sigma: NDArray[np.float64]) -> NDArray[np.float64]:
    """A shape for the start at the free knots: under the largest constant b each segment's rows
    allow (a = 0 there), and under the largest ramps b ∝ σ and b ∝ 1 − σ from the rest ends."""
    big_n = sigma.size - 1
    ramp_up = _start_scale(rows, sigma.copy()) * sigma
    ramp_down = _start_scale(rows, 1.0 - sigma) * (1.0 - sigma)
    # b_k = b_{k+1} = β on a segment: row (coef_left + coef_right) β + d √β + const ≤ 0
    a = rows.coef_left + rows.coef_right
    bb, c = rows.sqrt_coef, rows.const
    disc = bb * bb - 4.0 * a * c
    with np.errstate(divide="ignore", invalid="ignore"):
        root = np.sqrt(np.maximum(disc, 0.0))
        q = -0.5 * (bb + np.where(bb >= 0.0, root, -root))
        t = np.where(
            a != 0.0, np.where(q / a > 0.0, q / a, c / q), np.where(bb > 0, -c / bb, np.inf)
        )
    t = np.where(np.isfinite(t) & (t > 0.0) & (disc >= 0.0), t, np.inf)
    level = np.full(big_n, np.inf)
    np.minimum.at(level, np.minimum(rows.left, big_n - 1), t * t)
    knot = np.minimum(np.concatenate([[np.inf], level]), np.concatenate([level, [np.inf]]))
    return np.minimum(np.minimum(ramp_up, ramp_down), knot)[1:-1]
