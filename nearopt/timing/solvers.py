"""The solver back ends of stage 1: nearopt's banded interior-point kernel, Clarabel's SOCP and
SciPy's trust-constr.

:func:`solve_timing` chooses among them by the cost (see :mod:`nearopt.timing`): the built-in costs
go to the kernel (:mod:`nearopt.timing.interior`), and to Clarabel only if the kernel reports a
failure (the answer says so); every back end reads the same rows, those of
:class:`~nearopt.timing.Discretisation`.
"""

from __future__ import annotations

import dataclasses
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
from scipy.optimize import Bounds, LinearConstraint, NonlinearConstraint, minimize

from ..cost import Cost, TimeCost, TorqueCost
from ..errors import ConfigurationError, InfeasiblePathError, SolverError
from .conic import is_solved, solve_conic
from .discretisation import Discretisation
from .interior import solve_interior
from .problem import check_gravity

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from .problem import TimingProblem

__all__ = [
    "TimingStatus",
    "TimingMethod",
    "TimingSolution",
    "solve_timing",
    "largest_scale",
    "into_limits",
]


class TimingStatus(StrEnum):
    """How stage 1's solver stopped."""

    OPTIMAL = "optimal"
    """The optimality conditions hold to the tolerance (for the built-in costs: the global optimum
    of the discretised problem)."""
    ITERATION_LIMIT = "iteration limit"
    """The NLP of a user's cost stopped at its iteration limit (a feasible timing)."""


class TimingMethod(StrEnum):
    """The back end that produced a timing."""

    INTERIOR = "nearopt interior point"
    SOCP = "Clarabel SOCP"
    NLP = "SciPy trust-constr"


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
        How the solver stopped.
    solver
        The back end that produced b.
    iterations
        Iterations of that back end.
    message
        The solver's own words.
    slowed
        1 − α of the uniform scaling αb that put the back end's answer within every row (0: it
        held them as it was; Clarabel's answers leave rows by its feasibility tolerance, which
        on rows with large, nearly cancelling coefficients is 1e-7 of a limit and more).
    """

    b: NDArray[np.float64]
    objective: float
    status: TimingStatus
    solver: TimingMethod
    iterations: int
    message: str
    slowed: float = 0.0


def solve_timing(
    problem: TimingProblem,
    cost: Cost,
    *,
    tolerance: float = 1e-9,
    max_iterations: int = 1000,
    time_limit: float = np.inf,
    guess: NDArray[np.float64] | None = None,
    method: TimingMethod | None = None,
    max_duration: float | None = None,
    price: NDArray[np.float64] | None = None,
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
    time_limit
        Wall-time budget of the whole solve [s]: checked before and during every conic solve
        and at every NLP iteration.
    guess
        A timing b near the answer, shape (N+1,) (e.g. the last one of a path close to this
        one): the shape of the interior-point
        kernel's start (and, for Clarabel, where the damping is first linearised; without it,
        Clarabel's first solve leaves the damping out).
    method
        The back end of the built-in costs (and of the convex start of any other cost):
        ``TimingMethod.INTERIOR`` or ``TimingMethod.SOCP`` (Clarabel, the independent
        reference); default: the interior-point kernel, and Clarabel where it reports a failure.
    max_duration
        t_e ≤ this [s] as a constraint of Clarabel's SOCP (``method=TimingMethod.SOCP`` only:
        the reference of :func:`~nearopt.timing.optimal_timing`'s ``max_duration``, which
        searches over the cost's weights with the kernel instead).
    price
        A linear term Σ_k price_k b_k added to J's discretisation, shape (N+1,) (the ends'
        entries unused), for a TimeCost or TorqueCost: how
        :mod:`nearopt.timing.duration` lengthens a motion beyond every optimum of J.

    Raises
    ------
    InfeasiblePathError
        If gravity alone exceeds a torque limit somewhere on the path.
    SolverError
        If Clarabel fails (it should not on a feasible problem), or the time limit runs out
        (``status`` is then ``"MaxTime"``).
    """
    deadline = time.perf_counter() + time_limit
    check_gravity(problem)
    disc = Discretisation.of(problem)
    if guess is not None:
        guess = np.asarray(guess, dtype=float)
        if guess.shape != problem.sigma.shape:
            guess = None
    if method not in (None, TimingMethod.INTERIOR, TimingMethod.SOCP):
        raise ConfigurationError(
            f"method must be a TimingMethod of a convex solver (INTERIOR or SOCP), got {method!r}"
        )
    if max_duration is not None and (
        method != TimingMethod.SOCP or not isinstance(cost, TorqueCost)
    ):
        raise ConfigurationError(
            "solve_timing takes max_duration with method=TimingMethod.SOCP and a TimeCost or "
            "TorqueCost (the reference); optimal_timing(…, max_duration=) solves it otherwise"
        )
    if price is not None and not isinstance(cost, TorqueCost):
        raise ConfigurationError("solve_timing takes a price with a TimeCost or TorqueCost only")
    if max_duration is not None:
        weights = cost.torque_weights(problem.dof)
        return _solve_convex(disc, cost, weights, tolerance, time_limit, None, max_duration)
    if isinstance(cost, TorqueCost):
        weights = cost.torque_weights(problem.dof)
        return _solve_builtin(
            disc, cost, weights, tolerance, deadline, guess, time_limit, method, price
        )
    # any other f0: a local NLP from inside the time-optimal profile
    fastest = _solve_builtin(
        disc, TimeCost(), np.zeros(problem.dof), tolerance, deadline, guess, time_limit, method
    )
    return _solve_nlp(disc, cost, fastest.b[1:-1], tolerance, max_iterations, deadline)


