"""The compiled loops of :mod:`nearopt.timing.joint` (numba): one Newton iteration's residuals,
Newton matrix and directions, over the rows of a CSR matrix (columns sorted in each row).

The rows are a_r x ∈ [lo_r, hi_r]; a side is open where ``fin_lo`` / ``fin_hi`` is false (its
slack 1 and multiplier 0 then, never changed). The first ``t_count`` rows are the torque rows of
the energy term (u_r = t_scale_r · a_r x + u0_r). x = (z / z_scale, p / p_scale); knot k + 1 of
the grid is z index k. Compiled on first use and cached beside this file, as
:mod:`nearopt.timing._kernels`.
"""

from __future__ import annotations

import numpy as np

from ._kernels import cached_jit, inline_jit


@inline_jit(error_model="numpy")
def _lambdas(x, z_scale, nz):  # pragma: no cover - compiled
    """λ = √b at the free knots and its first two derivatives in x."""
    lam = np.empty(nz)
    dl = np.empty(nz)
    d2l = np.empty(nz)
    for j in range(nz):
        b = max(x[j] * z_scale[j], 0.0)
        lam[j] = np.sqrt(b)
        if lam[j] > 0.0:
            dl[j] = 0.5 * z_scale[j] / lam[j]
            d2l[j] = -0.25 * z_scale[j] * z_scale[j] / (lam[j] * lam[j] * lam[j])
        else:
            dl[j] = 0.0
            d2l[j] = 0.0
    return lam, dl, d2l


@inline_jit(error_model="numpy")
def _row_values(indptr, indices, data, x):  # pragma: no cover - compiled
    m = indptr.size - 1
    ax = np.zeros(m)
    for r in range(m):
        acc = 0.0
        for a in range(indptr[r], indptr[r + 1]):
            acc += data[a] * x[indices[a]]
        ax[r] = acc
    return ax


@inline_jit(error_model="numpy")
def _add(band, position, i, j, value):  # pragma: no cover - compiled
    """value at (i, j) of a symmetric matrix held as its lower band: the entry of the variables
    at places P = position[i] ≥ Q = position[j] is band[P − Q, Q] (LAPACK's lower band storage
    of the matrix in the places' order)."""
    pi, pj = position[i], position[j]
    if pi >= pj:
        band[pi - pj, pj] += value
    else:
        band[pj - pi, pi] += value


@inline_jit(error_model="numpy")
def _add_cross(newton, position, c, j, value):  # pragma: no cover - compiled
    """value at (c, j) and (j, c) of a symmetric matrix held as its lower band."""
    _add(newton, position, c, j, 2.0 * value if c == j else value)


