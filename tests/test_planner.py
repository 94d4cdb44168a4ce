"""Stage 2 and the planner: gradients against finite differences, the paper's example, any arm."""

from __future__ import annotations

import numpy as np
import pytest
from checks import assert_independent_checks
from conftest import load, random_configuration

import nearopt
from nearopt.paper_example import BEST_KNOWN_DURATION, BEST_KNOWN_J, TABLE_2, THETA_0, THETA_E
from nearopt.paper_example import COST as PAPER_COST
from nearopt.planning import nominal_motion, path_basis, row_path_jacobian, torque_gradient
from nearopt.timing import Discretisation, build_timing_problem, solve_timing

PAPER_J6 = TABLE_2[-1].J  # after six iterations


def end_points(robot: nearopt.Robot, seed: int) -> tuple[np.ndarray, np.ndarray]:
    if robot.name == "two_link":
        return THETA_0, THETA_E
    rng = np.random.default_rng(seed)
    return random_configuration(robot, rng), random_configuration(robot, rng)


# ------------------------------------------------------------------ derivatives
@pytest.mark.parametrize("name", ["two_link", "ur5", "panda"])
def test_row_path_jacobian_matches_finite_differences(name: str) -> None:
    """∂(stage 1's rows)/∂(control points) at a fixed timing, against central differences of the
    rows rebuilt for the perturbed paths (torques with damping, accelerations, speeds): exact
    for the rows at the samples; the rows between the samples (the bounds of the motion inside
    the segments) are interpolated between the derivatives at their segment's ends, an O(Δσ²)
    approximation for stage 2's convex model (every step it proposes is timed again exactly),
    within 1 % of the largest entry at N = 60 (0.6 % measured)."""
    robot = load(name).with_limits(acceleration=30.0)
    rng = np.random.default_rng(5)
    q0, qe = end_points(robot, seed=5)
    controls = np.array(nearopt.BSplinePath.line(q0, qe, 6).control_points)
    controls[1:-1] += rng.normal(scale=0.1, size=controls[1:-1].shape)
    path = nearopt.BSplinePath(controls)
    problem = build_timing_problem(robot, path, grid=60)
    disc = Discretisation(problem)
    z = solve_timing(problem, PAPER_COST).b[1:-1]
    jac = row_path_jacobian(robot, disc, z, path_basis(path, disc)).toarray()
    # stage 2's form (the torque rows on the control points nonzero at each knot, no rows
    # between the samples): the same numbers where it has rows
    inner = row_path_jacobian(robot, disc, z, path_basis(path, disc), between=False).toarray()
    tail = disc.blocks.torque_between.start
    np.testing.assert_array_equal(inner[:tail], jac[:tail])
    assert not inner[tail:].any()
    h = 1e-6
    for column in (0, 7, jac.shape[1] - 1):
        j, i = divmod(column, robot.n)
        values = []
        for sign in (1.0, -1.0):
            moved = controls.copy()
            moved[j + 1, i] += sign * h
            rebuilt = Discretisation(
                build_timing_problem(robot, nearopt.BSplinePath(moved), grid=60)
            )
            assert np.array_equal(rebuilt.joint, disc.joint)  # the same rows, in order
            values.append(rebuilt.values(z))
        fd = (values[0] - values[1]) / (2 * h)
        between = np.zeros(fd.size, dtype=bool)
        for block in (
            disc.blocks.torque_between,
            disc.blocks.acceleration_between,
            disc.blocks.speed_between,
        ):
            between[block] = True
        assert between.any()
        np.testing.assert_allclose(
            jac[~between, column], fd[~between], atol=1e-7 * np.abs(jac).max()
        )
        np.testing.assert_allclose(jac[between, column], fd[between], atol=1e-2 * np.abs(jac).max())