KERNEL_TOLERANCE = 1e-10  # the kernel's duality gap and residuals, relative to the cost


def _solve_builtin(
    disc: Discretisation,
    cost: Cost,
    weights: NDArray[np.float64],
    tolerance: float,
    deadline: float,
    guess: NDArray[np.float64] | None,
    time_limit: float,
    method: TimingMethod | None,
    price: NDArray[np.float64] | None = None,
) -> TimingSolution:
    """f0 = 1 + Σ w u²: the interior-point kernel, and Clarabel's SOCP where it fails (unless
    ``method`` is ``TimingMethod.INTERIOR``), or Clarabel's SOCP alone (``TimingMethod.SOCP``,
    see :func:`_solve_convex`)."""
    note = ""
    if method != TimingMethod.SOCP:
        sol = solve_interior(
            disc, weights, tolerance=KERNEL_TOLERANCE, deadline=deadline, guess=guess, price=price
        )
        if sol.timed_out:
            raise out_of_time(disc.problem, time_limit)
        if sol.converged:
            z, alpha = into_limits(disc, sol.z)
            return TimingSolution(
                b=disc.b(z),
                objective=disc.torque_cost(z, weights),
                slowed=1.0 - alpha,
                status=TimingStatus.OPTIMAL,
                solver=TimingMethod.INTERIOR,
                iterations=sol.iterations,
                message=sol.message + (" (damping exact)" if disc.has_damping else ""),
            )
        if method == TimingMethod.INTERIOR:
            raise SolverError(f"nearopt's interior-point kernel failed: {sol.message}")
        note = f"; nearopt's interior-point kernel failed first ({sol.message})"
    z_guess = None if guess is None or not disc.has_damping else guess[1:-1]
    try:
        reference = _solve_convex(
            disc, cost, weights, tolerance, deadline - time.perf_counter(), z_guess, price=price
        )
    except SolverError as exc:
        if exc.status == "MaxTime":
            raise out_of_time(disc.problem, time_limit) from None
        if not disc.problem.at_rest and "Infeasible" in str(exc.status):
            raise moving_ends_infeasible(disc) from None
        raise
    return dataclasses.replace(reference, message=reference.message + note)


def out_of_time(problem: TimingProblem, time_limit: float) -> SolverError:
    """The error of a stage-1 solve that ran out of its wall-time budget ``time_limit`` [s]."""
    return SolverError(
        f"stage 1 ran out of its time limit ({time_limit:.3g} s) on a grid of "
        f"{problem.segments} segments",
        status="MaxTime",
    )


