"""Stage 2's convex model solved by nearopt's joint interior-point method against Clarabel's
conic form of the same model, on models built as stage 2 builds them (stage 1's rows at its
optimal timing, linearised in the path), over URDF arms, with and without the energy term."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import load, random_configuration

import nearopt
from nearopt.paper_example import THETA_0, THETA_E
from nearopt.planning import path_basis, row_path_jacobian
from nearopt.timing import (
    Discretisation,
    LinearRows,
    build_timing_problem,
    is_solved,
    solve_conic,
    solve_joint,
    solve_timing,
)


def _model(name: str, weight: float, controls: int = 6, grid: int = 40) -> dict:
    """Stage 1's rows of a bent path at its optimal timing z, linearised in the path's interior
    control points p (a trust region of 0.05 rad), a via-point at σ = 0.5 kept (B(σ) Δp = 0),
    the torques and their limits apart (the arguments both solvers take)."""
    robot = load(name).with_limits(acceleration=30.0)
    rng = np.random.default_rng(11)
    if name == "two_link":
        q0, qe = THETA_0, THETA_E
    else:
        q0, qe = random_configuration(robot, rng), random_configuration(robot, rng)
    controls = np.array(nearopt.BSplinePath.line(q0, qe, controls).control_points)
    controls[1:-1] += rng.normal(scale=0.1, size=controls[1:-1].shape)
    path = nearopt.BSplinePath(controls)
    problem = build_timing_problem(robot, path, grid=grid)
    disc = Discretisation(problem)
    cost = nearopt.TorqueCost(weight)
    z = solve_timing(problem, cost).b[1:-1]
    rows = disc.linear_rows(z)
    full = sp.hstack([rows.matrix, row_path_jacobian(robot, disc, z, path_basis(path, disc))])
    full = full.tocsr()
    t = disc.blocks.torque
    others = np.r_[disc.blocks.acceleration, disc.blocks.speed]
    via = sp.csr_matrix(np.kron(path.basis(np.array([0.5]))[:, 1:-1], np.eye(robot.n)))
    n_p = full.shape[1] - z.size
    linear = LinearRows(
        sp.vstack([full[others], sp.hstack([sp.csr_matrix((robot.n, z.size)), via])]).tocsr(),
        np.r_[rows.lower[others], np.zeros(robot.n)],
        np.r_[rows.upper[others], np.zeros(robot.n)],
    )
    return {
        "ds": disc.ds,
        "weights": cost.torque_weights(robot.n),
        "rows": linear,
        "torque": (full[t], disc.upper[t] - rows.upper[t]),
        "z_upper": disc.z_upper,
        "p_bounds": (np.full(n_p, -0.05), np.full(n_p, 0.05)),
        "torque_limits": (disc.lower[t], disc.upper[t]),
        "start": z,
    }


def _cost(model: dict, z: np.ndarray, p: np.ndarray) -> float:
    """F of the model at (z, p), summed here from its definition."""
    ds, weights = model["ds"], model["weights"]
    big_n = ds.size
    lam = np.sqrt(np.r_[0.0, z, 0.0])
    y = lam[:-1] + lam[1:]
    t_mat, u0 = model["torque"]
    u = (t_mat @ np.r_[z, p] + u0).reshape(-1, 2 * big_n)  # joint-major: (n, 2N)
    q = 0.5 * (weights[:, None] * (u[:, :big_n] ** 2 + u[:, big_n:] ** 2)).sum(axis=0)
    return float(np.sum(2.0 * ds * (1.0 + q) / y))


@pytest.mark.parametrize("weight", [0.0, 1e-3], ids=["time", "energy"])
@pytest.mark.parametrize("name", ["two_link", "ur5", "panda"])
def test_joint_solver_finds_the_conic_optimum(name: str, weight: float) -> None:
    """The same optimum as Clarabel (F within 1e-6 relative, or lower), a point that keeps
    every row, torque limit, bound and the via-point, and the F it reports is F at its point."""
    model = _model(name, weight)
    answer = solve_joint(**model)
    assert answer.converged, answer.message
    conic = solve_conic(**{k: v for k, v in model.items() if k != "start"}, tolerance=1e-9)
    assert is_solved(conic.status)
    assert answer.objective <= conic.objective * (1 + 1e-6)
    assert answer.objective >= conic.objective * (1 - 1e-6)  # neither finds a lower F
    assert answer.objective == pytest.approx(_cost(model, answer.z, answer.p), rel=1e-12)
    x = np.r_[answer.z, answer.p]
    rows = model["rows"]
    values = rows.matrix @ x
    scale = np.maximum(np.abs(np.where(np.isfinite(rows.upper), rows.upper, 0.0)), 1.0)
    assert np.all(values <= rows.upper + 1e-7 * scale)
    assert np.all(values >= rows.lower - 1e-7 * scale)
    t_mat, u0 = model["torque"]
    u = t_mat @ x + u0
    low, high = model["torque_limits"]
    span = np.where(np.isfinite(high), np.abs(high), 1.0)
    assert np.all(u <= high + 1e-7 * span) and np.all(u >= low - 1e-7 * span)
    assert np.all(np.abs(answer.p) <= 0.05 * (1 + 1e-9))
    assert np.all(answer.z >= 0.0) and np.all(answer.z <= model["z_upper"] * (1 + 1e-7))
    assert np.max(np.abs(rows.matrix[-load(name).n :] @ x)) <= 1e-8  # on the via-point
    assert answer.objective < _cost(model, model["start"], 0.0 * answer.p)  # the path moved


@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_the_banded_newton_system_gives_the_dense_answer(
    name: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """With stage 2's 16 control points on 64 segments every row is local along the path: the
    Newton matrix is held as a band a quarter of its size or less, and the answer is the one of
    the whole matrix factorised densely (F to 1e-12, the same iterations) and Clarabel's."""
    from nearopt.timing import joint

    model = _model(name, 1e-3, controls=16, grid=64)
    rows = model["rows"]
    mat = sp.vstack([model["torque"][0], rows.matrix, sp.eye(rows.matrix.shape[1])]).tocsr()
    mat.sort_indices()
    band = joint._Band.of(mat, model["start"].size)
    assert not band.dense and 4 * band.kd <= mat.shape[1]
    banded = solve_joint(**model)
    monkeypatch.setattr(
        joint._Band, "of", lambda m, nz: joint._Band(np.arange(m.shape[1]), m.shape[1] - 1)
    )
    dense = solve_joint(**model)
    assert banded.converged and dense.converged
    assert banded.iterations == dense.iterations
    assert banded.objective == pytest.approx(dense.objective, rel=1e-12)
    np.testing.assert_allclose(banded.p, dense.p, atol=1e-9 * 0.05)
    conic = solve_conic(**{k: v for k, v in model.items() if k != "start"}, tolerance=1e-9)
    assert banded.objective == pytest.approx(conic.objective, rel=1e-6)
