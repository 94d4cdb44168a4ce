"""The solver back ends of stage 1: HiGHS LPs, Clarabel's SOCP and SciPy's trust-constr.

:func:`solve_timing` chooses among them by the cost and the damping (see :mod:`nearopt.timing`).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
from scipy.optimize import Bounds, LinearConstraint, NonlinearConstraint, linprog, minimize

from ..cost import Cost, TimeCost, TorqueCost
from ..errors import SolverError
from .discretisation import Discretisation
from .problem import check_gravity

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from .problem import TimingProblem

__all__ = ["TimingSolution", "solve_timing", "largest_scale", "into_limits"]


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
    check_gravity(problem)
    disc = Discretisation(problem)
    weights = cost.torque_weights(problem.dof) if isinstance(cost, TorqueCost) else None
    if weights is not None and not disc.has_damping:
        return _solve_convex(disc, cost, weights, None, tolerance)  # no linearisation point needed
    z_max, rounds = _greatest_profile(disc)
    z_max = into_limits(disc, z_max)
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
    disc: Discretisation,
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
    z = into_limits(disc, z)
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
    disc: Discretisation,
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
    z = into_limits(disc, np.maximum(res.x, lb))
    return TimingSolution(
        b=disc.b(z),
        objective=disc.objective(z, cost)[0],
        status="optimal" if res.status in (1, 2) else "iteration_limit",
        solver="trust-constr",
        iterations=int(res.nit),
        message=str(res.message),
    )


def _lp(
    disc: Discretisation, c: NDArray[np.float64], z_lin: NDArray[np.float64] | None = None
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
    disc: Discretisation,
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


def _greatest_profile(disc: Discretisation) -> tuple[NDArray[np.float64], int]:
    """The greatest feasible b (maximise Σ b), damping linearised to a fixed point."""
    weights = -np.ones(disc.problem.segments - 1)
    z, _ = _lp(disc, weights)
    return _relinearise(
        disc, lambda z_lin: _lp(disc, weights, z_lin)[0], z, tolerance=1e-10, max_rounds=51
    )


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
            mid = 0.5 * (lo + hi)
        e_mid = excess(mid)
        if e_mid <= 0.0:
            lo, e_lo = mid, e_mid
            e_hi, side = (0.5 * e_hi, side) if side == -1 else (e_hi, -1)
        else:
            hi, e_hi = mid, e_mid
            e_lo, side = (0.5 * e_lo, side) if side == 1 else (e_lo, 1)
    return lo


def into_limits(disc: Discretisation, z: NDArray[np.float64]) -> NDArray[np.float64]:
    """Scale b by the largest α ≤ 1 that puts every torque sample within the limits."""
    z = np.minimum(z, disc.problem.b_upper[1:-1])
    if disc.speed_bound.size:  # the interior speed rows S z ≤ bound, S ≥ 0
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = disc.speed_bound / (disc.speed @ z)
        z = z * min(1.0, float(np.nanmin(np.where(ratio > 0, ratio, np.inf))))

    def excess(alpha: float) -> float:
        u = disc.torque(alpha * z)
        return float(max(np.max(u - disc.upper), np.max(disc.lower - u)))

    return largest_scale(excess) * z


def _socp(
    disc: Discretisation,
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
