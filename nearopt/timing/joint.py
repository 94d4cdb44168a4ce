"""Stage 1's convex problem jointly with further variables p (stage 2's model), by nearopt's own
primal-dual interior-point method with a dense Newton system in (z, p).

The problem is that of :func:`~nearopt.timing.solve_conic`: over z = b_1 … b_{N−1} and p,

    minimise   F(z, p) = Σ_k 2Δσ_k (1 + Q_k) / y_k,   y_k = √b_k + √b_{k+1},
               Q_k = ½ Σ_i w_i (u_{k⁺,i}² + u_{(k+1)⁻,i}²),   u = T (z, p) + u0,
    subject to lower ≤ M (z, p) ≤ upper, the torque samples within their limits,
               0 ≤ z ≤ z_upper, p within its bounds,

convex (u²/y with u affine and y concave is). Stage 2 solves it once per iteration with a few
hundred variables (N − 1 = 63 knots, 16 control points × n joints) and thousands of rows, each
row touching two knots and the control points whose basis is nonzero where it lies. Clarabel's
conic form of it adds a variable per torque sample, the cones' variables and a sparse LDLᵀ of
their KKT system per iteration; here the Newton system is formed directly in (z, p):

    (∇²F + Σ_r (y_r/s_r) a_r a_rᵀ) Δx = …,

dense and of the size of x, summed over the rows' few nonzeros by a compiled loop
(:func:`~nearopt.timing._kernels.gram_add`), and factorised by Cholesky (LAPACK). Equality rows
(via-points, a goal pose) are kept exactly by a Schur complement on their multipliers.

The method is Mehrotra's predictor-corrector with an infeasible start (Nocedal & Wright,
*Numerical Optimization*, §14.2 and §19.3): every finite side of a row gets a slack s > 0 and a
multiplier y > 0; the rows are divided by their limits (so that they are of size 1), z by the
start timing and p by its bounds (the trust region), F by its value at the start; one step length
for the primal and the dual variables, 0.995 of the way to a slack's or multiplier's boundary, and
no b more than halves in one step. It stops when the duality measure Σ s y, the rows' residuals
and the gradient of the Lagrangian are below the tolerance (relative to F), or reports that it
did not converge (stage 2 then asks Clarabel).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from .discretisation import LinearRows

__all__ = ["JointSolution", "solve_joint"]

STEP_TO_BOUNDARY = 0.995  # the fraction of the way to a slack's (or a multiplier's) boundary
START_SLACK = 1e-2  # the least slack of a row at the start (rows are of size 1)


class JointSolution(NamedTuple):
    """The joint solver's answer.

    Attributes
    ----------
    z
        b at the free knots, shape (N−1,) (clipped at 0).
    p
        The further variables, shape (P,).
    objective
        F at (z, p): the discretised cost of the model [s, or the cost's unit].
    converged
        Whether the stopping test passed within the iteration limit.
    iterations
        Newton iterations (one factorisation, two solves each).
    message
        What happened, in words.
    """

    z: NDArray[np.float64]
    p: NDArray[np.float64]
    objective: float
    converged: bool
    iterations: int
    message: str


def solve_joint(
    ds: NDArray[np.float64],
    weights: NDArray[np.float64],
    rows: LinearRows,
    torque: tuple[sp.spmatrix, NDArray[np.float64]],
    z_upper: NDArray[np.float64],
    *,
    p_bounds: tuple[NDArray[np.float64], NDArray[np.float64]],
    torque_limits: tuple[NDArray[np.float64], NDArray[np.float64]],
    start: NDArray[np.float64],
    tolerance: float = 1e-9,
    max_iterations: int = 80,
) -> JointSolution:
    """Solve the problem of this module's docstring.

    Parameters
    ----------
    ds
        Δσ_k of the N segments, shape (N,).
    weights
        w_i of the cost, shape (n,) (all 0: time-optimal).
    rows
        ``lower ≤ M (z, p) ≤ upper``, M of shape (R, N − 1 + P); rows with lower = upper are
        kept as equalities.
    torque
        (T, u0): the torque samples u = T (z, p) + u0, joint-major (row i·2N + r as in
        :class:`~nearopt.timing.Discretisation`), T of shape (n·2N, N − 1 + P).
    z_upper
        Upper bounds on z (inf where none), shape (N − 1,); z ≥ 0 always.
    p_bounds
        Lower and upper bounds on p, each (P,), finite (a trust region).
    torque_limits
        Lower and upper limits of the torque samples, each (n·2N,) (±inf where none).
    start
        b at the free knots where the model was built, shape (N − 1,) (positive): the scale of z
        and its start.
    tolerance
        Relative accuracy of F at the answer.
    max_iterations
        Newton iterations before giving up (``converged`` False).
    """
    problem = _Problem(ds, weights, rows, torque, z_upper, p_bounds, torque_limits, start)
    with _one_blas_thread():
        return _iterate(problem, tolerance, max_iterations)


def _one_blas_thread():  # noqa: ANN202 - threadpoolctl's context manager
    """LAPACK on one thread: at these sizes (a few hundred) OpenBLAS's threads cost more than
    they give, and several times more when another process keeps the other cores busy."""
    global _BLAS
    if _BLAS is None:
        from threadpoolctl import ThreadpoolController

        _BLAS = ThreadpoolController()
    return _BLAS.limit(limits=1, user_api="blas")


_BLAS = None


class _Problem:
    """The scaled problem: x = (z / z_scale, p / p_scale); one-sided sides of two-sided rows
    a_r x ∈ [lo_r, hi_r] (each row divided by its limit; the torque rows first, then M's rows,
    then the variables' bounds); the equalities E x = f; F / F(start)."""

    def __init__(
        self,
        ds: NDArray[np.float64],
        weights: NDArray[np.float64],
        rows: LinearRows,
        torque: tuple[sp.spmatrix, NDArray[np.float64]],
        z_upper: NDArray[np.float64],
        p_bounds: tuple[NDArray[np.float64], NDArray[np.float64]],
        torque_limits: tuple[NDArray[np.float64], NDArray[np.float64]],
        start: NDArray[np.float64],
    ) -> None:
        big_n = ds.size
        self.ds, self.nz, self.big_n = ds, big_n - 1, big_n
        self.z_scale = np.maximum(start, 1e-9 * max(float(np.max(start, initial=0.0)), 1e-300))
        reach = np.maximum(np.abs(p_bounds[0]), np.abs(p_bounds[1]))
        self.p_scale = np.where(np.isfinite(reach) & (reach > 0.0), reach, 1.0)
        columns = sp.diags(np.concatenate([self.z_scale, self.p_scale]))
        self.nx = self.nz + self.p_scale.size
        t_rows, t_lo, t_hi, t_scale = _torque_block(weights, torque, torque_limits, columns)
        self.energy = bool(np.any(weights > 0.0))
        if self.energy:  # the torque rows of the energy term: u = scale · (a x) + u0
            n2 = t_scale.size
            joint, r = np.divmod(np.arange(n2), 2 * big_n)
            self.t_count, self.t_scale, self.u0 = n2, t_scale, np.asarray(torque[1], dtype=float)
            self.t_weight, self.t_seg = weights[joint], np.where(r < big_n, r, r - big_n)
        else:
            self.t_count = 0
        m_rows, m_lo, m_hi, self.e_mat, self.e_rhs = _linear_block(rows, columns)
        z_hi = np.where(np.isfinite(z_upper), z_upper / self.z_scale, np.inf)
        self.mat = sp.vstack([t_rows, m_rows, sp.eye(self.nx, format="csr")]).tocsr()
        self.mat.sort_indices()
        self.mat_t = self.mat.T.tocsr()
        self.top = self.mat[: self.t_count]  # the energy's torque rows
        self.top_t = self.top.T.tocsr()
        lo = np.concatenate([t_lo, m_lo, np.zeros(self.nz), p_bounds[0] / self.p_scale])
        hi = np.concatenate([t_hi, m_hi, z_hi, p_bounds[1] / self.p_scale])
        self.fin_lo, self.fin_hi = np.isfinite(lo), np.isfinite(hi)
        self.lo, self.hi = np.where(self.fin_lo, lo, 0.0), np.where(self.fin_hi, hi, 0.0)
        self.sides = int(self.fin_lo.sum() + self.fin_hi.sum())
        self.f_scale = 1.0
        self.f_scale = 1.0 / self.value(self._start())

    def _start(self) -> NDArray[np.float64]:
        return np.concatenate([np.ones(self.nz), np.zeros(self.nx - self.nz)])

    def _segments(self, x: NDArray[np.float64]) -> tuple[NDArray[np.float64], ...]:
        """λ at the free knots, y_k, g_k = 2Δσ_k (1 + Q_k)/y_k and the torques u (energy)."""
        lam = np.sqrt(np.maximum(x[: self.nz] * self.z_scale, 0.0))
        y = np.concatenate([lam, [0.0]]) + np.concatenate([[0.0], lam])
        q = np.zeros(self.big_n)
        u = np.zeros(0)
        if self.energy:
            u = self.t_scale * (self.top @ x) + self.u0
            q = np.bincount(self.t_seg, 0.5 * self.t_weight * u * u, self.big_n)
        return lam, y, 2.0 * self.ds * (1.0 + q) / y, u

    def value(self, x: NDArray[np.float64]) -> float:
        """F(x), scaled."""
        return float(np.sum(self._segments(x)[2])) * self.f_scale

    def derivatives(
        self, x: NDArray[np.float64], newton: NDArray[np.float64]
    ) -> tuple[float, NDArray[np.float64], NDArray[np.float64]]:
        """F(x) and ∇F(x), scaled; ∇²F(x) but for the energy's curvature along the torque rows
        added into the lower triangle of ``newton``; that curvature per torque row (the
        coefficient of a_r a_rᵀ)."""
        from ._kernels import segment_sums

        lam, y, g, u = self._segments(x)
        g = g * self.f_scale
        safe = np.where(lam > 0.0, lam, np.inf)
        dl = 0.5 / safe * self.z_scale  # dλ/dx at the free knots
        d2l = -0.25 / safe**3 * self.z_scale**2
        gy, gyy = -g / y, 2.0 * g / y**2  # ∂g/∂y, ∂²g/∂y²
        grad = np.zeros(self.nx)
        grad[: self.nz] = (gy[:-1] + gy[1:]) * dl
        knots = np.arange(self.nz)
        newton[knots, knots] += (gyy[:-1] + gyy[1:]) * dl * dl + (gy[:-1] + gy[1:]) * d2l
        newton[knots[1:], knots[:-1]] += gyy[1:-1] * dl[:-1] * dl[1:]
        if not self.energy:
            return float(np.sum(g)), grad, np.zeros(0)
        y_r = y[self.t_seg]
        curvature = 2.0 * self.f_scale * self.ds[self.t_seg] * self.t_weight / y_r  # ∂²g/∂u²
        slope = curvature * u  # ∂g/∂u
        top = self.top
        grad += self.top_t @ (slope * self.t_scale)
        # ∂²g/∂u∂y = −slope/y: Σ_r of it along a_r per segment, then along ∇y_k
        per_segment = np.zeros((self.nx, self.big_n))
        mixed = -slope / y_r * self.t_scale
        segment_sums(top.indptr, top.indices, top.data, mixed, self.t_seg, per_segment)
        cross = per_segment[:, 1:] * dl + per_segment[:, :-1] * dl  # (nx, nz)
        newton[:, : self.nz] += np.tril(cross)
        newton[: self.nz, : self.nz] += np.tril(cross[: self.nz].T)
        return float(np.sum(g)), grad, curvature * self.t_scale**2


def _row_scale(
    mat: sp.csr_matrix, lower: NDArray[np.float64], upper: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Each row's largest finite limit (its largest coefficient where that is 0; else 1)."""
    scale = np.maximum(
        np.where(np.isfinite(upper), np.abs(upper), 0.0),
        np.where(np.isfinite(lower), np.abs(lower), 0.0),
    )
    if mat.nnz:
        largest = np.zeros(scale.size)
        coo = mat.tocoo()
        np.maximum.at(largest, coo.row, np.abs(coo.data))
        scale = np.where(scale > 0.0, scale, largest)
    return np.where(scale > 0.0, scale, 1.0)


def _torque_block(
    weights: NDArray[np.float64],
    torque: tuple[sp.spmatrix, NDArray[np.float64]],
    limits: tuple[NDArray[np.float64], NDArray[np.float64]],
    columns: sp.spmatrix,
) -> tuple[sp.csr_matrix, NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The torque rows (all of them with an energy term, else those with a limit), divided by
    their limits, and their sides; the divisors."""
    t_mat, u0 = sp.csr_matrix(torque[0]), np.asarray(torque[1], dtype=float)
    low, high = limits
    held = np.isfinite(low) | np.isfinite(high)
    index = np.arange(u0.size) if np.any(weights > 0.0) else np.flatnonzero(held)
    low, high, u0 = low[index], high[index], u0[index]
    scale = np.maximum(
        np.where(np.isfinite(high), np.abs(high), 0.0),
        np.where(np.isfinite(low), np.abs(low), 0.0),
    )
    scale = np.where(scale > 0.0, scale, 1.0)
    rows = sp.diags(1.0 / scale) @ t_mat[index] @ columns
    return sp.csr_matrix(rows), (low - u0) / scale, (high - u0) / scale, scale


def _linear_block(
    rows: LinearRows, columns: sp.spmatrix
) -> tuple[sp.csr_matrix, NDArray[np.float64], NDArray[np.float64], sp.csr_matrix, NDArray]:
    """The rows with a finite side, divided by their scale, and their sides; the equality rows
    (lower = upper) and their right-hand side."""
    mat = sp.csr_matrix(rows.matrix)
    lower, upper = np.asarray(rows.lower, dtype=float), np.asarray(rows.upper, dtype=float)
    equal = np.isfinite(lower) & (lower == upper)
    keep = np.flatnonzero(~equal & (np.isfinite(lower) | np.isfinite(upper)))
    e_mat = sp.csr_matrix(mat[np.flatnonzero(equal)] @ columns)
    kept, lower, upper = mat[keep], lower[keep], upper[keep]
    scale = _row_scale(kept, lower, upper)
    return (
        sp.csr_matrix(sp.diags(1.0 / scale) @ kept @ columns),
        lower / scale,
        upper / scale,
        e_mat,
        upper[:0] if not equal.any() else np.asarray(rows.upper, dtype=float)[equal],
    )


class _State:
    """The iterate: x, the equalities' multipliers ν, and per row the slacks and multipliers of
    its upper and lower sides (1 and 0 where a side is open)."""

    def __init__(self, pr: _Problem) -> None:
        self.x = pr._start()
        self.nu = np.zeros(pr.e_rhs.size)
        ax = pr.mat @ self.x
        self.s_hi = np.where(pr.fin_hi, np.maximum(pr.hi - ax, START_SLACK), 1.0)
        self.s_lo = np.where(pr.fin_lo, np.maximum(ax - pr.lo, START_SLACK), 1.0)
        self.y_hi = np.where(pr.fin_hi, START_SLACK / self.s_hi, 0.0)
        self.y_lo = np.where(pr.fin_lo, START_SLACK / self.s_lo, 0.0)


class _Newton:
    """The factorised Newton matrix and, with equalities, the Schur complement E H⁻¹ Eᵀ."""

    def __init__(self, matrix: NDArray[np.float64], e_mat: sp.csr_matrix) -> None:
        try:
            self.factor = la.cho_factor(matrix, lower=True, check_finite=False)
        except la.LinAlgError:  # not positive definite to rounding: a tiny regularisation
            shift = 1e-10 * max(float(np.max(np.abs(np.diag(matrix)))), 1e-300)
            self.factor = la.cho_factor(
                matrix + shift * np.eye(matrix.shape[0]), lower=True, check_finite=False
            )
        self.e_mat = e_mat
        if e_mat.shape[0]:
            self.h_et = la.cho_solve(self.factor, e_mat.T.toarray(), check_finite=False)
            schur = e_mat @ self.h_et
            shift = 1e-13 * max(float(np.max(np.abs(np.diag(schur)))), 1e-300)
            self.schur = la.cho_factor(schur + shift * np.eye(schur.shape[0]), lower=True)

    def solve(
        self, rhs: NDArray[np.float64], r_e: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Δx and Δν of [H Eᵀ; E 0] (Δx, Δν) = (rhs, −r_e)."""
        dx = la.cho_solve(self.factor, rhs, check_finite=False)
        if not self.e_mat.shape[0]:
            return dx, np.zeros(0)
        dnu = la.cho_solve(self.schur, r_e + self.e_mat @ dx, check_finite=False)
        return dx - self.h_et @ dnu, dnu


def _longest(v: NDArray[np.float64], dv: NDArray[np.float64]) -> float:
    """The largest α with v + α dv ≥ 0 (v ≥ 0)."""
    neg = dv < 0.0
    return float(np.min(-v[neg] / dv[neg], initial=np.inf))


def _iterate(pr: _Problem, tolerance: float, max_iterations: int) -> JointSolution:
    """Mehrotra's predictor-corrector from :class:`_State`'s start."""
    from ._kernels import gram_add, mirror

    st = _State(pr)
    for iteration in range(1, max_iterations + 1):
        newton = np.zeros((pr.nx, pr.nx))
        f, grad, curvature = pr.derivatives(st.x, newton)
        ax = pr.mat @ st.x
        r_hi = np.where(pr.fin_hi, ax + st.s_hi - pr.hi, 0.0)
        r_lo = np.where(pr.fin_lo, st.s_lo - ax + pr.lo, 0.0)
        r_e = pr.e_mat @ st.x - pr.e_rhs
        r_d = grad + pr.mat_t @ (st.y_hi - st.y_lo) + pr.e_mat.T @ st.nu
        gap = float(st.s_hi @ st.y_hi + st.s_lo @ st.y_lo)
        worst = max(np.max(np.abs(r_hi)), np.max(np.abs(r_lo)), np.max(np.abs(r_e), initial=0.0))
        if not (np.isfinite(f) and np.isfinite(gap) and np.all(np.isfinite(r_d))):
            return _answer(pr, st, False, iteration, "the iterate is not finite")
        if gap <= tolerance and worst <= tolerance and np.max(np.abs(r_d)) <= tolerance:
            return _answer(pr, st, True, iteration - 1, f"converged in {iteration - 1} iterations")
        d = st.y_hi / st.s_hi + st.y_lo / st.s_lo
        d[: curvature.size] += curvature
        gram_add(pr.mat.indptr, pr.mat.indices, pr.mat.data, d, newton)
        mirror(newton)
        try:
            system = _Newton(newton, pr.e_mat)
        except la.LinAlgError:
            return _answer(pr, st, False, iteration, "the Newton matrix is singular")
        residuals = (r_hi, r_lo, r_e, r_d)
        mu = gap / pr.sides
        aff = _direction(pr, st, system, residuals, st.s_hi * st.y_hi, st.s_lo * st.y_lo)
        a_aff = _step_length(pr, st, aff, 1.0)
        mu_aff = (
            (st.s_hi + a_aff * aff[2]) @ (st.y_hi + a_aff * aff[4])
            + (st.s_lo + a_aff * aff[3]) @ (st.y_lo + a_aff * aff[5])
        ) / pr.sides
        target = (mu_aff / mu) ** 3 * mu
        rc_hi = np.where(pr.fin_hi, st.s_hi * st.y_hi + aff[2] * aff[4] - target, 0.0)
        rc_lo = np.where(pr.fin_lo, st.s_lo * st.y_lo + aff[3] * aff[5] - target, 0.0)
        step = _direction(pr, st, system, residuals, rc_hi, rc_lo)
        alpha = _step_length(pr, st, step, STEP_TO_BOUNDARY)
        st.x = st.x + alpha * step[0]
        st.nu = st.nu + alpha * step[1]
        st.s_hi = np.where(pr.fin_hi, st.s_hi + alpha * step[2], 1.0)
        st.s_lo = np.where(pr.fin_lo, st.s_lo + alpha * step[3], 1.0)
        st.y_hi = np.where(pr.fin_hi, st.y_hi + alpha * step[4], 0.0)
        st.y_lo = np.where(pr.fin_lo, st.y_lo + alpha * step[5], 0.0)
    return _answer(pr, st, False, max_iterations, f"no convergence in {max_iterations} iterations")


def _direction(
    pr: _Problem,
    st: _State,
    system: _Newton,
    residuals: tuple[NDArray[np.float64], ...],
    rc_hi: NDArray[np.float64],
    rc_lo: NDArray[np.float64],
) -> tuple[NDArray[np.float64], ...]:
    """The Newton direction (Δx, Δν, Δs_hi, Δs_lo, Δy_hi, Δy_lo) for the complementarity
    targets s·y − rc."""
    r_hi, r_lo, r_e, r_d = residuals
    w_hi = np.where(pr.fin_hi, (rc_hi - st.y_hi * r_hi) / st.s_hi, 0.0)
    w_lo = np.where(pr.fin_lo, (rc_lo - st.y_lo * r_lo) / st.s_lo, 0.0)
    dx, dnu = system.solve(-r_d + pr.mat_t @ (w_hi - w_lo), r_e)
    a_dx = pr.mat @ dx
    ds_hi, ds_lo = -r_hi - a_dx, -r_lo + a_dx
    dy_hi = np.where(pr.fin_hi, (-rc_hi - st.y_hi * ds_hi) / st.s_hi, 0.0)
    dy_lo = np.where(pr.fin_lo, (-rc_lo - st.y_lo * ds_lo) / st.s_lo, 0.0)
    return dx, dnu, ds_hi, ds_lo, dy_hi, dy_lo


def _step_length(
    pr: _Problem, st: _State, step: tuple[NDArray[np.float64], ...], fraction: float
) -> float:
    """At most 1, ``fraction`` of the way to the nearest slack's or multiplier's boundary, and
    no b more than halved."""
    hi, lo = pr.fin_hi, pr.fin_lo
    longest = min(
        _longest(st.s_hi[hi], step[2][hi]),
        _longest(st.s_lo[lo], step[3][lo]),
        _longest(st.y_hi[hi], step[4][hi]),
        _longest(st.y_lo[lo], step[5][lo]),
    )
    return min(1.0, fraction * longest, _longest(st.x[: pr.nz], 2.0 * step[0][: pr.nz]))


def _answer(
    pr: _Problem, st: _State, converged: bool, iterations: int, message: str
) -> JointSolution:
    return JointSolution(
        z=np.maximum(st.x[: pr.nz] * pr.z_scale, 0.0),
        p=st.x[pr.nz :] * pr.p_scale,
        objective=pr.value(st.x) / pr.f_scale,
        converged=converged,
        iterations=iterations,
        message=message,
    )