@cached_jit(error_model="numpy")
def assemble(
    x, nu, s_hi, s_lo, y_hi, y_lo,
    indptr, indices, data, lo, hi, fin_lo, fin_hi,
    e_mat, e_rhs,
    t_count, t_scale, u0, t_weight, t_seg, ds, z_scale, lam_ends, lin, f_scale, nz,
    group_start, group_rows, gram, newton, grad, r_hi, r_lo, r_e, r_d,
):  # fmt: skip  # pragma: no cover - compiled
    """F, the residuals (into r_hi, r_lo, r_e, r_d), ∇F (into grad) and the Newton matrix
    ∇²F + Σ_r (y/s)_r a_r a_rᵀ (into ``newton``, zeroed here: its lower band in the order of
    ``position``, see :func:`_add`; ``gram``: :func:`gram_plan`'s arrays, the position first);
    returns
    (F, Σ s y, the largest row residual, the largest |r_d|)."""
    big_n = ds.size
    m = indptr.size - 1
    position = gram[0]
    ax = _row_values(indptr, indices, data, x)
    lam, dl, d2l = _lambdas(x, z_scale, nz)
    y = np.empty(big_n)
    for k in range(big_n):
        y[k] = (lam[k - 1] if k >= 1 else 0.0) + (lam[k] if k < nz else 0.0)
    y[0] += lam_ends[0]  # the fixed ends' λ (0 at rest)
    y[big_n - 1] += lam_ends[1]
    q = np.zeros(big_n)
    u = np.empty(t_count)
    for r in range(t_count):
        u[r] = t_scale[r] * ax[r] + u0[r]
        q[t_seg[r]] += 0.5 * t_weight[r] * u[r] * u[r]
    g = np.empty(big_n)
    f = 0.0
    for k in range(big_n):
        g[k] = f_scale * 2.0 * ds[k] * (1.0 + q[k]) / y[k]
        f += g[k]
    newton[:, :] = 0.0
    grad[:] = 0.0
    for c in range(x.size):  # F's linear term (a price on p), lin · x
        if lin[c] != 0.0:
            f += f_scale * lin[c] * x[c]
            grad[c] += f_scale * lin[c]
    for j in range(nz):  # ∂g/∂y and ∂²g/∂y² along λ of the two segments at knot j + 1
        gy = -g[j] / y[j] - g[j + 1] / y[j + 1]
        gyy0, gyy1 = 2.0 * g[j] / y[j] ** 2, 2.0 * g[j + 1] / y[j + 1] ** 2
        grad[j] = gy * dl[j]
        _add(newton, position, j, j, (gyy0 + gyy1) * dl[j] * dl[j] + gy * d2l[j])
        if j + 1 < nz:
            _add(newton, position, j + 1, j, gyy1 * dl[j] * dl[j + 1])
    d = np.empty(m)
    for r in range(m):
        d[r] = (y_hi[r] / s_hi[r] if fin_hi[r] else 0.0) + (y_lo[r] / s_lo[r] if fin_lo[r] else 0.0)
    for r in range(t_count):  # the energy: ∂g/∂u, ∂²g/∂u², ∂²g/∂u∂y along the torque rows
        k = t_seg[r]
        curvature = 2.0 * f_scale * ds[k] * t_weight[r] / y[k]
        slope = curvature * u[r]
        d[r] += curvature * t_scale[r] * t_scale[r]
        mixed = -slope / y[k] * t_scale[r]
        for a in range(indptr[r], indptr[r + 1]):
            c = indices[a]
            grad[c] += slope * t_scale[r] * data[a]
            if k >= 1:
                _add_cross(newton, position, c, k - 1, mixed * data[a] * dl[k - 1])
            if k < nz:
                _add_cross(newton, position, c, k, mixed * data[a] * dl[k])
    _gram(d, group_start, group_rows, gram, newton.reshape(-1))
    return _residuals(
        x, nu, s_hi, s_lo, y_hi, y_lo, indptr, indices, data, ax, lo, hi, fin_lo, fin_hi,
        e_mat, e_rhs, grad, r_hi, r_lo, r_e, r_d, f,
    )  # fmt: skip


@cached_jit(error_model="numpy")
def gram_plan(indptr, indices, data, group_start, group_rows, position):  # pragma: no cover
    """What Σ_r d_r a_r a_rᵀ needs of the rows, which do not change while one problem is
    solved (only d does): per group of rows (rows of a group share most of their columns), the
    union of its rows' columns (``count`` of them), its rows densely on that union (``dense``,
    group g's rows × count from ``dense_start[g]``) and where each entry of the union's lower
    triangle lies in the Newton matrix's lower band held flat (``flat``, from
    ``flat_start[g]``; see :func:`_add`). Returns (position, count, dense_start, dense,
    flat_start, flat)."""
    nx = position.size
    groups = group_start.size - 1
    local = np.full(nx, -1)  # a column's place in the group's union
    columns = np.empty(nx, dtype=np.int64)
    count = np.zeros(groups, dtype=np.int64)
    for g in range(groups):
        first, end = group_start[g], group_start[g + 1]
        count[g] = _union(indptr, indices, first, end, group_rows, local, columns)
        for a in range(count[g]):
            local[columns[a]] = -1
    dense_start = np.zeros(groups + 1, dtype=np.int64)
    flat_start = np.zeros(groups + 1, dtype=np.int64)
    for g in range(groups):
        rows = group_start[g + 1] - group_start[g]
        dense_start[g + 1] = dense_start[g] + rows * count[g]
        flat_start[g + 1] = flat_start[g] + count[g] * (count[g] + 1) // 2
    dense = np.zeros(dense_start[groups])
    flat = np.empty(flat_start[groups], dtype=np.int64)
    for g in range(groups):
        first, end, c = group_start[g], group_start[g + 1], count[g]
        _union(indptr, indices, first, end, group_rows, local, columns)
        for e in range(end - first):
            r = group_rows[first + e]
            for a in range(indptr[r], indptr[r + 1]):
                dense[dense_start[g] + e * c + local[indices[a]]] = data[a]
        k = flat_start[g]
        for a in range(c):
            pa = position[columns[a]]
            for b in range(a + 1):
                pb = position[columns[b]]
                flat[k] = (pa - pb) * nx + pb if pa >= pb else (pb - pa) * nx + pa
                k += 1
        for a in range(c):
            local[columns[a]] = -1
    return position, count, dense_start, dense, flat_start, flat