def _solve_convex(
    disc: Discretisation,
    cost: Cost,
    weights: NDArray[np.float64],
    tolerance: float,
    time_limit: float = np.inf,
    z_guess: NDArray[np.float64] | None = None,
    max_duration: float | None = None,
    price: NDArray[np.float64] | None = None,
) -> TimingSolution:
    """f0 = 1 + Σ w u²: the SOCP, repeated with the damping re-linearised until a fixed point.

    The first solve takes the damping torque's tangent at ``z_guess`` or, without one, leaves it
    out; every further one takes its tangent at the previous answer, exact at the fixed point.
    """
    solutions = []
    torque_rows = disc.blocks.torque
    deadline = time.perf_counter() + time_limit
    infeasible = 0  # rounds in a row Clarabel found infeasible

    def socp(z_lin: NDArray[np.float64]) -> NDArray[np.float64]:
        nonlocal infeasible
        if time.perf_counter() >= deadline:  # building a large SOCP alone takes seconds
            raise out_of_time(disc.problem, time_limit)
        rows, z_upper = disc.solver_rows(z_lin)
        const = disc.upper[torque_rows] - rows.upper[torque_rows]  # the torque's constant part
        torque = (rows.matrix[torque_rows], const)
        # Clarabel may stop short of a 1e-9 gap ("InsufficientProgress") on badly scaled paths:
        # then the same problem is solved to 10 and 100 times looser tolerances
        for tol in (tolerance, 10.0 * tolerance, 100.0 * tolerance):
            sol = solve_conic(
                disc.ds,
                weights,
                rows,
                torque,
                z_upper,
                tolerance=tol,
                time_limit=deadline - time.perf_counter(),
                b_ends=disc.problem.b_ends,
                max_duration=max_duration,
                price=None if price is None else price[1:-1],
            )
            if str(sol.status) == "MaxTime":  # no use re-linearising an unfinished answer
                raise out_of_time(disc.problem, time_limit)
            if is_solved(sol.status) or "Infeasible" in str(sol.status):
                break  # (a certificate of infeasibility does not change with the tolerance)
        solutions.append(sol)
        infeasible = infeasible + 1 if "Infeasible" in str(sol.status) else 0
        if infeasible >= 1 + disc.has_damping:
            # the damping's tangent at an infeasible answer means nothing: once (twice with a
            # tangent, whose restriction may be what is infeasible) is enough — a moving end
            # xarm7 re-plan spent 21 s in 30 rounds × 3 tolerances of 'PrimalInfeasible'
            raise SolverError(
                f"Clarabel did not solve the stage-1 SOCP: {sol.status}", status=sol.status
            )
        return sol.z

    z, rounds = _relinearise(disc, socp, z_guess, tolerance=1e-7, max_rounds=30)
    iterations = sum(sol.iterations for sol in solutions)
    status = solutions[-1].status
    if not is_solved(status):
        raise SolverError(f"Clarabel did not solve the stage-1 SOCP: {status}", status=status)
    z, alpha = into_limits(disc, z)
    return TimingSolution(
        b=disc.b(z),
        objective=disc.objective(z, cost)[0],
        status=TimingStatus.OPTIMAL,
        solver=TimingMethod.SOCP,
        iterations=iterations,
        message=f"{status} in {rounds} round(s)"
        + (" (damping linearised)" if disc.has_damping else ""),
        slowed=1.0 - alpha,
    )


