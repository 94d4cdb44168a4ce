"""A primal-dual interior-point method for convex programs whose rows and objective terms each
touch a few consecutive variables (a window of ``width``): the jerk-limited timing's convex
restrictions (:mod:`nearopt.timing.jerk`), whose Newton matrix is then banded.

The program, over z ∈ Rⁿ:

    minimise   F(z) = lin·z + Σ_p ω_p (c0_p + Σ_q w_q (α_pq·z + g_pq)²) / √(ℓ_p·z)
    subject to a_j·z + e_j √(ℓ_j·z) ≤ h_j   (e_j ≤ 0: every row convex)

Each term (u/√v with u a convex quadratic, v linear) is convex, so is each row. The method
(Mehrotra's predictor-corrector, as in Nocedal & Wright, *Numerical Optimization*, §14.2 and
§19.3, as stage 1's kernel :mod:`nearopt.timing.interior`):

* slack s_j > 0 and multiplier y_j > 0 per row; the start z need not satisfy the rows (s starts
  at max(−c_j(z), 0.1), y at 1), but every ℓ·z of a term or a row must be positive;
* the Newton matrix ∇²F + Σ y_j ∇²c_j + Jᵀ (Y/S) J is banded (half-bandwidth width − 1): one
  banded Cholesky factorisation (compiled) and two solves per iteration, O((n + rows)·width²);
* one step length for primal and dual variables (the objective is not linear), 0.995 of the way
  to the boundary of a slack or multiplier, and no ℓ·z below a quarter of its value in one step;
* F is scaled to 1 at the start; it stops when the duality measure Σ s_j y_j and the gradient of
  the Lagrangian are below ``tolerance`` relative to F, and every row's residual below
  ``tolerance`` (rows are scaled so that their largest coefficient is 1);
* a program of a sequence (the jerk-limited timing's convex restrictions) may leave out the
  rows far from binding at the last optimum and put back those its optimum breaks
  (:func:`solve_banded`'s ``reference``): 80–90 % of the rows of a later restriction are
  slack, and the cost of an iteration is about proportional to the rows.

The loops are compiled by numba (:mod:`nearopt.timing._banded_kernels`, cached beside the source).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

__all__ = ["BandedProgram", "BandedSolution", "solve_banded", "windows"]


class BandedProgram(NamedTuple):
    """The program of the module docstring in window form: each row (term) j starts at variable
    ``start[j]`` and its coefficients ``[j, 0:width]`` apply to z[start : start + width]."""

    r_start: NDArray[np.int64]
    r_a: NDArray[np.float64]  # (rows, width)
    r_e: NDArray[np.float64]  # (rows,) ≤ 0
    r_ell: NDArray[np.float64]  # (rows, width)
    r_h: NDArray[np.float64]
    t_start: NDArray[np.int64]
    t_ell: NDArray[np.float64]  # (terms, width)
    t_omega: NDArray[np.float64]
    t_c0: NDArray[np.float64]
    t_alpha: NDArray[np.float64]  # (terms, squares, width)
    t_g: NDArray[np.float64]  # (terms, squares)
    weights: NDArray[np.float64]  # (squares,)
    lin: NDArray[np.float64]  # (n,)


class BandedSolution(NamedTuple):
    """z, whether it converged, the Newton iterations, F(z), a message and the largest row
    residual |c + s| at z (the rows scaled to a largest coefficient of 1; with s ≥ 0, how far
    z may lie beyond a row)."""

    z: NDArray[np.float64]
    converged: bool
    iterations: int
    value: float
    message: str
    primal: float = np.inf


def windows(
    matrices: list[sp.spmatrix], width: int, start: NDArray[np.int64] | None = None
) -> tuple[NDArray[np.int64], list[NDArray[np.float64]]]:
    """Rows of several matrices with the same rows (a row's window spans the columns of all of
    them) in window form: each row's first column and dense (rows, width) coefficients.
    ``start`` forces the windows' first columns (a ValueError if a column falls outside)."""
    csr = [sp.csr_matrix(a) for a in matrices]
    for a in csr:
        a.sum_duplicates()  # (and sorts each row's columns)
    rows = csr[0].shape[0]
    if start is None:
        none = np.iinfo(np.int64).max
        start = np.full(rows, none, dtype=np.int64)
        for a in csr:
            filled = np.diff(a.indptr) > 0
            first = a.indices[a.indptr[:-1][filled]]
            start[filled] = np.minimum(start[filled], first)
        start[start == none] = 0
        start = np.minimum(start, max(csr[0].shape[1] - width, 0))
    dense = []
    for a in csr:
        r = np.repeat(np.arange(rows), np.diff(a.indptr))
        offset = a.indices - start[r]
        if offset.size and (offset.min() < 0 or offset.max() >= width):
            raise ValueError(f"a row spans more than {width} columns")
        out = np.zeros((rows, width))
        out[r, offset] = a.data
        dense.append(out)
    return start, dense


def solve_banded(
    program: BandedProgram,
    z0: NDArray[np.float64],
    tolerance: float = 1e-9,
    max_iterations: int = 200,
    reference: NDArray[np.float64] | None = None,
    change: NDArray[np.float64] | None = None,
) -> BandedSolution:
    """The program's optimum from z0 (every ℓ·z0 > 0).

    With a ``reference`` (the last optimum of a program much like this one) and the ``change``
    of z that led to it (from the optimum before), the rows far from binding at the reference
    are left out: those whose slack exceeds :data:`SCREEN` times the change of their value
    that ``change`` would make (Σ |a_j| |Δz|) plus a share of their bound. The smaller program
    is solved, and the rows it breaks (c_j > ``tolerance``) are put back with those near
    binding at its optimum, until it holds every row (at most :data:`ROUNDS` times, then the
    whole program): an optimum of fewer rows that holds all of them is the program's."""
    if reference is not None and change is not None:
        screened = _screened(program, z0, tolerance, max_iterations, reference, change)
        if screened is not None:
            return screened
    return _solve(program, z0, tolerance, max_iterations)