@inline_jit(error_model="numpy")
def _union(indptr, indices, first, end, group_rows, local, columns):  # pragma: no cover
    """The columns of rows group_rows[first:end] in order of first appearance (into
    ``columns``, their places into ``local``); returns their count."""
    count = 0
    for e in range(first, end):
        r = group_rows[e]
        for a in range(indptr[r], indptr[r + 1]):
            if local[indices[a]] < 0:
                local[indices[a]] = count
                columns[count] = indices[a]
                count += 1
    return count


@inline_jit(error_model="numpy")
def _gram(d, group_start, group_rows, gram, out):  # pragma: no cover - compiled
    """out (the lower band, flat) += Σ_r d_r a_r a_rᵀ, group by group of :func:`gram_plan`:
    each group's sum formed densely on its union of columns, then added once."""
    _, count, dense_start, dense, flat_start, flat = gram
    widest = 1
    for g in range(count.size):
        widest = max(widest, count[g])
    block = np.zeros((widest, widest))
    for g in range(count.size):
        first, c = group_start[g], count[g]
        for a in range(c):
            block[a, : a + 1] = 0.0
        for e in range(group_start[g + 1] - first):
            dr = d[group_rows[first + e]]
            if dr != 0.0:
                at = dense_start[g] + e * c
                _rank_one(block, dense[at : at + c], dr, c)
        k = flat_start[g]
        for a in range(c):
            for b in range(a + 1):
                out[flat[k]] += block[a, b]
                k += 1


@cached_jit(error_model="numpy", fastmath=True)
def _rank_one(block, row, weight, count):  # pragma: no cover - compiled
    """block += weight · row rowᵀ in its lower triangle (the first ``count`` entries)."""
    for a in range(count):
        va = weight * row[a]
        if va != 0.0:
            for b in range(a + 1):
                block[a, b] += va * row[b]


@inline_jit(error_model="numpy")
def _residuals(
    x, nu, s_hi, s_lo, y_hi, y_lo, indptr, indices, data, ax, lo, hi, fin_lo, fin_hi,
    e_mat, e_rhs, grad, r_hi, r_lo, r_e, r_d, f,
):  # fmt: skip  # pragma: no cover - compiled
    m = indptr.size - 1
    gap = 0.0
    worst = 0.0
    r_d[:] = grad
    for r in range(m):
        r_hi[r] = ax[r] + s_hi[r] - hi[r] if fin_hi[r] else 0.0
        r_lo[r] = s_lo[r] - ax[r] + lo[r] if fin_lo[r] else 0.0
        worst = max(worst, abs(r_hi[r]), abs(r_lo[r]))
        gap += s_hi[r] * y_hi[r] + s_lo[r] * y_lo[r]
        dual = y_hi[r] - y_lo[r]
        if dual != 0.0:
            for a in range(indptr[r], indptr[r + 1]):
                r_d[indices[a]] += dual * data[a]
    for e in range(e_rhs.size):
        acc = -e_rhs[e]
        for c in range(x.size):
            acc += e_mat[e, c] * x[c]
            r_d[c] += e_mat[e, c] * nu[e]
        r_e[e] = acc
        worst = max(worst, abs(acc))
    rd_max = 0.0
    for c in range(x.size):
        rd_max = max(rd_max, abs(r_d[c]))
    return f, gap, worst, rd_max