def _solve_nlp(
    disc: Discretisation,
    cost: Cost,
    z_max: NDArray[np.float64],
    tolerance: float,
    max_iterations: int,
    deadline: float = np.inf,
) -> TimingSolution:
    """Any f0: SciPy's trust-constr interior-point method (a local optimum), from 0.7 times the
    time-optimal profile ``z_max``, until the wall clock (``time.perf_counter``) reaches
    ``deadline``."""
    start = time.perf_counter()

    def watch(*_: object) -> None:
        if time.perf_counter() >= deadline:
            raise out_of_time(disc.problem, deadline - start)

    # scale the cost to O(1) at the start and every two-sided row by its range
    x0 = 0.7 * z_max  # strictly inside: u(0.7 b) = g + 0.7 (u(b) − g)
    j_scale = 1.0 / disc.objective(x0, cost)[0]
    span = disc.upper - disc.lower
    row = np.where(np.isfinite(span), 2.0 / np.where(np.isfinite(span), span, 1.0), 1.0)
    ub = disc.z_cap
    lb = np.full(ub.size, 1e-10)

    def fun(x: NDArray[np.float64]) -> tuple[float, NDArray[np.float64]]:
        value, grad = disc.objective(x, cost)
        return value * j_scale, grad * j_scale

    def hess(x: NDArray[np.float64]) -> sp.csr_matrix:
        return _tridiagonal_hessian(lambda y: fun(y)[1], x, fun(x)[1])

    if disc.has_damping:

        def c_hess(x: NDArray[np.float64], v: NDArray[np.float64]) -> sp.csr_matrix:
            # ∂²(d·√b)/∂b² = −d / (4 b^{3/2}) on the row's own knot
            b = disc.b(x)
            col = disc.sqrt_node
            w = v * row * disc.sqrt_coef * -0.25 * np.where(b[col] > 0, b[col], np.inf) ** -1.5
            return sp.diags(np.bincount(col, weights=w, minlength=b.size)[1:-1])

        constraint = NonlinearConstraint(
            lambda x: row * disc.values(x),
            row * disc.lower,
            row * disc.upper,
            jac=lambda x: sp.diags(row) @ disc.jacobian(x),
            hess=c_hess,
        )
    else:
        rows = disc.linear_rows(None)
        constraint = LinearConstraint(
            sp.diags(row) @ rows.matrix, row * rows.lower, row * rows.upper
        )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # trust-constr warns about its own heuristics
        res = minimize(
            fun,
            x0,
            jac=True,
            hess=hess,
            method="trust-constr",
            bounds=Bounds(lb, ub, keep_feasible=True),  # b < 0 has no √b
            constraints=[constraint],
            callback=watch,
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
    z, alpha = into_limits(disc, np.maximum(res.x, lb))
    return TimingSolution(
        b=disc.b(z),
        objective=disc.objective(z, cost)[0],
        status=TimingStatus.OPTIMAL if res.status in (1, 2) else TimingStatus.ITERATION_LIMIT,
        solver=TimingMethod.NLP,
        iterations=int(res.nit),
        message=str(res.message),
        slowed=1.0 - alpha,
    )


def _relinearise(
    disc: Discretisation,
    solve: Callable[[NDArray[np.float64] | None], NDArray[np.float64]],
    z_lin: NDArray[np.float64] | None,
    *,
    tolerance: float,
    max_rounds: int,
) -> tuple[NDArray[np.float64], int]:
    """Re-solve with the damping linearised at the last answer until it stops moving.

    At the fixed point the tangent of √b is taken where it touches, so the constraints hold exactly.
    It also stops when the answer already keeps every row with the exact damping torque to 1e-9
    of its range after a linearised solve: the tangent's error there is second-order in the last
    change, and :func:`into_limits` removes what is left of it. The first solve linearises at
    ``z_lin`` (None: without the damping torque). Returns the answer and the number of solves.
    """
    z, rounds = solve(z_lin), 1
    while disc.has_damping and rounds < max_rounds:
        if z_lin is not None:
            change = np.max(np.abs(z - z_lin)) / max(z.max(), 1e-300)
            if change < tolerance or disc.relative_excess(z) <= 1e-9:
                break
        z_lin = np.maximum(z, 1e-12 * max(z.max(), 1e-12))
        z, rounds = solve(z_lin), rounds + 1
    return z, rounds


def largest_scale(excess: Callable[[float], float]) -> float:
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
            # a root within rounding of an end (an excess of 1e-16 at α = 1): just inside it,
            # not the midpoint (from which false position with a halved end value crawls back)
            near = 1e-12 * (hi - lo)
            mid = hi - near if mid >= hi else lo + near
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


def into_limits(disc: Discretisation, z: NDArray[np.float64]) -> tuple[NDArray[np.float64], float]:
    """αb with the largest α ≤ 1 that puts every row within its limits, and α.

    Every row is monotone along αb from α = 0, where it holds (torque g inside the limits after
    :func:`~nearopt.timing.check_gravity`, zero accelerations and speeds). A motion that starts
    or ends moving has no such ray (b_0 or b_N is fixed): z is returned as it is, α = 1.
    """
    z = np.minimum(z, disc.z_upper)
    if not disc.problem.at_rest:  # no ray from rest: the solver's answer holds the rows
        return z, 1.0
    alpha = largest_scale(lambda alpha: disc.excess(alpha * z))
    return alpha * z, alpha


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


def moving_ends_infeasible(disc: Discretisation) -> InfeasiblePathError:
    """Why no timing of a path with moving ends holds the limits: braking as hard as the rows
    allow from b_0 (forward) and from b_N (backward), the first segment where the rows leave
    no b, and the row that stops the braking there (its kind and joint). For the message of an
    infeasible problem only: the damping's √b is taken at the segment's known knot."""
    p = disc.problem
    names = p.joint_names
    kinds = [
        (disc.blocks.torque, "torque"),
        (disc.blocks.acceleration, "acceleration"),
        (disc.blocks.torque_between, "torque"),
        (disc.blocks.acceleration_between, "acceleration"),
    ]
    cap = p.with_ends(disc.z_cap)
    for end, forward in ((0, True), (1, False)):
        if p.b_ends[end] == 0.0:
            continue
        found = _brake(disc, cap, forward)
        if found is None:
            continue
        k, row = found
        what = next((word for block, word in kinds if block.start <= row < block.stop), "speed")
        far = k == (p.segments - 1 if forward else 0)
        name, verb = ("qd0", "starts") if forward else ("qde", "ends")
        where = (
            f"cannot {'reach qde by the end' if forward else 'start from qd0 at the start'} "
            "of the path"
            if far
            else f"finds no feasible speed at σ = {float(p.sigma[k + 1 if forward else k]):.4g}"
        )
        return InfeasiblePathError(
            f"no timing of this path {verb} at {name} within the limits: changing speed as fast "
            f"as they allow (the {what} limit of joint {names[disc.joint[row]]} binds), the arm "
            f"{where}; a longer path or a lower {name} would do",
            joint=names[disc.joint[row]],
        )
    return InfeasiblePathError(
        "no timing of this path holds the limits from its start velocity qd0 to its end "
        "velocity qde (the path is too short to change speed that much)"
    )


def _brake(disc: Discretisation, cap: NDArray[np.float64], forward: bool) -> tuple[int, int] | None:
    """The segment and the row where braking from the fixed end first leaves no feasible b
    (None if it reaches the other end)."""
    p = disc.problem
    big_n = p.segments
    rows = disc.solver_index
    order = np.argsort(disc.left[rows], kind="stable")
    rows = rows[order]
    starts = np.searchsorted(disc.left[rows], np.arange(big_n + 1))
    b_known = p.b_ends[0] if forward else p.b_ends[1]
    b_other = p.b_ends[1] if forward else p.b_ends[0]  # fixed at the far end
    segments = range(big_n) if forward else range(big_n - 1, -1, -1)
    for k in segments:
        r = rows[starts[k] : starts[k + 1]]
        known = disc.coef_left[r] if forward else disc.coef_right[r]
        coef = disc.coef_right[r] if forward else disc.coef_left[r]
        rest = known * b_known + disc.sqrt_coef[r] * np.sqrt(b_known) + disc.offset[r]
        upper, lower = disc.upper[r] - rest, disc.lower[r] - rest
        with np.errstate(divide="ignore", invalid="ignore"):
            hi_b = np.where(coef > 0, upper / coef, np.where(coef < 0, lower / coef, np.inf))
            lo_b = np.where(coef > 0, lower / coef, np.where(coef < 0, upper / coef, -np.inf))
        hi_b = np.where(np.isnan(hi_b), np.inf, hi_b)
        lo_b = np.where(np.isnan(lo_b), -np.inf, lo_b)
        nxt = k + 1 if forward else k
        high = min(float(np.min(hi_b, initial=np.inf)), float(cap[nxt]))
        low = max(float(np.max(lo_b, initial=-np.inf)), 0.0)
        if k == (big_n - 1 if forward else 0):  # the far end's b is fixed
            low = max(low, b_other)
        if r.size and low > high * (1.0 + 1e-9) + 1e-300:
            return k, int(r[np.argmax(lo_b)])
        b_known = low
    return None