SCREEN = 3.0
ROUNDS = 3
BOUND_SHARE = 0.05


def _screened(
    p: BandedProgram,
    z0: NDArray[np.float64],
    tolerance: float,
    max_iterations: int,
    reference: NDArray[np.float64],
    change: NDArray[np.float64],
) -> BandedSolution | None:
    """:func:`solve_banded` on the rows near binding; None where the whole program is needed."""
    width = p.r_a.shape[1]
    reach = np.einsum("jw,jw->j", np.abs(p.r_a), np.abs(_gather(change, p.r_start, width)))
    value, size = _rows_at(p, reference)
    homogeneous = p.r_h == 0.0  # (orderings of the variables, not limits: always kept)
    keep = homogeneous | ~(value < -(SCREEN * reach + BOUND_SHARE * size))
    for _ in range(ROUNDS):
        if np.all(keep):
            return None
        part = p._replace(
            r_start=p.r_start[keep], r_a=p.r_a[keep], r_e=p.r_e[keep], r_ell=p.r_ell[keep],
            r_h=p.r_h[keep],
        )  # fmt: skip
        solution = _solve(part, z0, tolerance, max_iterations)
        if not solution.converged:
            return None
        value, size = _rows_at(p, solution.z)
        broken = ~keep & ~(value <= tolerance)
        if not np.any(broken):
            message = f"{solution.message}; {int(keep.sum())} of {keep.size} rows near binding"
            return solution._replace(message=message)
        keep |= broken | ~(value < -(SCREEN * reach + BOUND_SHARE * size))
    return None


def _rows_at(p: BandedProgram, z: NDArray[np.float64]) -> tuple[NDArray, NDArray]:
    """Each row's c_j(z) = a_j·z + e_j √(ℓ_j·z) − h_j (NaN where ℓ_j·z < 0) and its size
    |h_j| + |e_j| √(ℓ_j·z)."""
    window = _gather(z, p.r_start, p.r_a.shape[1])
    with np.errstate(invalid="ignore"):
        root = np.sqrt(np.einsum("jw,jw->j", p.r_ell, window))
    root = np.where(p.r_e != 0.0, root, 0.0)
    value = np.einsum("jw,jw->j", p.r_a, window) + p.r_e * root - p.r_h
    size = np.abs(p.r_h)
    return value, size + np.abs(p.r_e) * root


def _solve(
    program: BandedProgram, z0: NDArray[np.float64], tolerance: float, max_iterations: int
) -> BandedSolution:
    """The kernel on the whole program."""
    from ._banded_kernels import CONVERGED, NOT_FINITE, SINGULAR, iterate

    p = program
    z = np.array(z0, dtype=float)
    m = p.r_h.size
    # c_j(z0), for the slacks' start
    a_dot = np.einsum("jw,jw->j", p.r_a, _gather(z, p.r_start, p.r_a.shape[1]))
    root = np.einsum("jw,jw->j", p.r_ell, _gather(z, p.r_start, p.r_a.shape[1]))
    c = a_dot + p.r_e * np.sqrt(np.maximum(root, 0.0)) - p.r_h
    s = np.maximum(-c, 0.1)
    y = np.ones(m)
    f0 = _value(p, z)
    if not (np.isfinite(f0) and f0 > 0.0):
        return BandedSolution(z, False, 0, f0, "the objective is not positive at the start")
    status, iterations, value, gap, dual, primal = iterate(
        z, s, y, p.r_start, p.r_a, p.r_e, p.r_ell, p.r_h, p.t_start, p.t_ell, p.t_omega,
        p.t_c0, p.t_alpha, p.t_g, p.weights, p.lin, 1.0 / f0, tolerance, max_iterations,
    )  # fmt: skip
    messages = {
        CONVERGED: "converged",
        SINGULAR: "the Newton matrix is singular",
        NOT_FINITE: "a step is not finite",
    }
    message = messages.get(status, f"not converged in {max_iterations} iterations")
    message += f" (Σ s y {gap:.1e}, |∇L| {dual:.1e}, |c + s| {primal:.1e})"
    return BandedSolution(
        z, status == CONVERGED, int(iterations), float(value), message, float(primal)
    )


def _gather(z: NDArray, start: NDArray, width: int) -> NDArray:
    """z[start_j : start_j + width] per row, shape (rows, width) (past the end: z's last)."""
    padded = np.concatenate([z, np.full(width - 1, z[-1])])
    return np.lib.stride_tricks.sliding_window_view(padded, width)[start]


def _value(p: BandedProgram, z: NDArray) -> float:
    width = p.t_ell.shape[1]
    window = _gather(z, p.t_start, width)
    v = np.einsum("pw,pw->p", p.t_ell, window)
    r = np.einsum("pqw,pw->pq", p.t_alpha, window) + p.t_g
    u = p.t_c0 + np.sum(p.weights[None, :] * r**2, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        return float(p.lin @ z + np.sum(p.t_omega * u / np.sqrt(v)))
