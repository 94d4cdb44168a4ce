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
        in the cost's cone and both sides of a limit (a much sparser problem).
    tolerance
        Clarabel's gap and feasibility tolerances.
    time_limit
        Clarabel's time limit [s].
    """
    import clarabel

    big_n, nz = ds.size, ds.size - 1
    n_p = 0 if p_bounds is None else p_bounds[0].size
    n = torque[0].shape[0] // (2 * big_n)
    iz, ip = 0, nz
    ic = nz + n_p
    it, ie = ic + nz, ic + nz + big_n
    energy = bool(np.any(weights > 0))
    iv = ie + big_n
    nv = 0 if torque_limits is None else n * 2 * big_n
    nx = iv + nv
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

    # 1. linear rows (finite sides), z ≥ 0, z ≤ z_upper, p within its bounds: A x + s = rhs, s ≥ 0
    # each row divided by its largest finite limit (or its largest coefficient where that is 0),
    # as the kernel does: rows whose coefficients are ∝ 1/Δσ would otherwise set Clarabel's
    # feasibility tolerance far above the limits' own scale
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
        put(
            count + index[mat.row[keep]],
            mat.col[keep],
            sign * mat.data[keep] / row_scale[mat.row[keep]],
        )
        rhs.append(side[finite] / row_scale[finite])
        count += int(finite.sum())
    put(count + np.arange(nz), iz + np.arange(nz), -np.ones(nz))
    rhs.append(np.zeros(nz))
    count += nz
    finite = np.flatnonzero(np.isfinite(z_upper))
    put(count + np.arange(finite.size), iz + finite, np.ones(finite.size))
    rhs.append(z_upper[finite])
    count += finite.size
    bounded = [(ip, p_bounds)] if n_p else []
    bounded += [(iv, torque_limits)] if nv else []
    for first, (low, high) in bounded:
        for sign, side in ((1.0, high), (-1.0, -low)):
            finite = np.flatnonzero(np.isfinite(side))
            put(count + np.arange(finite.size), first + finite, sign * np.ones(finite.size))
            rhs.append(side[finite])
            count += finite.size
    cones: list[object] = [clarabel.NonnegativeConeT(count)]
    row0 += count

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
        joint_all, r_all = np.divmod(np.arange(n * 2 * big_n), 2 * big_n)
        k_all = np.where(r_all < big_n, r_all, r_all - big_n)
        slot_all = np.where(r_all < big_n, joint_all, n + joint_all)
        scale_all = 2.0 * np.sqrt(ds[k_all] * weights[joint_all])
        e_rhs = np.zeros((big_n, width))
        if nv:
            put(width * k_all + 1 + slot_all, iv + np.arange(nv), -scale_all)
        else:
            tt = sp.coo_matrix(torque[0])
            joint, r = np.divmod(tt.row, 2 * big_n)
            k_of = np.where(r < big_n, r, r - big_n)
            slot = np.where(r < big_n, joint, n + joint)
            put(
                width * k_of + 1 + slot, tt.col, -2.0 * np.sqrt(ds[k_of] * weights[joint]) * tt.data
            )
            e_rhs[k_all, 1 + slot_all] = scale_all * torque[1]
        rhs.append(e_rhs.ravel())
        cones += [clarabel.SecondOrderConeT(width)] * big_n
        row0 += width * big_n
        q_vec[ie : ie + big_n] = 1.0
    else:  # no energy: pin e = 0
        put(np.arange(big_n), ie + seg, np.ones(big_n))
        rhs.append(np.zeros(big_n))
        cones.append(clarabel.ZeroConeT(big_n))
        row0 += big_n
    if nv:  # v = T (z, p) + u0 ⇔ T (z, p) − v = −u0
        tt = sp.coo_matrix(torque[0])
        put(tt.row, tt.col, tt.data)
        put(np.arange(nv), iv + np.arange(nv), -np.ones(nv))
        rhs.append(-np.asarray(torque[1], dtype=float))
        cones.append(clarabel.ZeroConeT(nv))
        row0 += nv
    a_all = sp.csc_matrix(
        (np.concatenate(trip_v), (np.concatenate(trip_r), np.concatenate(trip_c))), shape=(row0, nx)
    )
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
