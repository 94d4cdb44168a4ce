"""The compiled loops of :mod:`nearopt.timing.banded` (numba): a primal-dual interior-point
method for a convex program whose every row and objective term touches a window of W
consecutive variables, so that its Newton matrix is banded (half-bandwidth W − 1).

Plain loops over the rows and the terms; one iteration is O(rows·W² + n·W²). Compiled on first
use and cached beside this file; see :mod:`nearopt.timing.banded` for the method.
"""

from __future__ import annotations

import numpy as np

from ._kernels import FAST, cached_jit, inline_jit

RUNNING, CONVERGED, SINGULAR, NOT_FINITE = 0, 1, 2, 3
STEP_TO_BOUNDARY = 0.995
FLOOR = 1e-4  # the centring target's floor, relative to the largest |∇L|


@inline_jit(fastmath=FAST, error_model="numpy")
def _dot(coef, start, z):  # pragma: no cover - compiled
    total = 0.0
    for a in range(coef.size):
        total += coef[a] * z[start + a]
    return total


@inline_jit(fastmath=FAST, error_model="numpy")
def _terms(
    z, t_start, t_ell, t_omega, t_c0, t_alpha, t_g, wts, lin, f_scale, gradf, band
):  # pragma: no cover - compiled
    """F(z) = f_scale (lin·z + Σ_p ω_p (c0_p + Σ_q w_q (α_pq·z + g_pq)²) / √(ℓ_p·z)), its
    gradient into ``gradf`` and its Hessian added to the lower band ``band``."""
    n = z.size
    p_count, width = t_ell.shape
    nsq = wts.size
    total = 0.0
    for i in range(n):
        total += lin[i] * z[i]
        gradf[i] = f_scale * lin[i]
    du = np.zeros(width)
    for p in range(p_count):
        st = t_start[p]
        v = _dot(t_ell[p], st, z)
        u = t_c0[p]
        for a in range(width):
            du[a] = 0.0
        for q in range(nsq):
            if wts[q] == 0.0:
                continue
            r = _dot(t_alpha[p, q], st, z) + t_g[p, q]
            u += wts[q] * r * r
            for a in range(width):
                du[a] += 2.0 * wts[q] * r * t_alpha[p, q, a]
        om = f_scale * t_omega[p]
        rv = 1.0 / np.sqrt(v)
        total += t_omega[p] * u * rv
        k1 = om * rv  # ∇u
        k2 = -0.5 * om * u * rv / v  # ℓ
        k3 = 0.75 * om * u * rv / (v * v)  # ℓℓᵀ
        k4 = -0.5 * om * rv / v  # ∇u ℓᵀ + ℓ ∇uᵀ
        for a in range(width):
            gradf[st + a] += k1 * du[a] + k2 * t_ell[p, a]
            for b in range(a + 1):
                h = k3 * t_ell[p, a] * t_ell[p, b] + k4 * (
                    du[a] * t_ell[p, b] + t_ell[p, a] * du[b]
                )
                for q in range(nsq):
                    if wts[q] != 0.0:
                        h += 2.0 * k1 * wts[q] * t_alpha[p, q, a] * t_alpha[p, q, b]
                band[st + a, a - b] += h
    return total


@inline_jit(fastmath=FAST, error_model="numpy")
def _cholesky(band, low):  # pragma: no cover - compiled
    """The banded Cholesky factor L (``low[i, k]`` = L[i, i − k]) of the lower band ``band``;
    False if a pivot is not positive."""
    n, width = band.shape
    for i in range(n):
        for k in range(min(i, width - 1), -1, -1):
            j = i - k  # column
            total = band[i, k]
            for c in range(max(0, i - width + 1), j):
                total -= low[i, i - c] * low[j, j - c]
            if k == 0:
                if not total > 0.0:
                    return False
                low[i, 0] = np.sqrt(total)
            else:
                low[i, k] = total / low[j, 0]
    return True


@inline_jit(fastmath=FAST, error_model="numpy")
def _back(low, rhs, out):  # pragma: no cover - compiled
    """out = (L Lᵀ)⁻¹ rhs."""
    n, width = low.shape
    for i in range(n):
        total = rhs[i]
        for k in range(1, min(i, width - 1) + 1):
            total -= low[i, k] * out[i - k]
        out[i] = total / low[i, 0]
    for i in range(n - 1, -1, -1):
        total = out[i]
        for k in range(1, min(n - 1 - i, width - 1) + 1):
            total -= low[i + k, k] * out[i + k]
        out[i] = total / low[i, 0]


