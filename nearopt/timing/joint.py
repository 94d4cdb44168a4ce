"""Stage 1's convex problem jointly with further variables p (stage 2's model), by nearopt's own
primal-dual interior-point method with a banded Newton system in (z, p).

The problem is that of :func:`~nearopt.timing.solve_conic`: over z = b_1 … b_{N−1} and p,

    minimise   F(z, p) = Σ_k 2Δσ_k (1 + Q_k) / y_k + c·p,   y_k = √b_k + √b_{k+1},
               Q_k = ½ Σ_i w_i (u_{k⁺,i}² + u_{(k+1)⁻,i}²),   u = T (z, p) + u0,

with b_0, b_N fixed (0 at rest; a moving end's given b) and c a price on p (stage 2's first-order
term of a moving end's b through the path; 0 otherwise),
    subject to lower ≤ M (z, p) ≤ upper, the torque samples within their limits,
               0 ≤ z ≤ z_upper, p within its bounds,

convex (u²/y with u affine and y concave is). Stage 2 solves it once per iteration with a few
hundred variables (N − 1 = 63 knots, 16 control points × n joints) and thousands of rows, each
row touching two knots and the control points whose basis is nonzero where it lies. Clarabel's
conic form of it adds a variable per torque sample, the cones' variables and a sparse LDLᵀ of
their KKT system per iteration; here the Newton system is formed directly in (z, p):

    (∇²F + Σ_r (y_r/s_r) a_r a_rᵀ) Δx = …,

of the size of x, summed over the rows' few nonzeros by compiled loops
(:mod:`nearopt.timing._joint_kernels`; the rows at one knot as a group) and factorised by
Cholesky (LAPACK, one thread). Every row is local along the path (two knots and the control
points whose basis is nonzero there), so with the variables ordered along the path the matrix is
a band (half-width ≈ 4n + a few knots): it is held and factorised as one (:class:`_Band`),
nx·kd² instead of nx³/3.
Equality rows (via-points, a goal pose) are kept exactly by a Schur complement on their
multipliers.

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
    """The joint solver's answer: z, p and objective as in
    :class:`~nearopt.timing.ConicSolution` (the objective is F at (z, p)), and

    Attributes
    ----------
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
    b_ends: tuple[float, float] = (0.0, 0.0),
    p_price: NDArray[np.float64] | None = None,
) -> JointSolution:
    """Solve the problem of this module's docstring.

    Parameters
    ----------
    ds, weights, rows, torque, z_upper, p_bounds, torque_limits
        As in :func:`~nearopt.timing.solve_conic`, but: rows with lower = upper are kept as
        equalities, p_bounds are finite (a trust region) and torque_limits are always given
        (±inf where a sample has none).
    start
        b at the free knots where the model was built, shape (N − 1,) (positive): the scale of z
        and its start.
    tolerance
        Relative accuracy of F at the answer.
    max_iterations
        Newton iterations before giving up (``converged`` False).
    b_ends
        The fixed b_0 and b_N (0 at rest): their √b enter y_0 and y_{N−1} as constants (the
        rows' terms in them are in ``rows`` and ``torque`` already), as in
        :func:`~nearopt.timing.solve_conic`.
    p_price
        A linear term c·p added to F (shape of p), or None.
    """
    problem = _Problem(
        (ds, weights, rows, torque, z_upper), p_bounds, torque_limits, start, (b_ends, p_price)
    )
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
        model: tuple,
        p_bounds: tuple[NDArray[np.float64], NDArray[np.float64]],
        torque_limits: tuple[NDArray[np.float64], NDArray[np.float64]],
        start: NDArray[np.float64],
        extra: tuple = ((0.0, 0.0), None),
    ) -> None:
        """``model``: (ds, weights, rows, torque, z_upper) of :func:`solve_joint`; ``extra``:
        its (b_ends, p_price)."""
        ds, weights, rows, torque, z_upper = model
        big_n = ds.size
        self.ds, self.nz, self.big_n = ds, big_n - 1, big_n
        self.ends = np.sqrt(np.maximum(np.asarray(extra[0], dtype=float), 0.0))  # λ_0, λ_N
        self.z_scale = np.maximum(start, 1e-9 * max(float(np.max(start, initial=0.0)), 1e-300))
        reach = np.maximum(np.abs(p_bounds[0]), np.abs(p_bounds[1]))
        self.p_scale = np.where(np.isfinite(reach) & (reach > 0.0), reach, 1.0)
        columns = np.concatenate([self.z_scale, self.p_scale])
        self.nx = self.nz + self.p_scale.size
        self.lin = np.zeros(self.nx)  # the price on p, per scaled variable
        if extra[1] is not None:
            self.lin[self.nz :] = np.asarray(extra[1], dtype=float) * self.p_scale
        t_rows, t_lo, t_hi, t_scale, t_index = _torque_block(
            weights, torque, torque_limits, columns
        )
        self.energy = bool(np.any(weights > 0.0))
        if self.energy:  # the torque rows of the energy term: u = scale · (a x) + u0
            n2 = t_scale.size
            joint, r = np.divmod(np.arange(n2), 2 * big_n)
            self.t_count, self.t_scale, self.u0 = n2, t_scale, np.asarray(torque[1], dtype=float)
            self.t_weight, self.t_seg = weights[joint], np.where(r < big_n, r, r - big_n)
        else:
            self.t_count, self.t_scale, self.u0 = 0, np.zeros(0), np.zeros(0)
            self.t_weight, self.t_seg = np.zeros(0), np.zeros(0, dtype=np.int64)
        m_rows, m_lo, m_hi, e_mat, self.e_rhs = _linear_block(rows, columns)
        z_hi = np.where(np.isfinite(z_upper), z_upper / self.z_scale, np.inf)
        self.mat = sp.vstack([t_rows, m_rows, sp.eye(self.nx, format="csr")]).tocsr()
        self.mat.sort_indices()
        # the rows at one knot (torque, speed, … of its samples) share most of their columns:
        # summed as a group (a row without a knot alone)
        counts = np.diff(self.mat.indptr)
        first = np.where(
            counts > 0,
            self.mat.indices[np.minimum(self.mat.indptr[:-1], max(self.mat.nnz - 1, 0))],
            self.nx,
        )
        key = np.where(first < self.nz, first, self.nz + np.arange(first.size))
        self.group_rows = np.argsort(key, kind="stable").astype(np.int64)
        keys = key[self.group_rows]
        self.group_start = np.r_[
            np.flatnonzero(np.r_[True, keys[1:] != keys[:-1]]), keys.size
        ].astype(np.int64)
        self.top = self.mat[: self.t_count]  # the energy's torque rows
        self.e_dense = np.ascontiguousarray(e_mat.toarray())
        lo = np.concatenate([t_lo, m_lo, np.zeros(self.nz), p_bounds[0] / self.p_scale])
        hi = np.concatenate([t_hi, m_hi, z_hi, p_bounds[1] / self.p_scale])
        self.fin_lo, self.fin_hi = np.isfinite(lo), np.isfinite(hi)
        self.lo, self.hi = np.where(self.fin_lo, lo, 0.0), np.where(self.fin_hi, hi, 0.0)
        self.sides = int(self.fin_lo.sum() + self.fin_hi.sum())
        self.f_scale = 1.0 / self.cost(self.start())
        self.band = _Band.of(self.mat, self.nz)
        from . import _joint_kernels as kernels

        csr = (self.mat.indptr, self.mat.indices, self.mat.data)
        self.gram = kernels.gram_plan(*csr, self.group_start, self.group_rows, self.band.position)

    def start(self) -> NDArray[np.float64]:
        """x at the start: z at the model's timing, p = 0."""
        return np.concatenate([np.ones(self.nz), np.zeros(self.nx - self.nz)])

    def cost(self, x: NDArray[np.float64]) -> float:
        """F at x = Σ_k 2Δσ_k (1 + Q_k) / (λ_k + λ_{k+1}) (not scaled)."""
        lam = np.sqrt(np.maximum(x[: self.nz] * self.z_scale, 0.0))
        y = np.concatenate([lam, [self.ends[1]]]) + np.concatenate([[self.ends[0]], lam])
        q = np.zeros(self.big_n)
        if self.energy:
            u = self.t_scale * (self.top @ x) + self.u0
            q = np.bincount(self.t_seg, 0.5 * self.t_weight * u * u, self.big_n)
        return float(np.sum(2.0 * self.ds * (1.0 + q) / y) + self.lin @ x)


