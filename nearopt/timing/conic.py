"""Stage 1's convex problem for f0 = 1 + Σ w_i u_i² as a second-order cone program (Clarabel).

With c_k ≤ √b_k (tight at the optimum) and y_k = c_k + c_{k+1} (c_0 = c_N = 0), the segment time is
Δt_k = 2Δσ_k / y_k and the discretised cost Σ Δt_k (1 + ½ Σ_i w_i (u_{k⁺,i}² + u_{(k+1)⁻,i}²)) is

    minimise Σ t_k + e_k   s.t.  c_k² ≤ b_k,  t_k y_k ≥ 2Δσ_k,
                                 e_k y_k ≥ Δσ_k Σ_i w_i (u_{k⁺,i}² + u_{(k+1)⁻,i}²),

with the rows of :class:`~nearopt.timing.Discretisation` (torque, acceleration, speed) as linear
constraints. Rotated cones x·y ≥ ‖v‖² are written as ‖(2v, x − y)‖ ≤ x + y.

:func:`solve_conic` takes the rows over the variables (z, p): z = b_1 … b_{N−1} and, optionally,
further variables p that enter the rows and the torques linearly (stage 2 moves the path by p).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np
import scipy.sparse as sp

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from .discretisation import LinearRows

__all__ = ["ConicSolution", "solve_conic", "is_solved"]


class ConicSolution(NamedTuple):
    """Clarabel's answer.

    Attributes
    ----------
    z
        b at the free knots, shape (N−1,) (clipped at 0).
    p
        The further variables, shape (P,).
    objective
        The optimal value (the discretised cost of the model).
    status
        Clarabel's ``SolverStatus``.
    iterations
        Interior-point iterations.
    """

    z: NDArray[np.float64]
    p: NDArray[np.float64]
    objective: float
    status: object
    iterations: int


def is_solved(status: object) -> bool:
    """Whether a Clarabel status is an optimal (or almost optimal) solution."""
    import clarabel

    return status in (clarabel.SolverStatus.Solved, clarabel.SolverStatus.AlmostSolved)


def solve_conic(
    ds: NDArray[np.float64],
    weights: NDArray[np.float64],
    rows: LinearRows,
    torque: tuple[sp.spmatrix, NDArray[np.float64]],
    z_upper: NDArray[np.float64],
    *,
    p_bounds: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None,
    torque_limits: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None,
    tolerance: float = 1e-9,
    time_limit: float = np.inf,
    b_ends: tuple[float, float] = (0.0, 0.0),
    max_duration: float | None = None,
    price: NDArray[np.float64] | None = None,
) -> ConicSolution:
    """Solve the SOCP of this module's docstring.

    Parameters
    ----------
    ds
        Δσ_k of the N segments, shape (N,).
    weights
        w_i of the cost, shape (n,) (all 0: time-optimal).
    rows
        ``lower ≤ M (z, p) ≤ upper``, M of shape (R, N − 1 + P).
    torque
        (T, u0): the torque samples u = T (z, p) + u0, joint-major (row i·2N + r as in
        :class:`~nearopt.timing.Discretisation`), T of shape (n·2N, N − 1 + P).
    z_upper
        Upper bounds on z (inf where none), shape (N − 1,); z ≥ 0 always.
    p_bounds
        Lower and upper bounds on p, each (P,), or None when there is no p.
    torque_limits
        Lower and upper limits of the torque samples, each (n·2N,) (±inf where none), when they
        are not among ``rows``. The torques are then variables v = T (z, p) + u0 of their own,
        bounded directly: with p, T's rows are dense in p, and each is then held once instead of
        in the cost's cone and both sides of a limit (a much sparser problem). Without an energy
        term only the torques with a finite limit are variables (the others have no role).
    tolerance
        Clarabel's gap and feasibility tolerances.
    time_limit
        Clarabel's time limit [s].
    b_ends
        The fixed b_0 and b_N (0 at rest): their √b enter y_0 and y_{N−1} as constants (the
        rows' terms in them are in ``rows`` and ``torque`` already).
    max_duration
        t_e = Σ t_k ≤ this [s] (t_k ≥ the segment's time), or None.
    price
        A linear term Σ price_k z_k added to the cost, shape (N − 1,), or None.
    """
    import clarabel

    big_n, nz = ds.size, ds.size - 1
    n_p = 0 if p_bounds is None else p_bounds[0].size
    n = torque[0].shape[0] // (2 * big_n)
    energy = bool(np.any(weights > 0))
    if torque_limits is not None and not energy:  # only the torques held are needed
        held = np.flatnonzero(np.isfinite(torque_limits[0]) | np.isfinite(torque_limits[1]))
        torque = (sp.csr_matrix(torque[0])[held], np.asarray(torque[1])[held])
        torque_limits = (torque_limits[0][held], torque_limits[1][held])
    at = _Columns(nz, n_p, big_n, 0 if torque_limits is None else torque_limits[0].size)
    pb = _Builder(big_n)
    _linear_block(pb, clarabel, at, rows, z_upper, p_bounds, torque_limits)
    _root_block(pb, clarabel, at)
    roots = np.sqrt(np.asarray(b_ends, dtype=float))
    _time_block(pb, clarabel, at, ds, roots)
    q_vec = np.zeros(at.nx)
    q_vec[at.it : at.it + big_n] = 1.0
    if price is not None:
        q_vec[at.iz : at.iz + nz] = price
    if energy:
        _energy_block(pb, clarabel, at, ds, weights, torque, n, roots)
        q_vec[at.ie : at.ie + big_n] = 1.0
    else:  # no energy: pin e = 0
        pb.put(np.arange(big_n), at.ie + pb.seg, np.ones(big_n))
        pb.close(np.zeros(big_n), [clarabel.ZeroConeT(big_n)], big_n)
    if max_duration is not None:  # Σ t_k ≤ T
        pb.put(np.zeros(big_n), at.it + pb.seg, np.ones(big_n))
        pb.close(np.array([float(max_duration)]), [clarabel.NonnegativeConeT(1)], 1)
    if at.nv:  # v = T (z, p) + u0 ⇔ T (z, p) − v = −u0
        tt = sp.coo_matrix(torque[0])
        pb.put(tt.row, tt.col, tt.data)
        pb.put(np.arange(at.nv), at.iv + np.arange(at.nv), -np.ones(at.nv))
        pb.close(-np.asarray(torque[1], dtype=float), [clarabel.ZeroConeT(at.nv)], at.nv)
    a_all = pb.matrix(at.nx)
    nx, iz, ip, nz = at.nx, at.iz, at.ip, at.nz
    rhs, cones = pb.rhs, pb.cones
    p_mat = sp.csc_matrix((nx, nx))
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.tol_gap_abs = settings.tol_gap_rel = settings.tol_feas = tolerance
    settings.max_iter = 200
    if np.isfinite(time_limit):
        settings.time_limit = float(max(time_limit, 1e-3))  # Clarabel then stops with MaxTime
    solver = clarabel.DefaultSolver(p_mat, q_vec, a_all, np.concatenate(rhs), cones, settings)
    sol = solver.solve()
    x = np.asarray(sol.x)
    return ConicSolution(
        z=np.maximum(x[iz : iz + nz], 0.0),
        p=x[ip : ip + n_p].copy(),
        objective=float(sol.obj_val),
        status=sol.status,
        iterations=int(sol.iterations),
    )


class _Columns:
    """Where each variable lies in x = (z, p, c, t, e, v): c = √b at the free knots, t and e
    the segments' time and energy bounds, v the torque samples when they are variables."""

    def __init__(self, nz: int, n_p: int, big_n: int, nv: int) -> None:
        self.nz, self.n_p, self.nv = nz, n_p, nv
        self.iz, self.ip = 0, nz
        self.ic = nz + n_p
        self.it = self.ic + nz
        self.ie = self.it + big_n
        self.iv = self.ie + big_n
        self.nx = self.iv + nv


class _Builder:
    """Clarabel's A x + s = b, s in the cones, built block after block: triplets, right-hand
    sides and cones in order."""

    def __init__(self, big_n: int) -> None:
        self.trip_r: list[NDArray[np.int64]] = []
        self.trip_c: list[NDArray[np.int64]] = []
        self.trip_v: list[NDArray[np.float64]] = []
        self.rhs: list[NDArray[np.float64]] = []
        self.cones: list[object] = []
        self.row0 = 0
        self.seg = np.arange(big_n)
        seg = self.seg
        # y_k = c_k + c_{k+1} (c_0 = c_N = 0): the c columns of segment k (offset by ic)
        self.y_seg = np.concatenate([seg[seg >= 1], seg[seg <= big_n - 2]])
        self.y_col = np.concatenate([seg[seg >= 1] - 1, seg[seg <= big_n - 2]])

    def put(self, r: NDArray, c: NDArray, v: NDArray) -> None:
        """Entries of the current block (rows counted from its first)."""
        self.trip_r.append(np.asarray(r, dtype=np.int64) + self.row0)
        self.trip_c.append(np.asarray(c, dtype=np.int64))
        self.trip_v.append(np.asarray(v, dtype=float))

    def close(self, rhs: NDArray, cones: list[object], rows: int) -> None:
        """End the current block: its right-hand side, its cones, its number of rows."""
        self.rhs.append(rhs)
        self.cones += cones
        self.row0 += rows

    def cone_xy(self, width: int, var: int, ic: int) -> None:
        """Rows 0 and last of per-segment cones ‖(…, x − y)‖ ≤ x + y with x = var_k."""
        big_n = self.seg.size
        self.put(width * self.seg, var + self.seg, -np.ones(big_n))
        self.put(width * self.y_seg, self.y_col + ic, -np.ones(self.y_seg.size))
        self.put(width * self.seg + width - 1, var + self.seg, -np.ones(big_n))
        self.put(width * self.y_seg + width - 1, self.y_col + ic, np.ones(self.y_seg.size))

    def matrix(self, nx: int) -> sp.csc_matrix:
        return sp.csc_matrix(
            (
                np.concatenate(self.trip_v),
                (np.concatenate(self.trip_r), np.concatenate(self.trip_c)),
            ),
            shape=(self.row0, nx),
        )


def _linear_block(
    pb: _Builder,
    clarabel: object,
    at: _Columns,
    rows: LinearRows,
    z_upper: NDArray[np.float64],
    p_bounds: tuple[NDArray[np.float64], NDArray[np.float64]] | None,
    torque_limits: tuple[NDArray[np.float64], NDArray[np.float64]] | None,
) -> None:
    """1. linear rows (finite sides), z ≥ 0, z ≤ z_upper, p (and v) within their bounds: each
    row divided by its largest finite limit (or its largest coefficient where that is 0), as the
    kernel does: rows whose coefficients are ∝ 1/Δσ would otherwise set Clarabel's feasibility
    tolerance far above the limits' own scale."""
    nz, iz = at.nz, at.iz
    rhs: list[NDArray[np.float64]] = []
    mat = rows.matrix.tocoo()
    row_scale = np.maximum(
        np.where(np.isfinite(rows.upper), np.abs(rows.upper), 0.0),
        np.where(np.isfinite(rows.lower), np.abs(rows.lower), 0.0),
    )
    if mat.nnz:
        largest = np.zeros(row_scale.size)
        np.maximum.at(largest, mat.row, np.abs(mat.data))
        row_scale = np.where(row_scale > 0.0, row_scale, largest)
    row_scale = np.where(row_scale > 0.0, row_scale, 1.0)
    count = 0
    for sign, side in ((1.0, rows.upper), (-1.0, -rows.lower)):
        finite = np.isfinite(side)
        index = np.cumsum(finite) - 1  # row of each finite side among them
        keep = finite[mat.row]
        pb.put(
            count + index[mat.row[keep]],
            mat.col[keep],
            sign * mat.data[keep] / row_scale[mat.row[keep]],
        )
        rhs.append(side[finite] / row_scale[finite])
        count += int(finite.sum())
    pb.put(count + np.arange(nz), iz + np.arange(nz), -np.ones(nz))
    rhs.append(np.zeros(nz))
    count += nz
    finite = np.flatnonzero(np.isfinite(z_upper))
    pb.put(count + np.arange(finite.size), iz + finite, np.ones(finite.size))
    rhs.append(z_upper[finite])
    count += finite.size
    bounded = [(at.ip, p_bounds)] if at.n_p else []
    bounded += [(at.iv, torque_limits)] if at.nv else []
    for first, (low, high) in bounded:
        for sign, side in ((1.0, high), (-1.0, -low)):
            finite = np.flatnonzero(np.isfinite(side))
            pb.put(count + np.arange(finite.size), first + finite, sign * np.ones(finite.size))
            rhs.append(side[finite])
            count += finite.size
    pb.rhs += rhs[:-1]
    pb.close(rhs[-1], [clarabel.NonnegativeConeT(count)], count)


def _root_block(pb: _Builder, clarabel: object, at: _Columns) -> None:
    """2. c_k² ≤ b_k ⇔ ‖(2c_k, b_k − 1)‖ ≤ b_k + 1, knots 1 … N−1."""
    nz = at.nz
    kn = np.arange(nz)
    pb.put(3 * kn, at.iz + kn, -np.ones(nz))
    pb.put(3 * kn + 1, at.ic + kn, -2.0 * np.ones(nz))
    pb.put(3 * kn + 2, at.iz + kn, -np.ones(nz))
    pb.close(np.tile([1.0, 0.0, -1.0], nz), [clarabel.SecondOrderConeT(3)] * nz, 3 * nz)


def _time_block(
    pb: _Builder,
    clarabel: object,
    at: _Columns,
    ds: NDArray[np.float64],
    roots: NDArray[np.float64],
) -> None:
    """3. t_k y_k ≥ 2Δσ_k ⇔ ‖(2√(2Δσ_k), t_k − y_k)‖ ≤ t_k + y_k."""
    big_n = ds.size
    pb.cone_xy(3, at.it, at.ic)
    rhs = np.column_stack([np.zeros(big_n), 2.0 * np.sqrt(2.0 * ds), np.zeros(big_n)])
    _root_ends(rhs, roots)
    pb.close(rhs.ravel(), [clarabel.SecondOrderConeT(3)] * big_n, 3 * big_n)


def _root_ends(rhs: NDArray[np.float64], roots: NDArray[np.float64]) -> None:
    """The fixed √b_0 and √b_N in y_0 and y_{N−1} of the cones ‖(…, x − y)‖ ≤ x + y whose
    right-hand sides are ``rhs`` (one row per segment): + in the first entry, − in the last."""
    for k, root in ((0, roots[0]), (-1, roots[1])):
        rhs[k, 0] += root
        rhs[k, -1] -= root


def _energy_block(
    pb: _Builder,
    clarabel: object,
    at: _Columns,
    ds: NDArray[np.float64],
    weights: NDArray[np.float64],
    torque: tuple[sp.spmatrix, NDArray[np.float64]],
    n: int,
    roots: NDArray[np.float64],
) -> None:
    """4. e_k y_k ≥ Δσ_k Σ w (u_{k+}² + u_{(k+1)-}²) ⇔ ‖(2v, e_k − y_k)‖ ≤ e_k + y_k,
    v = √(Δσ w) u."""
    big_n, nv = ds.size, at.nv
    width = 2 + 2 * n
    pb.cone_xy(width, at.ie, at.ic)
    joint_all, r_all = np.divmod(np.arange(n * 2 * big_n), 2 * big_n)
    k_all = np.where(r_all < big_n, r_all, r_all - big_n)
    slot_all = np.where(r_all < big_n, joint_all, n + joint_all)
    scale_all = 2.0 * np.sqrt(ds[k_all] * weights[joint_all])
    e_rhs = np.zeros((big_n, width))
    if nv:
        pb.put(width * k_all + 1 + slot_all, at.iv + np.arange(nv), -scale_all)
    else:
        tt = sp.coo_matrix(torque[0])
        joint, r = np.divmod(tt.row, 2 * big_n)
        k_of = np.where(r < big_n, r, r - big_n)
        slot = np.where(r < big_n, joint, n + joint)
        pb.put(width * k_of + 1 + slot, tt.col, -2.0 * np.sqrt(ds[k_of] * weights[joint]) * tt.data)
        e_rhs[k_all, 1 + slot_all] = scale_all * torque[1]
    _root_ends(e_rhs, roots)
    pb.close(e_rhs.ravel(), [clarabel.SecondOrderConeT(width)] * big_n, width * big_n)