@inline_jit(fastmath=FAST, error_model="numpy")
def _newton(
    z, r_start, r_a, r_e, r_ell, r_h, s, y, c, grad, gradf, rd, band
):  # pragma: no cover - compiled
    """One pass over the rows: each row's value c_j = a·z + e√(ℓ·z) − h (and, for a row with
    a √ term, its gradient into ``grad``: the others' is a), its share of the Newton matrix
    (Jᵀ(Y/S)J + Σ y_j ∇²c_j, into ``band``: ∇²c_j = −e/4 (ℓ·z)^{−3/2} ℓℓᵀ ≥ 0 for e ≤ 0) and of
    the gradient of the Lagrangian (rd = ∇F + Jᵀy). Returns Σ s_j y_j and the largest
    |c_j + s_j|."""
    m, width = r_a.shape
    for i in range(rd.size):
        rd[i] = gradf[i]
    gap = 0.0
    rp = 0.0
    for j in range(m):
        st = r_start[j]
        value = -r_h[j]
        for a in range(width):
            value += r_a[j, a] * z[st + a]
        yj = y[j]
        e = r_e[j]
        g = r_a
        hj = 0.0
        if e != 0.0:
            root = _dot(r_ell[j], st, z)
            sq = np.sqrt(root)
            value += e * sq
            half = 0.5 * e / sq
            for a in range(width):
                grad[j, a] = r_a[j, a] + half * r_ell[j, a]
            g = grad
            hj = -0.25 * e * yj / (root * sq)
        c[j] = value
        wj = yj / s[j]
        for a in range(width):
            ga = g[j, a]
            rd[st + a] += yj * ga
            wa = wj * ga
            for b in range(a + 1):
                band[st + a, a - b] += wa * g[j, b]
        if hj != 0.0:
            for a in range(width):
                for b in range(a + 1):
                    band[st + a, a - b] += hj * r_ell[j, a] * r_ell[j, b]
        gap += s[j] * yj
        rp = max(rp, abs(value + s[j]))
    return gap, rp


@inline_jit(fastmath=FAST, error_model="numpy")
def _rhs(r_start, r_a, r_e, grad, s, y, c, ds, dy, target, rd, rhs):  # pragma: no cover
    """The right-hand side −rd − Jᵀ(Y/S)(c + s − rc/y) of the Newton system for the
    complementarity target rc = s∘y + Δs∘Δy − target (Δs = Δy = 0: the predictor's)."""
    m, width = r_a.shape
    for i in range(rd.size):
        rhs[i] = -rd[i]
    for j in range(m):
        st = r_start[j]
        # y(c + s) − rc = y c − Δs Δy + target
        t = (y[j] * c[j] - ds[j] * dy[j] + target) / s[j]
        g = grad if r_e[j] != 0.0 else r_a
        for a in range(width):
            rhs[st + a] -= g[j, a] * t
    return 0


@inline_jit(fastmath=FAST, error_model="numpy")
def _steps(
    r_start, r_a, r_e, grad, s, y, c, dz, ds_old, dy_old, target, ds, dy
):  # pragma: no cover - compiled
    """Δs = −(c + s) − JΔz and Δy = (−rc − yΔs)/s (rc as in :func:`_rhs`), into ``ds``, ``dy``;
    returns the longest step ≤ 1 that keeps s, y > 0 (STEP_TO_BOUNDARY of the way) and the
    sums Σ (sΔy + yΔs), Σ ΔsΔy (the duality measure after a step α: Σ s y + α·first + α²·second)."""
    m, width = r_a.shape
    step = 1.0
    first = 0.0
    second = 0.0
    for j in range(m):
        st = r_start[j]
        g = grad if r_e[j] != 0.0 else r_a
        jd = 0.0
        for a in range(width):
            jd += g[j, a] * dz[st + a]
        sj, yj = s[j], y[j]
        dsj = -(c[j] + sj) - jd
        dyj = (-(sj * yj + ds_old[j] * dy_old[j] - target) - yj * dsj) / sj
        ds[j] = dsj
        dy[j] = dyj
        if dsj < 0.0:
            step = min(step, -STEP_TO_BOUNDARY * sj / dsj)
        if dyj < 0.0:
            step = min(step, -STEP_TO_BOUNDARY * yj / dyj)
        first += sj * dyj + yj * dsj
        second += dsj * dyj
    return step, first, second


@inline_jit(fastmath=FAST, error_model="numpy")
def _roots_step(step, z, dz, r_start, r_e, r_ell, t_start, t_ell, has_roots):  # pragma: no cover
    """``step`` shortened so that no ℓ·z of a term (or of a row's √ term) falls below a quarter
    of its value."""
    for p in range(t_start.size):
        v = _dot(t_ell[p], t_start[p], z)
        dv = _dot(t_ell[p], t_start[p], dz)
        if dv < 0.0:
            step = min(step, -0.75 * v / dv)
    for j in range(r_start.size if has_roots else 0):
        if r_e[j] != 0.0:
            v = _dot(r_ell[j], r_start[j], z)
            dv = _dot(r_ell[j], r_start[j], dz)
            if dv < 0.0:
                step = min(step, -0.75 * v / dv)
    return step