@pytest.mark.parametrize("name", ["two_link", "ur5"])
def test_torque_gradient_matches_finite_differences(name: str) -> None:
    """η(t) of eq. (23) against J(u + εφ) by forward simulation (ABA) of the perturbed torques."""
    robot = load(name)
    q0, qe = end_points(robot, seed=2)
    timing = nearopt.optimal_timing(robot, nearopt.StraightPath(q0, qe), PAPER_COST, grid=60)
    t, _, u = nominal_motion(robot, timing.trajectory, 0.9 * timing.duration)
    n = robot.n
    target = np.concatenate([qe, np.zeros(n)]) + 0.05  # so that F and p(T) are not zero
    gamma = 0.1

    def rollout(torques: np.ndarray) -> tuple[np.ndarray, float]:
        """x(t) on the grid t and J = F(x(T)) + ∫ f0 under u interpolated linearly.

        Classical RK4 with 8 steps per grid interval: deterministic (an adaptive integrator's
        step choices differ between the ± runs and put noise into the difference) and smooth in
        u, with an error far below the differences measured here.
        """

        def rhs(y: np.ndarray, uk: np.ndarray) -> np.ndarray:
            qdd = robot.forward_dynamics(y[:n], y[n : 2 * n], uk)
            f0 = PAPER_COST(y[None, :n], y[None, n : 2 * n], uk[None])[0]
            return np.concatenate([y[n : 2 * n], qdd, [f0]])

        y = np.concatenate([q0, np.zeros(n), [0.0]])
        states = [y[: 2 * n]]
        sub = 8
        for k in range(t.size - 1):
            h = (t[k + 1] - t[k]) / sub
            for m in range(sub):
                w0, w1 = m / sub, (m + 1) / sub
                ua = (1 - w0) * torques[k] + w0 * torques[k + 1]
                ub = (1 - w1) * torques[k] + w1 * torques[k + 1]
                um = 0.5 * (ua + ub)
                k1 = rhs(y, ua)
                k2 = rhs(y + 0.5 * h * k1, um)
                k3 = rhs(y + 0.5 * h * k2, um)
                k4 = rhs(y + h * k3, ub)
                y = y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            states.append(y[: 2 * n])
        x = np.array(states)
        return x, gamma * np.sum((x[-1] - target) ** 2) + y[-1]

    x, _ = rollout(u)
    eta = torque_gradient(robot, t, x, u, PAPER_COST, target, gamma)
    for i in sorted({0, n - 1}):
        phi = np.zeros_like(u)
        phi[:, i] = np.sin(np.pi * t / t[-1]) * (1 + t / t[-1])
        eps = 1e-4
        fd = (rollout(u + eps * phi)[1] - rollout(u - eps * phi)[1]) / (2 * eps)
        predicted = np.trapezoid(np.sum(eta * phi, axis=1), t)
        # A(t) and f0's gradient are interpolated linearly between 401 samples: O(Δt²) error
        assert predicted == pytest.approx(fd, rel=2e-3, abs=1e-6), (i, predicted, fd)


# ------------------------------------------------------------------ the paper's example
@pytest.fixture(scope="module")
def paper_plan() -> nearopt.PlanResult:
    return nearopt.plan(load("two_link"), THETA_0, THETA_E, PAPER_COST, grid=200)


def test_paper_example_beats_the_paper_and_reaches_the_best_known(
    paper_plan: nearopt.PlanResult,
) -> None:
    result = paper_plan
    assert result.J < PAPER_J6
    assert result.J <= BEST_KNOWN_J * (1 + 1e-3), result.J
    assert result.J >= BEST_KNOWN_J * (1 - 1e-3)  # not below an optimum by more than IPOPT's error
    assert result.duration == pytest.approx(BEST_KNOWN_DURATION, abs=2e-3)
    assert result.status == nearopt.StopReason.CONVERGED
    assert result.J < result.initial.J


def test_paper_example_plan_passes_independent_checks(paper_plan: nearopt.PlanResult) -> None:
    robot = load("two_link")
    assert_independent_checks(
        robot, paper_plan.trajectory, PAPER_COST, paper_plan.J, THETA_0, THETA_E
    )


def test_every_iterate_meets_the_end_conditions_and_lowers_j(
    paper_plan: nearopt.PlanResult,
) -> None:
    history = paper_plan.history
    # iterate 0 is the straight line, timed on the optimisation grid like every iterate
    assert history[0].J == pytest.approx(paper_plan.initial.objective, rel=2e-3)
    assert all(b.J < a.J for a, b in zip(history[:-1], history[1:], strict=True))
    for it in history:
        ends = it.path(np.array([0.0, it.path.s_end]), 0)
        np.testing.assert_allclose(ends, [THETA_0, THETA_E], atol=1e-8, rtol=0)