@cached_jit(error_model="numpy")
def newton_rhs(
    rc_hi, rc_lo, s_hi, s_lo, y_hi, y_lo, r_hi, r_lo, fin_lo, fin_hi, r_d,
    indptr, indices, data, out,
):  # fmt: skip  # pragma: no cover - compiled
    """−r_d + Aᵀ(w_hi − w_lo), w = (rc − y r)/s on the finite sides: the right-hand side of
    the Newton system for the complementarity targets s y − rc."""
    out[:] = -r_d
    for r in range(indptr.size - 1):
        w = (rc_hi[r] - y_hi[r] * r_hi[r]) / s_hi[r] if fin_hi[r] else 0.0
        if fin_lo[r]:
            w -= (rc_lo[r] - y_lo[r] * r_lo[r]) / s_lo[r]
        if w != 0.0:
            for a in range(indptr[r], indptr[r + 1]):
                out[indices[a]] += w * data[a]


@cached_jit(error_model="numpy")
def directions(
    dx, rc_hi, rc_lo, s_hi, s_lo, y_hi, y_lo, r_hi, r_lo, fin_lo, fin_hi,
    indptr, indices, data, x, nz, ds_hi, ds_lo, dy_hi, dy_lo,
):  # fmt: skip  # pragma: no cover - compiled
    """Δs and Δy from Δx (into ds_*, dy_*); returns the largest step to the boundary of the
    slacks and multipliers and the largest that leaves every z at least half of itself."""
    longest = np.inf
    for r in range(indptr.size - 1):
        a_dx = 0.0
        for a in range(indptr[r], indptr[r + 1]):
            a_dx += data[a] * dx[indices[a]]
        if fin_hi[r]:
            ds_hi[r] = -r_hi[r] - a_dx
            dy_hi[r] = (-rc_hi[r] - y_hi[r] * ds_hi[r]) / s_hi[r]
            longest = _towards(longest, s_hi[r], ds_hi[r])
            longest = _towards(longest, y_hi[r], dy_hi[r])
        else:
            ds_hi[r], dy_hi[r] = 0.0, 0.0
        if fin_lo[r]:
            ds_lo[r] = -r_lo[r] + a_dx
            dy_lo[r] = (-rc_lo[r] - y_lo[r] * ds_lo[r]) / s_lo[r]
            longest = _towards(longest, s_lo[r], ds_lo[r])
            longest = _towards(longest, y_lo[r], dy_lo[r])
        else:
            ds_lo[r], dy_lo[r] = 0.0, 0.0
    halving = np.inf
    for j in range(nz):
        halving = _towards(halving, x[j], 2.0 * dx[j])
    return longest, halving


@inline_jit()
def _towards(longest, v, dv):  # pragma: no cover - compiled
    """The smaller of ``longest`` and the step at which v + α dv reaches 0 (v ≥ 0)."""
    if dv < 0.0:
        return min(longest, -v / dv)
    return longest


@cached_jit(error_model="numpy")
def gap_after(alpha, s_hi, s_lo, y_hi, y_lo, ds_hi, ds_lo, dy_hi, dy_lo):  # pragma: no cover
    """Σ s y after a step α."""
    total = 0.0
    for r in range(s_hi.size):
        total += (s_hi[r] + alpha * ds_hi[r]) * (y_hi[r] + alpha * dy_hi[r])
        total += (s_lo[r] + alpha * ds_lo[r]) * (y_lo[r] + alpha * dy_lo[r])
    return total


@cached_jit(error_model="numpy")
def corrector_targets(
    s_hi, s_lo, y_hi, y_lo, ds_hi, ds_lo, dy_hi, dy_lo, fin_lo, fin_hi, target, rc_hi, rc_lo
):  # pragma: no cover - compiled
    """Mehrotra's targets s y + Δs_aff Δy_aff − σμ on the finite sides (into rc_*)."""
    for r in range(s_hi.size):
        rc_hi[r] = s_hi[r] * y_hi[r] + ds_hi[r] * dy_hi[r] - target if fin_hi[r] else 0.0
        rc_lo[r] = s_lo[r] * y_lo[r] + ds_lo[r] * dy_lo[r] - target if fin_lo[r] else 0.0
