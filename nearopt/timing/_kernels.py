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


def _jit(**options: object):  # noqa: ANN202 - numba's decorator
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


@_jit(fastmath=FAST, error_model="numpy")
def iterate(z, s, y, left, cl, cr, sd, node, const, e_left, e_cl, e_cr, e_d, e_node, e_const,
            e_w, ds, scale, f_scale, tolerance, iterations, tau):  # pragma: no cover - compiled
    """Run up to ``iterations`` predictor-corrector steps on (z, s, y) in place.

    Four passes over the rows per iteration: (1) values, derivatives, residuals, the Newton
    matrix and the predictor's right-hand side; (2) the predictor's direction, its step and the
    sums that give its duality measure; (3) the corrector's right-hand side; (4) the corrector's
    direction and step, then the update. Returns (status, steps taken, F unscaled).
    """
    big_n = ds.size
    m = left.size
    ne = e_left.size
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
    q = np.zeros(big_n)
    ql = np.zeros(big_n)
    qr = np.zeros(big_n)
    qll = np.zeros(big_n)
    qrr = np.zeros(big_n)
    qlr = np.zeros(big_n)
    f_total = 0.0
    for it in range(iterations):
        # ---------------------------------------------------------- the objective at z
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
            q[k] = 0.0
            ql[k] = 0.0
            qr[k] = 0.0
            qll[k] = 0.0
            qrr[k] = 0.0
            qlr[k] = 0.0
        for j in range(ne):
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
            q[k] += 0.5 * wt * u * u
            ql[k] += wt * u * ul
            qr[k] += wt * u * ur
            qll[k] += wt * ul * ul
            qrr[k] += wt * ur * ur
            qlr[k] += wt * ul * ur
            if curv != 0.0:
                if nd == k:
                    qll[k] += wt * u * curv
                else:
                    qrr[k] += wt * u * curv
        f_total = 0.0
        for k in range(big_n):
            sl = lam[k] + lam[k + 1]
            t = 2.0 * ds[k] / sl
            dt = -t / sl
            d2 = 2.0 * t / (sl * sl)
            hl = hinv[k]
            hr = hinv[k + 1]
            tl = dt * hl
            tr = dt * hr
            one = 1.0 + q[k]
            f_total += t * one
            grad_l = (tl * one + t * ql[k]) * f_scale
            grad_r = (tr * one + t * qr[k]) * f_scale
            rd[k] += grad_l
            rd[k + 1] += grad_r
            rd_size[k] += abs(grad_l)
            rd_size[k + 1] += abs(grad_r)
            hdiag[k] += (d2 * hl * hl + dt * croot[k]) * one * f_scale
            hdiag[k] += (2.0 * tl * ql[k] + t * qll[k]) * f_scale
            hdiag[k + 1] += (d2 * hr * hr + dt * croot[k + 1]) * one * f_scale
            hdiag[k + 1] += (2.0 * tr * qr[k] + t * qrr[k]) * f_scale
            hoff[k] += (d2 * hl * hr * one + tl * qr[k] + tr * ql[k] + t * qlr[k]) * f_scale
        # ---------------------------------------------------------- pass 1 over the rows
        gap = 0.0
        rp_max = 0.0
        for j in range(m):
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
        rd_max = 0.0
        for k in range(1, big_n):
            rd_max = max(rd_max, (abs(rd[k]) - ROUNDING * rd_size[k]) * scale[k - 1])
        mu = gap / m
        rel = f_total * f_scale
        if gap <= tolerance * rel and rd_max <= tolerance * rel and rp_max <= tolerance:
            return CONVERGED, it, f_total
        # ---------------------------------------------------------- L D Lᵀ of D M D
        size = 0.0
        for i in range(nf):
            if abs(hdiag[i + 1] * scale[i] * scale[i]) > size:
                size = abs(hdiag[i + 1] * scale[i] * scale[i])
        delta = 0.0
        ok = False
        for _attempt in range(14):
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
        if not ok:
            return SINGULAR, it, f_total
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
                largest = min(largest, min(r_s if d_s < 0.0 else np.inf,
                                           r_y if d_y < 0.0 else np.inf))
                if phase == 0:
                    cross += s[j] * d_y + y[j] * d_s
                    square += d_s * d_y
            if phase == 0:
                step = min(1.0, largest, largest_z)
                mu_aff = (gap + step * cross + step * step * square) / m
                sigma_mu = (mu_aff / mu) ** 3 * mu
                # the corrector: complementarity target s y + Δs Δy − σμ
                for k in range(big_n + 1):
                    rhs[k] = 0.0
                for j in range(m):
                    comp = s[j] * y[j] + dsl[j] * dy[j] - sigma_mu
                    v = (comp - y[j] * rp[j]) * inv_s[j]
                    rhs[left[j]] += gl[j] * v
                    rhs[left[j] + 1] += gr[j] * v
                    dy[j] = (-comp + y[j] * rp[j]) * inv_s[j]
            else:
                step = min(1.0, tau * largest, largest_z)
        for i in range(nf):
            z[i] += step * dz[i]
            if not np.isfinite(z[i]):
                return NOT_FINITE, it + 1, f_total
        for j in range(m):
            s[j] += step * dsl[j]
            y[j] += step * dy[j]
    return RUNNING, iterations, f_total


@_jit()
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


@_jit()
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


@_jit()
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