def test_paper_update_lowers_j_and_keeps_the_ends() -> None:
    """Section 6's own update (η, clipped u*, boundary-value problem) from the straight line."""
    robot = load("two_link")
    seen: list[nearopt.Iteration] = []
    result = nearopt.plan(
        robot,
        THETA_0,
        THETA_E,
        PAPER_COST,
        method="paper",
        grid=100,
        max_iterations=3,
        callback=seen.append,
    )
    assert len(result.history) == 4 and seen == list(result.history)  # the line first
    assert all(b.J < a.J for a, b in zip(result.history[:-1], result.history[1:], strict=True))
    assert result.J < result.initial.J * 0.99
    for it in result.history:
        ends = it.path(np.array([0.0, it.path.s_end]), 0)
        np.testing.assert_allclose(ends, [THETA_0, THETA_E], atol=1e-8, rtol=0)
    assert_independent_checks(robot, result.trajectory, PAPER_COST, result.J, THETA_0, THETA_E)


# ------------------------------------------------------------------ URDF arms
@pytest.mark.parametrize("name", ["two_link", "ur5", "panda"])
def test_plan_on_urdf_arms(name: str) -> None:
    """A short plan on each arm: better than the straight line, verified, within every limit."""
    robot = load(name)
    q0, qe = end_points(robot, seed=9)
    result = nearopt.plan(
        robot,
        q0,
        qe,
        PAPER_COST,
        grid=60,
        options=nearopt.SCPOptions(control_points=6),
        max_iterations=15,
    )
    assert result.J < result.initial.J
    assert_independent_checks(robot, result.trajectory, PAPER_COST, result.J, q0, qe)


def test_position_limits_bind_when_the_free_optimum_leaves_them() -> None:
    """Narrow limits around the straight line: the plan stays inside, the unlimited one does not."""
    robot = load("two_link")
    lo = np.minimum(THETA_0, THETA_E) - 0.05
    hi = np.maximum(THETA_0, THETA_E) + 0.05
    narrow = robot.with_limits(position=(lo, hi))
    free = nearopt.plan(robot, THETA_0, THETA_E, PAPER_COST, grid=60, max_iterations=40)
    q_free = free.trajectory.sample(500.0).q
    assert np.any(q_free < lo) or np.any(q_free > hi)
    bound = nearopt.plan(narrow, THETA_0, THETA_E, PAPER_COST, grid=60, max_iterations=40)
    assert bound.J < bound.initial.J
    assert_independent_checks(narrow, bound.trajectory, PAPER_COST, bound.J, THETA_0, THETA_E)


def test_plan_rejects_bad_requests() -> None:
    robot = load("two_link")
    with pytest.raises(nearopt.ConfigurationError, match="method"):
        nearopt.plan(robot, THETA_0, THETA_E, method="newton")
    with pytest.raises(nearopt.ConfigurationError, match="PaperOptions"):
        nearopt.plan(robot, THETA_0, THETA_E, method="paper", options=nearopt.SCPOptions())
    with pytest.raises(nearopt.ConfigurationError, match="control_points"):
        nearopt.plan(robot, THETA_0, THETA_E, options=nearopt.SCPOptions(control_points=1))
    with pytest.raises(nearopt.ConfigurationError, match="zero-length"):
        nearopt.plan(robot, THETA_0, THETA_0)
    for bad in (-1, 1.5, True, 4):
        with pytest.raises(nearopt.ConfigurationError, match="refinements must be an integer"):
            nearopt.plan(robot, THETA_0, THETA_E, options=nearopt.SCPOptions(refinements=bad))
    narrow = robot.with_limits(position=([-1.0, -1.0], [1.0, 1.0]))
    with pytest.raises(nearopt.ConfigurationError, match="joint2"):
        nearopt.plan(narrow, [0.0, 0.0], [0.5, -1.5])


@pytest.mark.slow
def test_many_control_points_do_not_stall_on_a_coarse_iterate_grid() -> None:
    """48 control points with the default 64-segment iterate grid: the iterates are timed on at
    least 4 segments per control point, so the plan improves the line as 16 points do (it
    returned the line, converged after 5 rejected steps, before)."""
    robot = load("panda")
    lo = np.maximum(robot.limits.position_lower, -np.pi)
    hi = np.minimum(robot.limits.position_upper, np.pi)
    q0, qe = lo + 0.3 * (hi - lo), lo + 0.7 * (hi - lo)
    cost = nearopt.TorqueCost(weights=0.5 / robot.limits.effort_upper**2)
    many = nearopt.plan(robot, q0, qe, cost, options=nearopt.SCPOptions(control_points=48))
    few = nearopt.plan(robot, q0, qe, cost, options=nearopt.SCPOptions(control_points=16))
    assert few.J < 0.95 * few.initial.J  # 11 % lower than the line
    assert many.J <= 1.001 * few.J, (many.J, few.J)


