"""The banded interior-point kernel (nearopt.timing.banded) against SciPy's SLSQP on small
random programs of its form, and the rows it leaves out as implied."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize

from nearopt.timing._banded_kernels import implied_rows
from nearopt.timing.banded import BandedProgram, solve_banded

N, WIDTH = 9, 3


def _program(seed: int, squares: bool, roots: bool) -> BandedProgram:
    """Minimise Σ ω (c0 + Σ w (α·z + g)²)/√(ℓ·z) + lin·z over a band of 3, under z ≤ U, a
    random upper row per window, (roots) a row a·z − e√(ℓ·z) ≤ h per window, and z ≥ 0."""
    rng = np.random.default_rng(seed)
    starts = np.arange(N - WIDTH + 1)
    r_start, r_a, r_e, r_ell, r_h = [], [], [], [], []
    for st in starts:
        for row in (rng.uniform(0.2, 1.0, WIDTH), -np.eye(WIDTH)[0], -np.eye(WIDTH)[-1]):
            r_start.append(st)
            r_a.append(row)
            r_e.append(0.0)
            r_ell.append(np.zeros(WIDTH))
            r_h.append(rng.uniform(1.0, 2.0) if row.min() > 0 else 0.0)
        if roots:
            r_start.append(st)
            r_a.append(rng.uniform(0.5, 1.0, WIDTH))
            r_e.append(-rng.uniform(0.1, 0.5))
            r_ell.append(rng.uniform(0.5, 1.0, WIDTH))
            r_h.append(rng.uniform(0.5, 1.5))
    t_start = np.repeat(starts, 2)
    terms = t_start.size
    t_alpha = np.zeros((terms, 2, WIDTH))
    t_g = np.zeros((terms, 2))
    if squares:
        t_alpha = rng.normal(size=(terms, 2, WIDTH))
        t_g = rng.normal(size=(terms, 2))
    return BandedProgram(
        np.array(r_start, dtype=np.int64),
        np.array(r_a),
        np.array(r_e),
        np.array(r_ell),
        np.array(r_h),
        t_start.astype(np.int64),
        rng.uniform(0.2, 1.0, (terms, WIDTH)),
        rng.uniform(0.5, 2.0, terms),
        np.ones(terms),
        t_alpha,
        t_g,
        np.array([0.3, 0.7]) if squares else np.zeros(2),
        rng.uniform(0.0, 0.1, N),
    )


def _f(p: BandedProgram, z: np.ndarray) -> float:
    win = z[p.t_start[:, None] + np.arange(WIDTH)]
    r = np.einsum("pqw,pw->pq", p.t_alpha, win) + p.t_g
    u = p.t_c0 + np.sum(p.weights * r**2, axis=1)
    return float(p.lin @ z + np.sum(p.t_omega * u / np.sqrt(np.einsum("pw,pw->p", p.t_ell, win))))


def _c(p: BandedProgram, z: np.ndarray) -> np.ndarray:
    win = z[p.r_start[:, None] + np.arange(WIDTH)]
    root = np.sqrt(np.maximum(np.einsum("jw,jw->j", p.r_ell, win), 0.0))
    return np.einsum("jw,jw->j", p.r_a, win) + p.r_e * root - p.r_h


@pytest.mark.parametrize(
    ("seed", "squares", "roots"), [(0, False, False), (1, True, True), (2, True, False)]
)
def test_the_kernel_finds_slsqps_optimum(seed: int, squares: bool, roots: bool) -> None:
    p = _program(seed, squares, roots)
    z0 = np.full(N, 0.05)
    ours = solve_banded(p, z0)
    assert ours.converged, ours.message
    assert np.max(_c(p, ours.z)) <= 1e-9
    assert ours.value == pytest.approx(_f(p, ours.z), rel=1e-12)
    theirs = minimize(
        lambda z: _f(p, z),
        z0,
        method="SLSQP",
        constraints=[{"type": "ineq", "fun": lambda z: -_c(p, z)}],
        bounds=[(1e-9, None)] * N,
        options={"ftol": 1e-14, "maxiter": 2000},
    )
    assert theirs.success, theirs.message
    assert np.max(_c(p, theirs.x)) <= 1e-7
    assert ours.value == pytest.approx(theirs.fun, rel=1e-6)
    assert ours.value <= theirs.fun * (1 + 1e-9)  # a convex program: SLSQP finds no lower
    np.testing.assert_allclose(ours.z, theirs.x, rtol=1e-3, atol=1e-5)


def test_a_kernel_that_runs_out_of_iterations_says_so() -> None:
    p = _program(1, True, True)
    answer = solve_banded(p, np.full(N, 0.05), max_iterations=2)
    assert not answer.converged
    assert "not converged in 2 iterations" in answer.message


def test_implied_rows() -> None:
    """For z ≥ 0, a·z ≤ h is implied by a'·z ≤ h' of the same window when a/h ≤ a'/h' entry by
    entry; of two equal rows one stays; rows with h ≤ 0 stay and imply nothing."""
    a = np.array(
        [
            [1.0, 1.0, 0.0],  # implied by row 1 (a/h ≤ [1, 1, 0.5])
            [2.0, 2.0, 1.0],  # h = 2
            [1.0, -5.0, 0.0],  # implied by row 1 too
            [3.0, 0.0, 0.0],  # not: 3 > 1
            [2.0, 2.0, 1.0],  # equal to row 1: the later goes
            [-1.0, 0.0, 0.0],  # h = 0: stays
            [9.0, 9.0, 9.0],  # another window
        ]
    )
    h = np.array([1.0, 2.0, 1.0, 2.0, 2.0, 0.0, 1.0])
    start = np.array([0, 0, 0, 0, 0, 0, 1])
    order = np.argsort(start, kind="stable")
    group = np.flatnonzero(np.diff(start[order], prepend=-1, append=-2))
    implied = implied_rows(order, group, a, h)
    np.testing.assert_array_equal(implied, [True, False, True, False, True, False, False])


@pytest.mark.parametrize("seed", [1, 3, 4])
def test_rows_left_out_far_from_binding_give_the_same_optimum(seed: int) -> None:
    """A later program of a sequence (its bounds moved by up to 5 %) solved on the rows near
    binding at the last optimum has the whole program's optimum; so has one screened at a far
    reference (the start), whose optimum breaks rows that are then put back."""
    p = _program(seed, True, True)
    z0 = np.full(N, 0.05)
    last = solve_banded(p, z0)
    rng = np.random.default_rng(seed)
    later = p._replace(r_h=p.r_h * rng.uniform(0.95, 1.05, p.r_h.size))
    whole = solve_banded(later, z0)
    assert whole.converged, whole.message
    for reference, change in ((last.z, 0.01 * (last.z - z0)), (z0, np.zeros(N))):
        screened = solve_banded(later, z0, reference=reference, change=change)
        assert screened.converged, screened.message
        assert f"of {p.r_h.size} rows near binding" in screened.message  # (rows were left out)
        assert np.max(_c(later, screened.z)) <= 1e-9
        assert screened.value == pytest.approx(whole.value, rel=1e-8)
        np.testing.assert_allclose(screened.z, whole.z, rtol=1e-4, atol=1e-6)
