"""The compiled loops of :mod:`nearopt.timing.interior` (numba): the Newton iterations and the
rows a sample's other rows imply.

Plain loops over the segments and the rows (each touches two neighbouring knots), so one iteration
is O(N + rows) with no temporary arrays beyond a few of size N and rows. Compiled on first use and
cached beside this file (``cache=True``); see :mod:`nearopt.timing.interior` for the method.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numba
import numpy as np


def cached_jit(**options: object):  # noqa: ANN202 - numba's decorator
    """``numba.njit`` with its machine code cached beside this file or, where that folder and the
    user's home cannot be written (a read-only install run by a user without a home), in a
    private folder of the temporary directory."""

    def wrap(fn):  # noqa: ANN001, ANN202
        try:
            return numba.njit(cache=True, **options)(fn)
        except RuntimeError:  # numba: "no locator available for file"
            folder = Path(tempfile.gettempdir()) / f"nearopt-numba-{os.getuid()}"
            folder.mkdir(mode=0o700, exist_ok=True)
            numba.config.CACHE_DIR = str(folder)
            return numba.njit(cache=True, **options)(fn)

    return wrap


RUNNING, CONVERGED, SINGULAR, NOT_FINITE = 0, 1, 2, 3
ROUNDING = 1e-13  # relative error of a sum of a few hundred terms in double precision
# reassociation and reciprocals allowed; NaN and inf keep their meaning (the limits may be inf)
FAST = {"nsz", "arcp", "contract", "reassoc"}


def inline_jit(**options: object):  # noqa: ANN202 - numba's decorator
    """A helper of a kernel, inlined into it by numba before compilation (the same machine code
    as one function: the kernel's sums are reassociated as before)."""
    return numba.njit(inline="always", **options)


@cached_jit(fastmath=FAST, error_model="numpy")
def iterate(
    z,
    s,
    y,
    left,
    cl,
    cr,
    sd,
    node,
    const,
    e_left,
    e_cl,
    e_cr,
    e_d,
    e_node,
    e_const,
    e_w,
    ds,
    ends,
    price,
    scale,
    f_scale,
    tolerance,
    iterations,
    tau,
):  # pragma: no cover - compiled
    """Run up to ``iterations`` predictor-corrector steps on (z, s, y) in place.

    Four passes over the rows per iteration: (1) values, derivatives, residuals, the Newton
    matrix and the predictor's right-hand side; (2) the predictor's direction, its step and the
    sums that give its duality measure; (3) the corrector's right-hand side; (4) the corrector's
    direction and step, then the update. Returns (status, steps taken, F unscaled).
    """
    big_n = ds.size
    m = left.size
    nf = big_n - 1
    b = np.zeros(big_n + 1)
    lam = np.zeros(big_n + 1)
    hinv = np.zeros(big_n + 1)
    croot = np.zeros(big_n + 1)
    hdiag = np.zeros(big_n + 1)
    hoff = np.zeros(big_n)
    rd = np.zeros(big_n + 1)
    rd_size = np.zeros(big_n + 1)  # Σ |terms| of rd: the floor of its rounding error
    rhs = np.zeros(big_n + 1)
    gl = np.zeros(m)
    gr = np.zeros(m)
    rp = np.zeros(m)
    w = np.zeros(m)
    inv_s = np.zeros(m)
    dsl = np.zeros(m)
    dy = np.zeros(m)
    dz = np.zeros(nf)
    dzx = np.zeros(big_n + 1)  # Δb on every knot (0 at the ends)
    dd = np.zeros(nf)
    ll = np.zeros(nf)
    q = np.zeros((6, big_n))  # the energy term per segment: q, q_l, q_r, q_ll, q_rr, q_lr
    f_total = 0.0
    for it in range(iterations):
        _at(z, ends, b, lam, hinv, croot, hdiag, rd, rd_size, rhs, hoff, q)
        _energy_sums(e_left, e_cl, e_cr, e_d, e_node, e_const, e_w, b, lam, hinv, croot, q)
        f_total = _objective(ds, lam, hinv, croot, q, f_scale, rd, rd_size, hdiag, hoff)
        for k in range(1, big_n):  # a linear term Σ price_k b_k (0 but for set durations)
            if price[k] != 0.0:
                f_total += price[k] * b[k]
                rd[k] += price[k] * f_scale
                rd_size[k] += abs(price[k] * f_scale)
        gap, rp_max = _rows(
            z, s, y, left, cl, cr, sd, node, const, b, lam, hinv, croot,
            gl, gr, rp, w, inv_s, rd, rd_size, hdiag, hoff, rhs,
        )  # fmt: skip
        rd_max = 0.0
        for k in range(1, big_n):
            rd_max = max(rd_max, (abs(rd[k]) - ROUNDING * rd_size[k]) * scale[k - 1])
        rel = f_total * f_scale
        if gap <= tolerance * rel and rd_max <= tolerance * rel and rp_max <= tolerance:
            return CONVERGED, it, f_total
        if not _factor(hdiag, hoff, scale, dd, ll):
            return SINGULAR, it, f_total
        step = _step(
            z, s, y, left, gl, gr, rp, w, inv_s, rd, rhs, scale, dd, ll,
            dz, dzx, dsl, dy, gap / m, gap, tau,
        )  # fmt: skip
        for i in range(nf):
            z[i] += step * dz[i]
            if not np.isfinite(z[i]):
                return NOT_FINITE, it + 1, f_total
        for j in range(m):
            s[j] += step * dsl[j]
            y[j] += step * dy[j]
    return RUNNING, iterations, f_total


@inline_jit(fastmath=FAST, error_model="numpy")
def _at(z, ends, b, lam, hinv, croot, hdiag, rd, rd_size, rhs, hoff, q):  # pragma: no cover
    """b, λ = √b, 1/(2λ) and −1/(4λ³) at the knots from z and the fixed ends (b_0, b_N: their
    derivatives stay 0, they are not variables); the sums of an iteration zeroed."""
    big_n = hoff.size
    b[0] = ends[0]
    lam[0] = np.sqrt(ends[0])
    b[big_n] = ends[1]
    lam[big_n] = np.sqrt(ends[1])
    for k in range(1, big_n):
        b[k] = z[k - 1]
        lam[k] = np.sqrt(z[k - 1])
        hinv[k] = 0.5 / lam[k]
        croot[k] = -0.25 / (lam[k] * lam[k] * lam[k])
    for k in range(big_n + 1):
        hdiag[k] = 0.0
        rd[k] = 0.0
        rd_size[k] = 0.0
        rhs[k] = 0.0
    for k in range(big_n):
        hoff[k] = 0.0
        for i in range(6):
            q[i, k] = 0.0


@inline_jit(fastmath=FAST, error_model="numpy")
def _energy_sums(
    e_left, e_cl, e_cr, e_d, e_node, e_const, e_w, b, lam, hinv, croot, q
):  # pragma: no cover - compiled
    """The energy term ½ Σ w u² of every segment and its derivatives in the segment's two b."""
    for j in range(e_left.size):
        k = e_left[j]
        nd = e_node[j]
        u = e_cl[j] * b[k] + e_cr[j] * b[k + 1] + e_d[j] * lam[nd] + e_const[j]
        ul = e_cl[j]
        ur = e_cr[j]
        curv = 0.0
        if e_d[j] != 0.0:
            if nd == k:
                ul += e_d[j] * hinv[nd]
            else:
                ur += e_d[j] * hinv[nd]
            curv = e_d[j] * croot[nd]
        wt = e_w[j]
        q[0, k] += 0.5 * wt * u * u
        q[1, k] += wt * u * ul
        q[2, k] += wt * u * ur
        q[3, k] += wt * ul * ul
        q[4, k] += wt * ur * ur
        q[5, k] += wt * ul * ur
        if curv != 0.0:
            if nd == k:
                q[3, k] += wt * u * curv
            else:
                q[4, k] += wt * u * curv


@inline_jit(fastmath=FAST, error_model="numpy")
def _objective(ds, lam, hinv, croot, q, f_scale, rd, rd_size, hdiag, hoff):  # pragma: no cover
    """F = Σ t_k (1 + q_k) with t_k = 2Δσ_k / (λ_k + λ_k+1), its gradient into rd and its
    Hessian into hdiag, hoff; returns F."""
    f_total = 0.0
    for k in range(ds.size):
        sl = lam[k] + lam[k + 1]
        t = 2.0 * ds[k] / sl
        dt = -t / sl
        d2 = 2.0 * t / (sl * sl)
        hl = hinv[k]
        hr = hinv[k + 1]
        tl = dt * hl
        tr = dt * hr
        one = 1.0 + q[0, k]
        f_total += t * one
        grad_l = (tl * one + t * q[1, k]) * f_scale
        grad_r = (tr * one + t * q[2, k]) * f_scale
        rd[k] += grad_l
        rd[k + 1] += grad_r
        rd_size[k] += abs(grad_l)
        rd_size[k + 1] += abs(grad_r)
        hdiag[k] += (d2 * hl * hl + dt * croot[k]) * one * f_scale
        hdiag[k] += (2.0 * tl * q[1, k] + t * q[3, k]) * f_scale
        hdiag[k + 1] += (d2 * hr * hr + dt * croot[k + 1]) * one * f_scale
        hdiag[k + 1] += (2.0 * tr * q[2, k] + t * q[4, k]) * f_scale
        hoff[k] += (d2 * hl * hr * one + tl * q[2, k] + tr * q[1, k] + t * q[5, k]) * f_scale
    return f_total


@inline_jit(fastmath=FAST, error_model="numpy")
def _rows(
    z, s, y, left, cl, cr, sd, node, const, b, lam, hinv, croot,
    gl, gr, rp, w, inv_s, rd, rd_size, hdiag, hoff, rhs,
):  # fmt: skip  # pragma: no cover - compiled
    """Pass 1 over the rows: values, derivatives, residuals, the Newton matrix and the
    predictor's right-hand side. Returns (Σ s y, the largest residual beyond rounding)."""
    gap = 0.0
    rp_max = 0.0
    for j in range(left.size):
        k = left[j]
        nd = node[j]
        g_l = cl[j]
        g_r = cr[j]
        c = g_l * b[k] + g_r * b[k + 1] + const[j]
        size_j = abs(g_l * b[k]) + abs(g_r * b[k + 1]) + abs(const[j]) + s[j]
        if sd[j] != 0.0:
            c += sd[j] * lam[nd]
            size_j += abs(sd[j] * lam[nd])
            if nd == k:
                g_l += sd[j] * hinv[nd]
            else:
                g_r += sd[j] * hinv[nd]
            hdiag[nd] += y[j] * sd[j] * croot[nd]  # the row's curvature, times its multiplier
        gl[j] = g_l
        gr[j] = g_r
        r = c + s[j]
        rp[j] = r
        # the residual beyond the rounding error of the row's terms (they nearly cancel
        # where the segments are short: coefficients ∝ 1/Δσ)
        rp_max = max(rp_max, abs(r) - ROUNDING * size_j)
        yj = y[j]
        rd[k] += g_l * yj
        rd[k + 1] += g_r * yj
        rd_size[k] += abs(g_l * yj)
        rd_size[k + 1] += abs(g_r * yj)
        gap += s[j] * yj
        inv = 1.0 / s[j]
        inv_s[j] = inv
        wj = yj * inv
        w[j] = wj
        hdiag[k] += wj * g_l * g_l
        hdiag[k + 1] += wj * g_r * g_r
        hoff[k] += wj * g_l * g_r
        v = yj - wj * r  # (s y − y r) / s: the predictor's complementarity target is 0
        rhs[k] += g_l * v
        rhs[k + 1] += g_r * v
    return gap, rp_max


@inline_jit(fastmath=FAST, error_model="numpy")
def _factor(hdiag, hoff, scale, dd, ll):  # pragma: no cover - compiled
    """L D Lᵀ of D M D (M tridiagonal: hdiag, hoff; D = diag(scale)) into dd, ll, shifted by
    the smallest multiple of its size (up to 10⁷: a joint whose damping torque outweighs the
    rest needed more than 1) that makes it positive definite; False if none does."""
    nf = dd.size
    size = 0.0
    for i in range(nf):
        if abs(hdiag[i + 1] * scale[i] * scale[i]) > size:
            size = abs(hdiag[i + 1] * scale[i] * scale[i])
    delta = 0.0
    ok = False
    for _attempt in range(20):
        ok = True
        for i in range(nf):
            dd[i] = hdiag[i + 1] * scale[i] * scale[i] + delta * size
            if i > 0:
                off = hoff[i] * scale[i - 1] * scale[i]
                ll[i] = off / dd[i - 1]
                dd[i] -= ll[i] * off
            if not dd[i] > 0.0:
                ok = False
                break
        if ok:
            break
        delta = 1e-12 if delta == 0.0 else 10.0 * delta
    return ok


@inline_jit(fastmath=FAST, error_model="numpy")
def _step(
    z, s, y, left, gl, gr, rp, w, inv_s, rd, rhs, scale, dd, ll,
    dz, dzx, dsl, dy, mu, gap, tau,
):  # fmt: skip  # pragma: no cover - compiled
    """The predictor's direction and step, the corrector's right-hand side, then the
    corrector's direction (into dz, dsl, dy) and its step, which it returns."""
    nf = dz.size
    m = left.size
    step = 0.0
    sigma_mu = 0.0
    for phase in range(2):
        # solve L D Lᵀ x = D (−rd + rhs), dz = D x
        for i in range(nf):
            dz[i] = (-rd[i + 1] + rhs[i + 1]) * scale[i]
            if i > 0:
                dz[i] -= ll[i] * dz[i - 1]
        for i in range(nf - 1, -1, -1):
            dz[i] /= dd[i]
            if i < nf - 1:
                dz[i] -= ll[i + 1] * dz[i + 1]
        # b may at most halve in one step (1/√b is far from its tangent below that), and
        # the slacks and multipliers stay positive
        largest_z = np.inf
        for i in range(nf):
            dz[i] *= scale[i]
            dzx[i + 1] = dz[i]
            ratio = -0.5 * z[i] / dz[i]
            largest_z = min(largest_z, ratio if dz[i] < 0.0 else np.inf)
        largest = np.inf
        cross = 0.0  # Σ s Δy + y Δs
        square = 0.0  # Σ Δs Δy
        for j in range(m):
            k = left[j]
            jdz = gl[j] * dzx[k] + gr[j] * dzx[k + 1]
            d_s = -rp[j] - jdz
            if phase == 0:
                d_y = -y[j] + w[j] * (rp[j] + jdz)
            else:
                d_y = dy[j] + w[j] * jdz  # dy holds the corrector's constant part
            dsl[j] = d_s
            dy[j] = d_y
            r_s = -s[j] / d_s  # branch-free: the sign of a step is unpredictable
            r_y = -y[j] / d_y
            largest = min(largest, min(r_s if d_s < 0.0 else np.inf, r_y if d_y < 0.0 else np.inf))
            if phase == 0:
                cross += s[j] * d_y + y[j] * d_s
                square += d_s * d_y
        if phase == 0:
            step = min(1.0, largest, largest_z)
            mu_aff = (gap + step * cross + step * step * square) / m
            sigma_mu = (mu_aff / mu) ** 3 * mu
            # the corrector: complementarity target s y + Δs Δy − σμ
            for k in range(rhs.size):
                rhs[k] = 0.0
            for j in range(m):
                comp = s[j] * y[j] + dsl[j] * dy[j] - sigma_mu
                v = (comp - y[j] * rp[j]) * inv_s[j]
                rhs[left[j]] += gl[j] * v
                rhs[left[j] + 1] += gr[j] * v
                dy[j] = (-comp + y[j] * rp[j]) * inv_s[j]
        else:
            step = min(1.0, tau * largest, largest_z)
    return step


@cached_jit()
def _first_drop(a, b, c, t_max):  # pragma: no cover - compiled
    """The first t in (0, t_max] where a + b t² + c t < 0 (a ≥ 0), or t_max if none."""
    if a == 0.0 and (c < 0.0 or (c == 0.0 and b < 0.0)):
        return 0.0
    # roots of b t² + c t + a = 0
    if b == 0.0:
        if c < 0.0:
            t = -a / c
            return t if t < t_max else t_max
        return t_max
    disc = c * c - 4.0 * b * a
    if disc < 0.0:
        return t_max  # b > 0 here (a ≥ 0 and no root): never negative
    root = np.sqrt(disc)
    q = -0.5 * (c + root) if c >= 0.0 else -0.5 * (c - root)
    best = t_max
    if q != 0.0:
        for t in (q / b, a / q):
            if t > 0.0 and t < best:
                # a sign change, not a double root touching zero
                mid = t * (1.0 + 1e-12)
                if a + b * mid * mid + c * mid < 0.0:
                    best = t
    return best


@cached_jit()
def _below_on(da, db, dc, t_max):  # pragma: no cover - compiled
    """Whether da + db t² + dc t ≥ 0 for every t in [0, t_max] (t_max may be inf)."""
    if da < 0.0:
        return False
    if np.isfinite(t_max):
        if da + db * t_max * t_max + dc * t_max < 0.0:
            return False
    elif db < 0.0 or (db == 0.0 and dc < 0.0):
        return False
    if db > 0.0:
        t = -dc / (2.0 * db)
        if 0.0 < t < t_max and da + db * t * t + dc * t < 0.0:
            return False
    return True


@cached_jit()
def redundant_rows(order, starts, left, cl, cr, sd, node, const, ds, cap_b):  # pragma: no cover
    """The rows at one sample that another row at it implies, and each sample's bound on b.

    The rows of a sample (knot ``node``, segment ``left``) are M a + C b + d √b + c0 ≤ 0 in the
    segment's path acceleration a and the knot's b (b at the other knot is b ± 2Δσ a): each bounds
    a from above (M > 0) or below (M < 0) by α + β t² + γ t, t = √b. The sample is feasible only
    for t up to the first crossing of an upper and a lower bound (its maximum velocity curve), and
    up to √cap_b; on [0, that t] a bound that another bound of its side is tighter than everywhere
    is implied by it. Returns a mask of the implied rows (ties keep the first) and the bound on
    b of every sample (inf if none).
    """
    m = left.size
    drop = np.zeros(m, dtype=np.bool_)
    groups = starts.size - 1
    b_max = np.full(groups, np.inf)
    size = 0
    for g in range(groups):
        size = max(size, starts[g + 1] - starts[g])
    alpha = np.zeros(size)
    beta = np.zeros(size)
    gamma = np.zeros(size)
    kind = np.zeros(size, dtype=np.int64)  # 1 upper, −1 lower, 0 keep
    for g in range(groups):
        lo, hi = starts[g], starts[g + 1]
        count = hi - lo
        first = order[lo]
        k = left[first]
        nd = node[first]
        t_max = np.sqrt(cap_b[nd])
        for p in range(count):
            j = order[lo + p]
            if nd == k:
                mm = 2.0 * ds[k] * cr[j]
            else:
                mm = -2.0 * ds[k] * cl[j]
            cc = cl[j] + cr[j]
            if mm == 0.0 or not np.isfinite(mm):
                kind[p] = 0
                continue
            kind[p] = 1 if mm > 0.0 else -1
            alpha[p] = -const[j] / mm
            beta[p] = -cc / mm
            gamma[p] = -sd[j] / mm
        # the maximum velocity curve of this sample: upper p meets lower q
        for p in range(count):
            if kind[p] != 1:
                continue
            for r in range(count):
                if kind[r] != -1:
                    continue
                da = alpha[p] - alpha[r]
                if da < 0.0:
                    da = 0.0
                t_max = _first_drop(da, beta[p] - beta[r], gamma[p] - gamma[r], t_max)
        b_max[g] = t_max * t_max
        for p in range(count):
            if kind[p] == 0:
                continue
            for r in range(count):
                if r == p or kind[r] != kind[p] or drop[order[lo + r]]:
                    continue
                sign = 1.0 if kind[p] == 1 else -1.0
                da = sign * (alpha[p] - alpha[r])
                db = sign * (beta[p] - beta[r])
                dc = sign * (gamma[p] - gamma[r])
                if da == 0.0 and db == 0.0 and dc == 0.0 and r > p:
                    continue  # the same bound twice: keep the first
                if _below_on(da, db, dc, t_max):
                    drop[order[lo + p]] = True
                    break
    return drop, b_max


@cached_jit()
def _clip(xs, ys, count, a, b, c, out_x, out_y):  # pragma: no cover - compiled
    """The convex polygon (xs, ys)[:count] cut by a x + b y + c ≤ 0 (Sutherland–Hodgman), into
    out_x, out_y; returns its vertex count, or −1 if that would not fit in out_x (a polygon
    that rounding made not quite convex can gain more than one vertex per cut)."""
    kept = 0
    room = out_x.size
    for i in range(count):
        j = i + 1 if i + 1 < count else 0
        fp = a * xs[i] + b * ys[i] + c
        fq = a * xs[j] + b * ys[j] + c
        if fp <= 0.0:
            if kept >= room:
                return -1
            out_x[kept] = xs[i]
            out_y[kept] = ys[i]
            kept += 1
        if (fp < 0.0 < fq) or (fq < 0.0 < fp):
            if kept >= room:
                return -1
            t = fp / (fp - fq)
            out_x[kept] = xs[i] + t * (xs[j] - xs[i])
            out_y[kept] = ys[i] + t * (ys[j] - ys[i])
            kept += 1
    return kept


@cached_jit()
def _cut(xs, ys, count, a, b, c, tx, ty):  # pragma: no cover - compiled
    """:func:`_clip` in place: the polygon (xs, ys) cut by a x + b y + c ≤ 0 (tx, ty scratch)."""
    count = _clip(xs, ys, count, a, b, c, tx, ty)
    for v in range(count):
        xs[v] = tx[v]
        ys[v] = ty[v]
    return count


@cached_jit()
def needed_inside(
    seg_rows,
    row_cl,
    row_cr,
    row_off,
    row_lo,
    row_up,
    cap_b,
    seg_inside,
    in_cl,
    in_cr,
    in_off,
    in_d,
    in_w,
    in_lo,
    in_up,
    slack,
):  # pragma: no cover - compiled
    """Which sides of the rows inside segments the rows at the segments' samples leave open.

    Segment k's samples allow (b_k, b_{k+1}) in a convex polygon: the box [0, cap_b[k]] ×
    [0, cap_b[k+1]] cut by its sample rows lo ≤ cl b_k + cr b_{k+1} + off ≤ up (those in
    ``seg_rows[k] : seg_rows[k + 1]``, undamped; damped ones are left out, which only enlarges
    the polygon), each loosened by ``slack`` of its size. A row inside the segment (those in
    ``seg_inside[k] : seg_inside[k + 1]``), cl b_k + cr b_{k+1} + off + d √b_p with
    b_p = (1 − w) b_k + w b_{k+1}, is implied on a side where its extreme over the polygon's
    vertices (the √ term bounded separately) is within the limit by ``slack`` of its size. Where
    the box is unbounded or the polygon empty, both sides are kept. Returns the masks of the
    upper and the lower sides needed.
    """
    m = in_cl.size
    need_up = np.ones(m, dtype=np.bool_)
    need_lo = np.ones(m, dtype=np.bool_)
    big_n = seg_rows.size - 1
    size = 4
    for k in range(big_n):
        size = max(size, 4 + 2 * (seg_rows[k + 1] - seg_rows[k]))
    xs = np.empty(size)
    ys = np.empty(size)
    tx = np.empty(size)
    ty = np.empty(size)
    for k in range(big_n):
        if seg_inside[k] == seg_inside[k + 1]:
            continue  # no row inside this segment (those next to the rest ends: two segments)
        count = _polygon(
            k, seg_rows, row_cl, row_cr, row_off, row_lo, row_up, cap_b, slack, xs, ys, tx, ty
        )
        if count <= 0:
            continue
        bx, by = cap_b[k], cap_b[k + 1]
        for q in range(seg_inside[k], seg_inside[k + 1]):
            hi = -np.inf
            lo = np.inf
            b_hi = 0.0
            b_lo = np.inf
            for v in range(count):
                value = in_cl[q] * xs[v] + in_cr[q] * ys[v] + in_off[q]
                hi = max(hi, value)
                lo = min(lo, value)
                bp = max((1.0 - in_w[q]) * xs[v] + in_w[q] * ys[v], 0.0)
                b_hi = max(b_hi, bp)
                b_lo = min(b_lo, bp)
            d = in_d[q]
            if d > 0.0:
                hi += d * np.sqrt(b_hi)
                lo += d * np.sqrt(b_lo)
            elif d < 0.0:
                hi += d * np.sqrt(b_lo)
                lo += d * np.sqrt(b_hi)
            size_q = (
                abs(in_cl[q]) * bx
                + abs(in_cr[q]) * by
                + abs(in_off[q])
                + abs(d) * np.sqrt(max(bx, by))
            )
            if hi <= in_up[q] - slack * (size_q + abs(in_up[q])):
                need_up[q] = False
            if lo >= in_lo[q] + slack * (size_q + abs(in_lo[q])):
                need_lo[q] = False
    return need_up, need_lo


@cached_jit()
def _polygon(
    k, seg_rows, row_cl, row_cr, row_off, row_lo, row_up, cap_b, slack, xs, ys, tx, ty
):  # pragma: no cover - compiled
    """The polygon of (b_k, b_{k+1}) that segment k's sample rows allow (see
    :func:`needed_inside`), into xs, ys; its vertex count (0: empty; −1 where the box is
    unbounded or rounding left no convex polygon)."""
    bx, by = cap_b[k], cap_b[k + 1]
    if not (np.isfinite(bx) and np.isfinite(by)):
        return -1
    xs[0], ys[0], xs[1], ys[1] = 0.0, 0.0, bx, 0.0
    xs[2], ys[2], xs[3], ys[3] = bx, by, 0.0, by
    count = 4
    for r in range(seg_rows[k], seg_rows[k + 1]):
        size_r = abs(row_cl[r]) * bx + abs(row_cr[r]) * by + abs(row_off[r])
        for sign in (1.0, -1.0):
            bound = row_up[r] if sign > 0.0 else row_lo[r]
            if not np.isfinite(bound):
                continue
            loose = slack * (size_r + abs(bound))
            count = _cut(
                xs,
                ys,
                count,
                sign * row_cl[r],
                sign * row_cr[r],
                sign * (row_off[r] - bound) - loose,
                tx,
                ty,
            )
            if count <= 0:
                return count  # empty, or not a polygon any more (−1): no use either way
    return count


@cached_jit()
def envelope_rows(
    seg_rows,
    row_cl,
    row_cr,
    row_off,
    row_lo,
    row_up,
    cap_b,
    pcl,
    pcr,
    poff,
    lo,
    up,
    slack,
    touch,
    merge,
):  # pragma: no cover - compiled
    """The rows that hold :class:`~nearopt.timing.BetweenSamples`' bound of a quantity between
    its points, where the other rows of the segment do not imply them.

    The quantity at the P + 2 points of segment k (its knots and the points inside) is, for
    joint j, q_p = pcl[k, p, j] b_k + pcr[k, p, j] b_{k+1} + poff[k, p, j]; on the interval
    between points p and p + 1 the bound is max(q_p, q_{p+1}) + (max(|κ_p|, |κ_{p+1}|)
    + |κ_{p+1} − κ_p|) / 8 (κ the second differences, extrapolated to the knots as in
    ``between._curvature``), and it lies within [lo_j, up_j] (and so does the one from below)
    if and only if every sum q_i ± κ_l / 8 ± (κ_{p+1} − κ_p) / 8,
    i, l ∈ {p, p + 1}, does (the bound of :class:`~nearopt.timing.BetweenSamples`). Each is a
    row of the two knots. A side of one is left out where it is implied: first where its extreme
    over the polygon of the samples (see :func:`needed_inside`) is within the limit by
    ``slack`` of its size; then the polygon is cut by the sides left and those that do not
    touch what remains, or cut into it by less than ``touch`` of their limit, are left out too (a
    convex polygon is the intersection of the half-planes that touch it; what the motion may
    then exceed a bound by, ``touch`` relatively, the check after the solve takes back by a
    uniform slow-down). Sides of one joint that differ by less than ``merge`` of their size over the
    box are merged into one that implies both (the optimum moves by at most that, relatively).
    Returns the one-sided rows: segment, point i, joint, the coefficients of b_k and
    b_{k+1}, the constant and the limits (±inf on a side implied).
    """
    big_n, points, joints = pcl.shape
    per_seg = joints * 16 * (points - 1)  # the sums of every interval
    size = 4
    for k in range(big_n):
        size = max(size, 4 + 2 * (seg_rows[k + 1] - seg_rows[k]) + 2 * per_seg)
    xs = np.empty(size)
    ys = np.empty(size)
    tx = np.empty(size)
    ty = np.empty(size)
    cap = max(1024, 4 * big_n * joints)  # grown as needed: most rows are left out
    o_seg = np.empty(cap, dtype=np.int64)
    o_pt = np.empty(cap, dtype=np.int64)
    o_joint = np.empty(cap, dtype=np.int64)
    o_cl = np.empty(cap)
    o_cr = np.empty(cap)
    o_off = np.empty(cap)
    o_lo = np.empty(cap)
    o_up = np.empty(cap)
    kappa = np.empty((3, points))  # κ's coefficients of b_k, b_k+1 and its constant
    c_pt = np.empty(per_seg, dtype=np.int64)
    c_joint = np.empty(per_seg, dtype=np.int64)
    c_val = np.empty((3, per_seg))  # a sum's coefficients of b_k, b_k+1 and its constant
    c_up = np.empty(per_seg, dtype=np.bool_)
    c_lo = np.empty(per_seg, dtype=np.bool_)
    out = 0
    for k in range(big_n):
        count = _polygon(
            k, seg_rows, row_cl, row_cr, row_off, row_lo, row_up, cap_b, slack, xs, ys, tx, ty
        )
        found = 0
        for j in range(joints):
            if not (np.isfinite(lo[j]) or np.isfinite(up[j])):
                continue
            _curvatures(pcl, pcr, poff, k, j, kappa)
            if count > 0 and not _may_bind(
                pcl, pcr, poff, k, j, kappa, cap_b[k], cap_b[k + 1],
                lo[j], up[j], slack, xs, ys, count,
            ):  # fmt: skip
                continue  # no sum can bind if the values and curvatures together cannot
            found = _sums(
                k, j, pcl, pcr, poff, kappa, lo[j], up[j], slack, cap_b, xs, ys, count,
                c_pt, c_joint, c_val, c_up, c_lo, found,
            )  # fmt: skip
        if count > 0:
            count = _touching(
                cap_b[k], cap_b[k + 1], lo, up, slack, touch, xs, ys, tx, ty, count,
                c_joint, c_val, c_up, c_lo, found,
            )  # fmt: skip
        if out + 2 * found > cap:
            cap = 2 * (out + 2 * found)
            o_seg, o_pt = _grow_int(o_seg, cap), _grow_int(o_pt, cap)
            o_joint = _grow_int(o_joint, cap)
            o_cl, o_cr, o_off = _grow(o_cl, cap), _grow(o_cr, cap), _grow(o_off, cap)
            o_lo, o_up = _grow(o_lo, cap), _grow(o_up, cap)
        out = _one_sided(
            k, cap_b[k], cap_b[k + 1], lo, up, merge, xs, ys, count,
            c_pt, c_joint, c_val, c_up, c_lo, found,
            o_seg, o_pt, o_joint, o_cl, o_cr, o_off, o_lo, o_up, out,
        )  # fmt: skip
    return (
        o_seg[:out],
        o_pt[:out],
        o_joint[:out],
        o_cl[:out],
        o_cr[:out],
        o_off[:out],
        o_lo[:out],
        o_up[:out],
    )


@cached_jit()
def _curvatures(pcl, pcr, poff, k, j, kappa):  # pragma: no cover - compiled
    """κ_p, the second differences of joint j's quantity at segment k's points (its
    coefficients of b_k and b_k+1 and its constant, from those of the values), at the knots
    extrapolated from the two next points (see between._curvature)."""
    points = pcl.shape[1]
    for p in range(1, points - 1):
        kappa[0, p] = pcl[k, p - 1, j] - 2.0 * pcl[k, p, j] + pcl[k, p + 1, j]
        kappa[1, p] = pcr[k, p - 1, j] - 2.0 * pcr[k, p, j] + pcr[k, p + 1, j]
        kappa[2, p] = poff[k, p - 1, j] - 2.0 * poff[k, p, j] + poff[k, p + 1, j]
    last = points - 1
    for c in range(3):
        if points >= 4:
            kappa[c, 0] = 2.0 * kappa[c, 1] - kappa[c, 2]
            kappa[c, last] = 2.0 * kappa[c, last - 1] - kappa[c, last - 2]
        else:
            kappa[c, 0] = kappa[c, 1]
            kappa[c, last] = kappa[c, last - 1]


@cached_jit()
def _may_bind(
    pcl, pcr, poff, k, j, kappa, bx, by, lo, up, slack, xs, ys, count
):  # pragma: no cover - compiled
    """Whether any sum of joint j's quantity on segment k's polygon can come within ``slack``
    of a limit: its largest value plus the largest curvature terms over the polygon."""
    points = pcl.shape[1]
    v_hi, v_lo, k_abs, dk_abs, v_size, k_size = -np.inf, np.inf, 0.0, 0.0, 0.0, 0.0
    for p in range(points):
        hi, low = _extremes(pcl[k, p, j], pcr[k, p, j], poff[k, p, j], xs, ys, count)
        v_hi, v_lo = max(v_hi, hi), min(v_lo, low)
        hi, low = _extremes(kappa[0, p], kappa[1, p], kappa[2, p], xs, ys, count)
        k_abs = max(k_abs, abs(hi), abs(low))
        if p + 1 < points:
            hi, low = _extremes(
                kappa[0, p + 1] - kappa[0, p],
                kappa[1, p + 1] - kappa[1, p],
                kappa[2, p + 1] - kappa[2, p],
                xs,
                ys,
                count,
            )
            dk_abs = max(dk_abs, abs(hi), abs(low))
        v_size = max(v_size, abs(pcl[k, p, j]) * bx + abs(pcr[k, p, j]) * by + abs(poff[k, p, j]))
        k_size = max(k_size, abs(kappa[0, p]) * bx + abs(kappa[1, p]) * by + abs(kappa[2, p]))
    size_max = v_size + 0.375 * k_size  # no sum is larger over the box
    reach = (k_abs + dk_abs) / 8.0
    open_up = np.isfinite(up) and (v_hi + reach > up - slack * (size_max + abs(up)))
    open_lo = np.isfinite(lo) and (v_lo - reach < lo + slack * (size_max + abs(lo)))
    return open_up or open_lo


@cached_jit()
def _sums(
    k, j, pcl, pcr, poff, kappa, lo, up, slack, cap_b, xs, ys, count,
    c_pt, c_joint, c_val, c_up, c_lo, found,
):  # fmt: skip  # pragma: no cover - compiled
    """The 16 sums q_i ± κ_l / 8 ± (κ_p+1 − κ_p) / 8 of every interval of joint j on segment
    k whose sides are not implied on the polygon, appended as candidates after ``found``;
    returns their new count."""
    points = pcl.shape[1]
    bx, by = cap_b[k], cap_b[k + 1]
    for p in range(points - 1):
        # where a curvature term keeps its sign on the whole polygon, the sums with the
        # other sign lie inside those with this one there: an upper side needs only
        # +|κ|, a lower side only −|κ| (0: either sign, both needed)
        sign_k0 = sign_k1 = sign_dk = 0.0
        if count > 0:
            sign_k0 = _sign_on(kappa[0, p], kappa[1, p], kappa[2, p], xs, ys, count)
            sign_k1 = _sign_on(kappa[0, p + 1], kappa[1, p + 1], kappa[2, p + 1], xs, ys, count)
            sign_dk = _sign_on(
                kappa[0, p + 1] - kappa[0, p],
                kappa[1, p + 1] - kappa[1, p],
                kappa[2, p + 1] - kappa[2, p],
                xs,
                ys,
                count,
            )
        for q in range(16):
            i = p + (q >> 3)
            at = p + ((q >> 2) & 1)
            s = 1.0 if (q >> 1) & 1 else -1.0
            t = 1.0 if q & 1 else -1.0
            sign_k = sign_k0 if at == p else sign_k1
            need_up = np.isfinite(up) and s * sign_k >= 0.0 and t * sign_dk >= 0.0
            need_lo = np.isfinite(lo) and s * sign_k <= 0.0 and t * sign_dk <= 0.0
            if not (need_up or need_lo):
                continue
            cl = pcl[k, i, j] + (s * kappa[0, at] + t * (kappa[0, p + 1] - kappa[0, p])) / 8.0
            cr = pcr[k, i, j] + (s * kappa[1, at] + t * (kappa[1, p + 1] - kappa[1, p])) / 8.0
            off = poff[k, i, j] + (s * kappa[2, at] + t * (kappa[2, p + 1] - kappa[2, p])) / 8.0
            if count > 0:
                hi, low = _extremes(cl, cr, off, xs, ys, count)
                size_q = abs(cl) * bx + abs(cr) * by + abs(off)
                if need_up and hi <= up - slack * (size_q + abs(up)):
                    need_up = False
                if need_lo and low >= lo + slack * (size_q + abs(lo)):
                    need_lo = False
            if not (need_up or need_lo):
                continue
            c_pt[found], c_joint[found] = i, j
            c_val[0, found], c_val[1, found], c_val[2, found] = cl, cr, off
            c_up[found], c_lo[found] = need_up, need_lo
            found += 1
    return found


@cached_jit()
def _touching(
    bx, by, lo, up, slack, touch, xs, ys, tx, ty, count,
    c_joint, c_val, c_up, c_lo, found,
):  # fmt: skip  # pragma: no cover - compiled
    """The polygon cut by the candidates' sides; the sides that do not touch what remains
    (within ``touch`` of their limit) are dropped. Returns the cut polygon's vertex count."""
    for c in range(found):
        j = c_joint[c]
        size_q = abs(c_val[0, c]) * bx + abs(c_val[1, c]) * by + abs(c_val[2, c])
        for sign in (1.0, -1.0):
            if (sign > 0.0 and not c_up[c]) or (sign < 0.0 and not c_lo[c]):
                continue
            bound = up[j] if sign > 0.0 else lo[j]
            loose = slack * (size_q + abs(bound))
            count = _cut(
                xs,
                ys,
                count,
                sign * c_val[0, c],
                sign * c_val[1, c],
                sign * (c_val[2, c] - bound) - loose,
                tx,
                ty,
            )
            if count <= 0:
                break
        if count <= 0:
            break
    if count > 0:
        for c in range(found):
            j = c_joint[c]
            hi, low = _extremes(c_val[0, c], c_val[1, c], c_val[2, c], xs, ys, count)
            size_q = abs(c_val[0, c]) * bx + abs(c_val[1, c]) * by + abs(c_val[2, c])
            if c_up[c] and hi <= up[j] - touch * abs(up[j]) - 1e-12 * size_q:
                c_up[c] = False
            if c_lo[c] and low >= lo[j] + touch * abs(lo[j]) + 1e-12 * size_q:
                c_lo[c] = False
    return count


@cached_jit()
def _one_sided(
    k, bx, by, lo, up, merge, xs, ys, count,
    c_pt, c_joint, c_val, c_up, c_lo, found,
    o_seg, o_pt, o_joint, o_cl, o_cr, o_off, o_lo, o_up, out,
):  # fmt: skip  # pragma: no cover - compiled
    """The candidates' sides left as one-sided rows of segment k, appended after ``out``;
    returns the new count.

    A side within ``merge`` of its limit of one already kept (of the same joint and point) on
    the polygon cut by all of them takes the place of the two: the one larger there (upper
    side; smaller, lower side). Outside that polygon the one left out may exceed the other by a
    little more; the check after the solve takes that back. Without a polygon (an unbounded
    box) the two merge into one that implies both for b ≥ 0: coefficients and constant the
    larger (upper) or the smaller (lower) of both.
    """
    first = out
    for c in range(found):
        j = c_joint[c]
        cl, cr, off = c_val[0, c], c_val[1, c], c_val[2, c]
        size_q = abs(cl) * bx + abs(cr) * by + abs(off)
        for sign in (1.0, -1.0):
            if (sign > 0.0 and not c_up[c]) or (sign < 0.0 and not c_lo[c]):
                continue
            bound = up[j] if sign > 0.0 else lo[j]
            tol = merge * abs(bound) + 1e-12 * size_q
            into = -1
            for r in range(first, out):
                if o_joint[r] != j or o_pt[r] != c_pt[c] or (o_up[r] < np.inf) != (sign > 0.0):
                    continue
                if count > 0:
                    hi, low = _extremes(o_cl[r] - cl, o_cr[r] - cr, o_off[r] - off, xs, ys, count)
                    gap = max(abs(hi), abs(low))
                else:
                    gap = abs(o_cl[r] - cl) * bx + abs(o_cr[r] - cr) * by + abs(o_off[r] - off)
                if gap <= tol:
                    into = r
                    break
            if into >= 0:
                if count > 0:
                    hi_r, low_r = _extremes(o_cl[into], o_cr[into], o_off[into], xs, ys, count)
                    hi_c, low_c = _extremes(cl, cr, off, xs, ys, count)
                    if (hi_c > hi_r) if sign > 0.0 else (low_c < low_r):
                        o_cl[into], o_cr[into], o_off[into] = cl, cr, off
                elif sign > 0.0:
                    o_cl[into] = max(o_cl[into], cl)
                    o_cr[into] = max(o_cr[into], cr)
                    o_off[into] = max(o_off[into], off)
                else:
                    o_cl[into] = min(o_cl[into], cl)
                    o_cr[into] = min(o_cr[into], cr)
                    o_off[into] = min(o_off[into], off)
                continue
            o_seg[out], o_pt[out], o_joint[out] = k, c_pt[c], j
            o_cl[out], o_cr[out], o_off[out] = cl, cr, off
            o_lo[out] = bound if sign < 0.0 else -np.inf
            o_up[out] = bound if sign > 0.0 else np.inf
            out += 1
    return out


@cached_jit()
def _grow(a, size):  # pragma: no cover - compiled
    out = np.empty(size)
    out[: a.size] = a
    return out


@cached_jit()
def _grow_int(a, size):  # pragma: no cover - compiled
    out = np.empty(size, dtype=np.int64)
    out[: a.size] = a
    return out


@cached_jit()
def _sign_on(cl, cr, off, xs, ys, count):  # pragma: no cover - compiled
    """+1 where cl x + cr y + off ≥ 0 on every vertex of the polygon, −1 where it is ≤ 0 on
    all (and not ≥ 0 on all), else 0."""
    hi, low = _extremes(cl, cr, off, xs, ys, count)
    if low >= 0.0:
        return 1.0
    if hi <= 0.0:
        return -1.0
    return 0.0


@cached_jit()
def _extremes(cl, cr, off, xs, ys, count):  # pragma: no cover - compiled
    """The largest and the smallest value of cl x + cr y + off over the polygon's vertices."""
    hi = -np.inf
    low = np.inf
    for v in range(count):
        value = cl * xs[v] + cr * ys[v] + off
        hi = max(hi, value)
        low = min(low, value)
    return hi, low


@cached_jit(error_model="numpy")
def envelope_crossing(g, w, d, kg, kw, kd, seg, at, joint, sign, limit):  # pragma: no cover
    """The smallest t = √α > 0 at which one of the sixteen sums of an interval (those of
    :func:`nearopt.timing.between._envelope_crossing`, formed here for G, W and D from their
    values and second differences κ) reaches its limit: sign · (G + W t² + D t − limit) = 0;
    inf where none does, −1 where one is above it already at t = 0 (or at it and rising). The
    intervals are (seg, at, joint) [segment, interval, joint]. The same arithmetic as
    :func:`nearopt.timing.between._first_crossing` on those sums."""
    best = np.inf
    for e in range(seg.size):
        k, j, i = seg[e], at[e], joint[e]
        cg = kg[k, j + 1, i] - kg[k, j, i]
        cw = kw[k, j + 1, i] - kw[k, j, i]
        cd = kd[k, j + 1, i] - kd[k, j, i]
        for side in range(2):
            for end in range(2):
                for s in (1.0, -1.0):
                    for t in (1.0, -1.0):
                        gs = g[k, j + side, i] + s * kg[k, j + end, i] / 8.0 + t * cg / 8.0
                        ws = w[k, j + side, i] + s * kw[k, j + end, i] / 8.0 + t * cw / 8.0
                        ds = d[k, j + side, i] + s * kd[k, j + end, i] / 8.0 + t * cd / 8.0
                        root = _crossing(sign * ws, sign * ds, sign * (gs - limit[i]))
                        if root < 0.0:
                            return -1.0
                        best = min(best, root)
    return best


@inline_jit(error_model="numpy")
def _crossing(w, d, c):  # pragma: no cover - compiled
    """The first t > 0 with c + d t + w t² = 0 (inf if none); −1 if c > 0, or c = 0 and the
    sum rises from there."""
    if c > 0.0 or (c == 0.0 and (d > 0.0 or (d == 0.0 and w > 0.0))):
        return -1.0
    if w == 0.0:
        return -c / d if d > 0.0 else np.inf
    disc = d * d - 4.0 * w * c
    root = np.sqrt(max(disc, 0.0))
    q = -0.5 * (d + (root if d >= 0.0 else -root))
    best = np.inf
    for t in (q / w, c / q):
        if np.isfinite(t) and t > 0.0 and disc >= 0.0:
            best = min(best, t)
    return best