def test_a_refined_path_is_the_same_curve_with_half_again_the_control_points() -> None:
    rng = np.random.default_rng(2)
    path = nearopt.BSplinePath(rng.normal(size=(18, 3)), np.sort(rng.uniform(0, 1, 14)))
    fine = path.refined()
    spans = np.unique(path.knots).size - 1  # 15
    assert fine.control_points.shape == (18 + (spans + 1) // 2, 3)
    s = np.linspace(0.0, 1.0, 997)
    for order in (0, 1, 2, 3):
        np.testing.assert_allclose(fine(s, order), path(s, order), atol=1e-9 * 10**order)


@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_the_refined_run_lowers_j(name: str) -> None:
    """After stage 2 converges on 16 control points it goes on from the same curve on 24 (the
    default): J no higher, and lower on these seeded motions (0.07–0.28 % measured)."""
    robot = load(name)
    rng = np.random.default_rng(4)
    lo, hi = np.maximum(robot.limits.position_lower, -3), np.minimum(robot.limits.position_upper, 3)
    q0, qe = (0.5 * (lo + hi) + 0.2 * (hi - lo) * rng.uniform(-1, 1, robot.n) for _ in range(2))
    cost = nearopt.TorqueCost(1e-3)
    coarse = nearopt.plan(robot, q0, qe, cost, options=nearopt.SCPOptions(refinements=0))
    fine = nearopt.plan(robot, q0, qe, cost)
    assert "refined to 24 control points" in fine.message
    assert fine.J < coarse.J * (1 - 1e-4), (fine.J, coarse.J)
    assert fine.trajectory.path.control_points.shape[0] == 26
    assert nearopt.verify_plan(fine).passed


@pytest.mark.parametrize(("arm", "weight"), [("ur5", 0.0), ("panda", 1e-3)])
def test_the_models_floor_is_its_value_at_no_step(arm: str, weight: float) -> None:
    """Stage 2's convex model at Δp = 0 (a zero trust region) is stage 1 without the rows
    between the samples: model_floor gives its J without solving the model, at most the
    iterate's own J (on a planned path, where they bind: 2–3e-4 below it), and the model with
    room to move predicts no more than that."""
    from nearopt.path import BSplinePath
    from nearopt.planning.ends import MovingEnds
    from nearopt.planning.scp import IterateParts, iterate_model, model_floor, solve_model

    robot = load(arm)
    rng = np.random.default_rng(3)
    q0, qe = random_configuration(robot, rng), random_configuration(robot, rng)
    cost = nearopt.TorqueCost(weight)
    weights = cost.torque_weights(robot.n)
    options = nearopt.SCPOptions(refinements=0, continuation=1.0)
    path = nearopt.plan(robot, q0, qe, cost, options=options).trajectory.path  # limits bind
    assert isinstance(path, BSplinePath)
    timing = nearopt.optimal_timing(robot, path, cost, grid=64)
    assert timing.problem.interior is not None  # the rows between the samples exist
    disc = Discretisation.of(timing.problem)
    z, p = timing.b[1:-1], path.control_points[1:-1].ravel()
    ends = MovingEnds(None, None, q0, qe, 15, False)
    scale = np.full(p.size, 0.05)
    model = iterate_model(
        robot, disc, z, path_basis(path, disc), p, IterateParts(timing, path), scale,
        None, path, ((), ()), None, None, (ends, weights),
    )  # fmt: skip
    limits = (np.full(p.size, -np.inf), np.full(p.size, np.inf))
    at_zero = solve_model(disc, weights, model, z, p, 0.0 * scale, *limits)
    floor = model_floor(timing, weights)
    assert floor < timing.objective * (1 - 1e-5)  # the rows between the samples bind
    assert floor == pytest.approx(at_zero[1], rel=1e-6), (floor, at_zero[1], timing.objective)
    moved = solve_model(disc, weights, model, z, p, scale, *limits)
    assert moved[1] <= floor * (1 + 1e-7)