def _row_scale(
    mat: sp.csr_matrix, lower: NDArray[np.float64], upper: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Each row's largest finite limit (its largest coefficient where that is 0; else 1)."""
    scale = _largest_limit(lower, upper)
    if mat.nnz:
        first = np.minimum(mat.indptr[:-1], mat.nnz - 1)
        largest = np.maximum.reduceat(np.abs(mat.data), first)
        largest = np.where(np.diff(mat.indptr) > 0, largest, 0.0)
        scale = np.where(scale > 0.0, scale, largest)
    return np.where(scale > 0.0, scale, 1.0)


def _largest_limit(lower: NDArray[np.float64], upper: NDArray[np.float64]) -> NDArray[np.float64]:
    """The larger of |lower| and |upper| where finite (0 where neither is)."""
    return np.maximum(
        np.where(np.isfinite(upper), np.abs(upper), 0.0),
        np.where(np.isfinite(lower), np.abs(lower), 0.0),
    )


def _scaled(
    mat: sp.csr_matrix, rows: NDArray[np.float64], columns: NDArray[np.float64]
) -> sp.csr_matrix:
    """diag(rows) · mat · diag(columns), entry by entry as the two products give it."""
    mat = sp.csr_matrix(mat)
    data = (np.repeat(rows, np.diff(mat.indptr)) * mat.data) * columns[mat.indices]
    return sp.csr_matrix((data, mat.indices, mat.indptr), shape=mat.shape)


def _torque_block(
    weights: NDArray[np.float64],
    torque: tuple[sp.spmatrix, NDArray[np.float64]],
    limits: tuple[NDArray[np.float64], NDArray[np.float64]],
    columns: NDArray[np.float64],
) -> tuple[sp.csr_matrix, NDArray, NDArray, NDArray, NDArray[np.int64]]:
    """The torque rows (all of them with an energy term, else those with a limit), divided by
    their limits, and their sides; the divisors; their indices among the torque samples."""
    t_mat, u0 = sp.csr_matrix(torque[0]), np.asarray(torque[1], dtype=float)
    low, high = limits
    held = np.isfinite(low) | np.isfinite(high)
    index = np.arange(u0.size) if np.any(weights > 0.0) else np.flatnonzero(held)
    low, high, u0 = low[index], high[index], u0[index]
    scale = _largest_limit(low, high)
    scale = np.where(scale > 0.0, scale, 1.0)
    rows = _scaled(t_mat[index], 1.0 / scale, columns)
    return rows, (low - u0) / scale, (high - u0) / scale, scale, index


def _linear_block(
    rows: LinearRows, columns: NDArray[np.float64]
) -> tuple[sp.csr_matrix, NDArray[np.float64], NDArray[np.float64], sp.csr_matrix, NDArray]:
    """The rows with a finite side, divided by their scale, and their sides; the equality rows
    (lower = upper) and their right-hand side."""
    mat = sp.csr_matrix(rows.matrix)
    lower, upper = np.asarray(rows.lower, dtype=float), np.asarray(rows.upper, dtype=float)
    equal = np.flatnonzero(np.isfinite(lower) & (lower == upper))
    e_mat, e_rhs = _scaled(mat[equal], np.ones(equal.size), columns), upper[equal]
    keep = np.flatnonzero((lower != upper) & (np.isfinite(lower) | np.isfinite(upper)))
    kept, lower, upper = mat[keep], lower[keep], upper[keep]
    scale = _row_scale(kept, lower, upper)
    return _scaled(kept, 1.0 / scale, columns), lower / scale, upper / scale, e_mat, e_rhs


class _State:
    """The iterate: x, the equalities' multipliers ν, and per row the slacks and multipliers of
    its upper and lower sides (1 and 0 where a side is open)."""

    def __init__(self, pr: _Problem) -> None:
        self.x = pr.start()
        self.nu = np.zeros(pr.e_rhs.size)
        ax = pr.mat @ self.x
        self.s_hi = np.where(pr.fin_hi, np.maximum(pr.hi - ax, START_SLACK), 1.0)
        self.s_lo = np.where(pr.fin_lo, np.maximum(ax - pr.lo, START_SLACK), 1.0)
        self.y_hi = np.where(pr.fin_hi, START_SLACK / self.s_hi, 0.0)
        self.y_lo = np.where(pr.fin_lo, START_SLACK / self.s_lo, 0.0)


class _Band:
    """Where the Newton matrix is held: as its lower band in an order of the variables along the
    path (a knot's b at its place, a control point among the knots its rows touch), in which
    every row's columns lie within ``kd`` places of each other, and so does every nonzero of
    Σ_r a_r a_rᵀ and of ∇²F. The band then holds (kd + 1)·nx numbers and its Cholesky factor
    costs nx·kd² instead of nx³/3 (LAPACK's pbtrf). Where no order makes it narrow enough to
    pay (kd > nx / 4), the order is x's own and the band the whole lower triangle, factorised
    densely.

    Attributes
    ----------
    order
        The variables in the band's order; ``position`` its inverse (a variable's place).
    kd
        The band's half-width.
    dense
        Whether the whole lower triangle is held (then factorised as a dense matrix).
    """

    def __init__(self, order: NDArray[np.int64], kd: int) -> None:
        nx = order.size
        self.order, self.kd, self.dense = order, kd, kd == nx - 1
        self.position = np.empty(nx, dtype=np.int64)
        self.position[order] = np.arange(nx)
        if self.dense:  # entry (i, j ≤ i) of the matrix is band[i − j, j]
            i, j = np.tril_indices(nx)
            self.lower = (i, j)
            self.flat = (i - j) * nx + j

    @staticmethod
    def of(mat: sp.csr_matrix, nz: int) -> _Band:
        """The band of the Newton matrix of rows ``mat`` over x = (z, p), z the first ``nz``
        columns (the rows' columns sorted)."""
        nx = mat.shape[1]
        counts = np.diff(mat.indptr)
        full = np.flatnonzero(counts)
        first = mat.indices[mat.indptr[full]]  # a row's first (smallest) column
        on_z = first < nz  # its place along the path: its first knot
        rows = np.repeat(np.arange(counts.size), counts)
        place = np.full(counts.size, -1.0)
        place[full[on_z]] = first[on_z]
        placed = place[rows] >= 0.0
        total = np.bincount(mat.indices[placed], place[rows][placed], nx)
        seen = np.bincount(mat.indices[placed], minlength=nx)
        where = np.where(seen > 0, total / np.maximum(seen, 1), np.inf)
        where[:nz] = np.arange(nz)  # a knot's b at its own place
        order = np.lexsort((np.arange(nx) >= nz, where))
        position = np.empty(nx, dtype=np.int64)
        position[order] = np.arange(nx)
        at = position[mat.indices]
        kd = 1 if nz > 1 else 0  # ∇²F couples neighbouring knots
        if full.size:
            starts = mat.indptr[full]
            spans = np.maximum.reduceat(at, starts) - np.minimum.reduceat(at, starts)
            kd = max(kd, int(np.max(spans)))
        if 4 * kd > nx:
            return _Band(np.arange(nx), nx - 1)
        return _Band(order, kd)


class _Newton:
    """The factorised Newton matrix (given as its lower band, :class:`_Band`) and, with
    equalities, the Schur complement E H⁻¹ Eᵀ."""

    def __init__(self, ab: NDArray[np.float64], e_mat: NDArray[np.float64], band: _Band) -> None:
        self.band = band
        if band.dense:
            nx = ab.shape[1]
            matrix = np.zeros((nx, nx))
            matrix[band.lower] = ab.ravel()[band.flat]
            try:
                self.factor = la.cho_factor(matrix, lower=True, check_finite=False)
            except la.LinAlgError:  # not positive definite to rounding: a tiny regularisation
                matrix[np.diag_indices(nx)] += 1e-10 * max(float(np.max(np.abs(ab[0]))), 1e-300)
                self.factor = la.cho_factor(matrix, lower=True, check_finite=False)
        else:
            try:
                self.factor = la.cholesky_banded(ab, lower=True, check_finite=False)
            except la.LinAlgError:  # as above
                ab = ab.copy()
                ab[0] += 1e-10 * max(float(np.max(np.abs(ab[0]))), 1e-300)
                self.factor = la.cholesky_banded(ab, lower=True, check_finite=False)
        self.e_mat = e_mat
        if e_mat.shape[0]:
            self.h_et = self._solve(e_mat.T)
            schur = e_mat @ self.h_et
            shift = 1e-13 * max(float(np.max(np.abs(np.diag(schur)))), 1e-300)
            self.schur = la.cho_factor(schur + shift * np.eye(schur.shape[0]), lower=True)

    def _solve(self, rhs: NDArray[np.float64]) -> NDArray[np.float64]:
        """H⁻¹ rhs (rhs of shape (nx,) or (nx, k))."""
        band = self.band
        if band.dense:
            return la.cho_solve(self.factor, rhs, check_finite=False)
        out = np.empty_like(rhs)
        out[band.order] = la.cho_solve_banded(
            (self.factor, True), rhs[band.order], check_finite=False
        )
        return out

    def solve(
        self, rhs: NDArray[np.float64], r_e: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Δx and Δν of [H Eᵀ; E 0] (Δx, Δν) = (rhs, −r_e)."""
        dx = self._solve(rhs)
        if not self.e_mat.shape[0]:
            return dx, np.zeros(0)
        dnu = la.cho_solve(self.schur, r_e + self.e_mat @ dx, check_finite=False)
        return dx - self.h_et @ dnu, dnu


def _iterate(pr: _Problem, tolerance: float, max_iterations: int) -> JointSolution:
    """Mehrotra's predictor-corrector from :class:`_State`'s start (the loops compiled:
    :mod:`nearopt.timing._joint_kernels`)."""
    from . import _joint_kernels as kernels

    st, w = _State(pr), _Work(pr)
    csr = (pr.mat.indptr, pr.mat.indices, pr.mat.data)
    sides = (st.s_hi, st.s_lo, st.y_hi, st.y_lo)
    finite = (pr.fin_lo, pr.fin_hi)
    energy = (pr.t_count, pr.t_scale, pr.u0, pr.t_weight, pr.t_seg, pr.ds, pr.z_scale)
    energy = (*energy, pr.ends, pr.lin)
    for iteration in range(1, max_iterations + 1):
        f, gap, worst, rd_max = kernels.assemble(
            st.x, st.nu, *sides, *csr, pr.lo, pr.hi, *finite, pr.e_dense, pr.e_rhs,
            *energy, pr.f_scale, pr.nz, pr.group_start, pr.group_rows, pr.gram,
            w.newton, w.grad, w.r_hi, w.r_lo, w.r_e, w.r_d,
        )  # fmt: skip
        if not (np.isfinite(f) and np.isfinite(gap) and np.isfinite(rd_max)):
            return _answer(pr, st, False, iteration, "the iterate is not finite")
        if gap <= tolerance and worst <= tolerance and rd_max <= tolerance:
            return _answer(pr, st, True, iteration - 1, f"converged in {iteration - 1} iterations")
        try:
            system = _Newton(w.newton, pr.e_dense, pr.band)
        except la.LinAlgError:
            return _answer(pr, st, False, iteration, "the Newton matrix is singular")
        np.multiply(st.s_hi, st.y_hi, out=w.rc_hi)  # the predictor: targets s y → 0
        np.multiply(st.s_lo, st.y_lo, out=w.rc_lo)
        _, _, longest, halving = _direction(pr, st, w, system, w.affine)
        a_aff = min(1.0, longest, halving)
        mu = gap / pr.sides
        mu_aff = kernels.gap_after(a_aff, *sides, *w.affine) / pr.sides
        kernels.corrector_targets(
            *sides, *w.affine, *finite, (mu_aff / mu) ** 3 * mu, w.rc_hi, w.rc_lo
        )
        dx, dnu, longest, halving = _direction(pr, st, w, system, w.step)
        alpha = min(1.0, STEP_TO_BOUNDARY * longest, halving)
        st.x += alpha * dx
        st.nu += alpha * dnu
        for v, dv in zip(sides, w.step, strict=True):  # (Δs_hi, Δs_lo, Δy_hi, Δy_lo)
            v += alpha * dv
    return _answer(pr, st, False, max_iterations, f"no convergence in {max_iterations} iterations")


def _direction(
    pr: _Problem, st: _State, w: _Work, system: _Newton, out: list[NDArray[np.float64]]
) -> tuple[NDArray[np.float64], NDArray[np.float64], float, float]:
    """Δx, Δν (and Δs_hi, Δs_lo, Δy_hi, Δy_lo into ``out``) for the complementarity targets
    s y − rc in ``w``; the longest step to the slacks' and multipliers' boundary and the
    longest that no more than halves any z."""
    from . import _joint_kernels as kernels

    csr = (pr.mat.indptr, pr.mat.indices, pr.mat.data)
    sides = (st.s_hi, st.s_lo, st.y_hi, st.y_lo)
    residuals = (w.r_hi, w.r_lo, pr.fin_lo, pr.fin_hi)
    kernels.newton_rhs(w.rc_hi, w.rc_lo, *sides, *residuals, w.r_d, *csr, w.rhs)
    dx, dnu = system.solve(w.rhs, w.r_e)
    targets = (w.rc_hi, w.rc_lo, *sides, *residuals)
    longest, halving = kernels.directions(dx, *targets, *csr, st.x, pr.nz, *out)
    return dx, dnu, longest, halving


class _Work:
    """The arrays one iteration fills: the Newton matrix, ∇F, the residuals, the right-hand
    side, the complementarity targets and the directions (Δs_hi, Δs_lo, Δy_hi, Δy_lo) of the
    predictor and of the step."""

    def __init__(self, pr: _Problem) -> None:
        nx, m = pr.nx, pr.lo.size
        self.newton = np.empty((pr.band.kd + 1, nx))
        self.grad, self.r_d, self.rhs = np.empty((3, nx))
        self.r_hi, self.r_lo, self.rc_hi, self.rc_lo = np.empty((4, m))
        self.r_e = np.empty(pr.e_rhs.size)
        self.affine = list(np.empty((4, m)))
        self.step = list(np.empty((4, m)))


def _answer(
    pr: _Problem, st: _State, converged: bool, iterations: int, message: str
) -> JointSolution:
    return JointSolution(
        z=np.maximum(st.x[: pr.nz] * pr.z_scale, 0.0),
        p=st.x[pr.nz :] * pr.p_scale,
        objective=pr.cost(st.x),
        converged=converged,
        iterations=iterations,
        message=message,
    )