@cached_jit(fastmath=FAST, error_model="numpy")
def iterate(
    z,
    s,
    y,
    r_start,
    r_a,
    r_e,
    r_ell,
    r_h,
    t_start,
    t_ell,
    t_omega,
    t_c0,
    t_alpha,
    t_g,
    wts,
    lin,
    f_scale,
    tolerance,
    iterations,
):  # pragma: no cover - compiled
    """Mehrotra's predictor-corrector on (z, s, y) in place, one step length for all three.

    Six passes over the rows per iteration: the Newton matrix and the residuals; the
    predictor's right-hand side, then its Δs, Δy and step; the corrector's right-hand side,
    then its Δs, Δy and step; the update.

    Returns (status, iterations taken, F(z) unscaled, and the last duality measure Σ s y,
    largest |∇L| (scaled) and largest |c + s|)."""
    n = z.size
    m, width = r_a.shape
    c = np.zeros(m)
    grad = np.zeros((m, width))
    gradf = np.zeros(n)
    band = np.zeros((n, width))
    low = np.zeros((n, width))
    rd = np.zeros(n)
    rhs = np.zeros(n)
    dz = np.zeros(n)
    ds = np.zeros(m)
    dy = np.zeros(m)
    ds2 = np.zeros(m)
    dy2 = np.zeros(m)
    f = 0.0
    gap = rd_max = rp = np.inf
    has_roots = False
    for j in range(m):
        has_roots = has_roots or r_e[j] != 0.0
    for it in range(iterations):
        band[:, :] = 0.0
        f = _terms(z, t_start, t_ell, t_omega, t_c0, t_alpha, t_g, wts, lin, f_scale, gradf, band)
        gap, rp = _newton(z, r_start, r_a, r_e, r_ell, r_h, s, y, c, grad, gradf, rd, band)
        rd_max = 0.0
        for i in range(n):
            rd_max = max(rd_max, abs(rd[i]))
        fs = abs(f) * f_scale
        if gap <= tolerance * fs and rd_max <= tolerance * max(fs, 1.0) and rp <= tolerance:
            return CONVERGED, it, f, gap, rd_max, rp
        for i in range(n):  # each diagonal by its own size: Y/S spans 40 orders near the end
            band[i, 0] += 1e-14 * band[i, 0] + 1e-300
        if not _cholesky(band, low):
            return SINGULAR, it, f, gap, rd_max, rp
        mu = gap / m
        # predictor: rc = s∘y
        ds[:] = 0.0
        dy[:] = 0.0
        _rhs(r_start, r_a, r_e, grad, s, y, c, ds, dy, 0.0, rd, rhs)
        _back(low, rhs, dz)
        step, first, second = _steps(r_start, r_a, r_e, grad, s, y, c, dz, ds, dy, 0.0, ds, dy)
        step = _roots_step(step, z, dz, r_start, r_e, r_ell, t_start, t_ell, has_roots)
        after = gap + step * first + step * step * second
        # the centring target σμ (Mehrotra), kept above a share of the dual residual so that
        # the complementarity does not reach 0 before the gradient of the Lagrangian
        target = max((max(after, 0.0) / gap) ** 3 * mu, min(0.1 * mu, FLOOR * rd_max))
        # corrector: rc = s∘y + Δs∘Δy − σμ
        _rhs(r_start, r_a, r_e, grad, s, y, c, ds, dy, target, rd, rhs)
        _back(low, rhs, dz)
        step = _steps(r_start, r_a, r_e, grad, s, y, c, dz, ds, dy, target, ds2, dy2)[0]
        step = _roots_step(step, z, dz, r_start, r_e, r_ell, t_start, t_ell, has_roots)
        for i in range(n):
            z[i] += step * dz[i]
            if not np.isfinite(z[i]):
                return NOT_FINITE, it + 1, f, gap, rd_max, rp
        for j in range(m):
            s[j] += step * ds2[j]
            y[j] += step * dy2[j]
    return RUNNING, iterations, f, gap, rd_max, rp


@cached_jit(fastmath=FAST, error_model="numpy")
def implied_rows(order, group, a, h):  # pragma: no cover - compiled
    """Which rows a·z ≤ h another row of the same window implies for z ≥ 0: row i is implied
    by row j when both bounds are positive and a_i/h_i ≤ a_j/h_j coefficient by coefficient
    (of two equal rows, the later). ``order`` lists the rows window by window, ``group`` the
    offsets of the windows in it."""
    m, width = a.shape
    implied = np.zeros(m, dtype=np.bool_)
    for g in range(group.size - 1):
        lo, hi = group[g], group[g + 1]
        for p in range(lo, hi):
            i = order[p]
            if not h[i] > 0.0:
                continue
            for q in range(lo, hi):
                j = order[q]
                if j == i or implied[j] or not h[j] > 0.0:
                    continue
                below, equal = True, True
                for c in range(width):
                    left = a[i, c] * h[j]
                    right = a[j, c] * h[i]
                    if left > right:
                        below = False
                        break
                    if left != right:
                        equal = False
                if below and (not equal or j < i):
                    implied[i] = True
                    break
    return implied
