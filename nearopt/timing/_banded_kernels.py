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
def _rows(z, r_start, r_a, r_e, r_ell, r_h, c, grad, curv):  # pragma: no cover - compiled
    """Each row's value c_j = a·z + e√(ℓ·z) − h, its gradient (m, W) and the coefficient of
    ℓℓᵀ in its Hessian (−e/4 (ℓ·z)^{−3/2} ≥ 0 for e ≤ 0)."""
    m, width = r_a.shape
    for j in range(m):
        st = r_start[j]
        value = _dot(r_a[j], st, z) - r_h[j]
        e = r_e[j]
        if e != 0.0:
            root = _dot(r_ell[j], st, z)
            sq = np.sqrt(root)
            value += e * sq
            half = 0.5 * e / sq
            for a in range(width):
                grad[j, a] = r_a[j, a] + half * r_ell[j, a]
            curv[j] = -0.25 * e / (root * sq)
        else:
            for a in range(width):
                grad[j, a] = r_a[j, a]
            curv[j] = 0.0
        c[j] = value


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
def _newton(r_start, r_ell, s, y, c, grad, curv, gradf, rd, band):  # pragma: no cover - compiled
    """The rows' share of the Newton matrix (Jᵀ(Y/S)J + Σ y_j ∇²c_j, into ``band``) and of the
    gradient of the Lagrangian (rd = ∇F + Jᵀy); returns Σ s_j y_j and the largest |c_j + s_j|."""
    m, width = grad.shape
    for i in range(rd.size):
        rd[i] = gradf[i]
    gap = 0.0
    rp = 0.0
    for j in range(m):
        st = r_start[j]
        yj = y[j]
        wj = yj / s[j]
        hj = yj * curv[j]
        for a in range(width):
            ga = grad[j, a]
            rd[st + a] += yj * ga
            wa = wj * ga
            for b in range(a + 1):
                band[st + a, a - b] += wa * grad[j, b]
        if hj != 0.0:
            for a in range(width):
                for b in range(a + 1):
                    band[st + a, a - b] += hj * r_ell[j, a] * r_ell[j, b]
        gap += s[j] * yj
        rp = max(rp, abs(c[j] + s[j]))
    return gap, rp


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
def _direction(r_start, grad, s, y, c, rd, rc, low, dz, ds, dy, rhs):  # pragma: no cover - compiled
    """The Newton direction for the residuals rd (dual), c + s (primal) and rc (s∘y − σμ…):
    (H + Jᵀ(Y/S)J) Δz = −rd − Jᵀ(Y/S)(c + s − rc/y), then Δy and Δs."""
    m, width = grad.shape
    n = rd.size
    for i in range(n):
        rhs[i] = -rd[i]
    for j in range(m):
        st = r_start[j]
        t = (y[j] * (c[j] + s[j]) - rc[j]) / s[j]
        for a in range(width):
            rhs[st + a] -= grad[j, a] * t
    _back(low, rhs, dz)
    for j in range(m):
        st = r_start[j]
        jd = 0.0
        for a in range(width):
            jd += grad[j, a] * dz[st + a]
        # Δs = −(c + s) − JΔz;  S Δy + Y Δs = −rc
        ds[j] = -(c[j] + s[j]) - jd
        dy[j] = (-rc[j] - y[j] * ds[j]) / s[j]


@inline_jit(fastmath=FAST, error_model="numpy")
def _longest(
    s, y, ds, dy, z, dz, r_start, r_e, r_ell, t_start, t_ell, has_roots
):  # pragma: no cover - compiled
    """The longest step ≤ 1 that keeps s, y > 0 (STEP_TO_BOUNDARY of the way) and every root
    ℓ·z above a quarter of its value."""
    step = 1.0
    for j in range(s.size):
        if ds[j] < 0.0:
            step = min(step, -STEP_TO_BOUNDARY * s[j] / ds[j])
        if dy[j] < 0.0:
            step = min(step, -STEP_TO_BOUNDARY * y[j] / dy[j])
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

    Returns (status, iterations taken, F(z) unscaled, and the last duality measure Σ s y,
    largest |∇L| (scaled) and largest |c + s|)."""
    n = z.size
    m, width = r_a.shape
    c = np.zeros(m)
    grad = np.zeros((m, width))
    curv = np.zeros(m)
    gradf = np.zeros(n)
    band = np.zeros((n, width))
    low = np.zeros((n, width))
    rd = np.zeros(n)
    rhs = np.zeros(n)
    dz = np.zeros(n)
    ds = np.zeros(m)
    dy = np.zeros(m)
    dz2 = np.zeros(n)
    ds2 = np.zeros(m)
    dy2 = np.zeros(m)
    rc = np.zeros(m)
    f = 0.0
    gap = rd_max = rp = np.inf
    has_roots = False
    for j in range(m):
        has_roots = has_roots or r_e[j] != 0.0
    for it in range(iterations):
        band[:, :] = 0.0
        f = _terms(z, t_start, t_ell, t_omega, t_c0, t_alpha, t_g, wts, lin, f_scale, gradf, band)
        _rows(z, r_start, r_a, r_e, r_ell, r_h, c, grad, curv)
        gap, rp = _newton(r_start, r_ell, s, y, c, grad, curv, gradf, rd, band)
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
        for j in range(m):
            rc[j] = s[j] * y[j]
        _direction(r_start, grad, s, y, c, rd, rc, low, dz, ds, dy, rhs)
        step = _longest(s, y, ds, dy, z, dz, r_start, r_e, r_ell, t_start, t_ell, has_roots)
        after = 0.0
        for j in range(m):
            after += (s[j] + step * ds[j]) * (y[j] + step * dy[j])
        # the centring target σμ (Mehrotra), kept above a share of the dual residual so that
        # the complementarity does not reach 0 before the gradient of the Lagrangian
        target = max((after / gap) ** 3 * mu, min(0.1 * mu, FLOOR * rd_max))
        # corrector: rc = s∘y + Δs∘Δy − σμ
        for j in range(m):
            rc[j] = s[j] * y[j] + ds[j] * dy[j] - target
        _direction(r_start, grad, s, y, c, rd, rc, low, dz2, ds2, dy2, rhs)
        step = _longest(s, y, ds2, dy2, z, dz2, r_start, r_e, r_ell, t_start, t_ell, has_roots)
        for i in range(n):
            z[i] += step * dz2[i]
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
