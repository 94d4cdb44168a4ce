"""Stage 1 (optimal timing of a given path) against closed forms and independent solvers."""

from __future__ import annotations

import time

import numpy as np
import pytest
from checks import assert_independent_checks
from conftest import ROBOT_NAMES, load, random_configuration
from urdfs import erd_urdf

import nearopt
from nearopt.cost import CallableCost, TimeCost, TorqueCost
from nearopt.paper_example import BETA, TABLE_1, TABLE_2, THETA_0, THETA_E, eq31
from nearopt.paper_example import COST as PAPER_COST
from nearopt.path import StraightPath
from nearopt.robot import PathCoefficients
from nearopt.timing import (
    TORQUE_SAFETY,
    BetweenSamples,
    Discretisation,
    PathQuantity,
    TimingMethod,
    TimingProblem,
    build_timing_problem,
    check_gravity,
    optimal_timing,
    solve_timing,
)
from nearopt.trajectory import segment_times


def random_line(robot: nearopt.Robot, seed: int) -> StraightPath:
    """A straight joint line between two random configurations (within the position limits)."""
    rng = np.random.default_rng(seed)
    return StraightPath(random_configuration(robot, rng), random_configuration(robot, rng))


# ------------------------------------------------------------------ the kernel, on arrays
def test_kernel_time_optimal_bang_bang_closed_form() -> None:
    """A 1-DOF rotor (inertia I, no gravity) moved by Θ with |u| ≤ U: t_e = 2√(ΘI/U)."""
    inertia, theta_total, u_max, big_n = 0.3, 1.2, 2.0, 64
    s = np.linspace(0, 1, big_n + 1)
    ones = np.ones((big_n + 1, 1))
    problem = TimingProblem(
        sigma=s,
        theta=theta_total * s[:, None],
        dtheta=theta_total * ones,
        ddtheta=0 * ones,
        torque=PathQuantity(
            PathCoefficients(m=inertia * theta_total * ones, c=0 * ones, d=0 * ones, g=0 * ones),
            lower=np.array([-u_max]),
            upper=np.array([u_max]),
        ),
        velocity=np.array([np.inf]),
        joint_names=("rotor",),
    )
    sol = solve_timing(problem, TimeCost())
    assert sol.status == "optimal"
    # the samples are held inside the limits by the relative safety margin TORQUE_SAFETY
    held = u_max * (1.0 - TORQUE_SAFETY)
    np.testing.assert_allclose(sol.objective, 2 * np.sqrt(theta_total * inertia / held), rtol=1e-9)
    # and with a torque cost the optimum is slower than bang-bang but still feasible
    slow = solve_timing(problem, TorqueCost(0.5))
    assert slow.status == "optimal"
    assert np.all(slow.b <= sol.b + 1e-9)


# ------------------------------------------------------------------ the paper's straight line
def casadi_reference(big_n: int = 1000) -> float:
    """The paper's line timed by IPOPT on eq. (31) in closed form, torques at segment midpoints.

    Independent of nearopt's robot layer (dynamics written out here), of its discretisation
    (midpoint rather than segment-end torques) and of its solver (IPOPT rather than Clarabel).
    """
    ca = pytest.importorskip("casadi")
    d_theta = THETA_E - THETA_0
    ds = 1.0 / big_n
    opti = ca.Opti()
    b = opti.variable(big_n - 1)
    bb = ca.vertcat(0, b, 0)
    cost = 0
    for k in range(big_n):
        sm = (k + 0.5) * ds
        q = THETA_0 + d_theta * sm
        lam = ca.sqrt(bb[k] + 1e-14) + ca.sqrt(bb[k + 1] + 1e-14)
        dt = 2 * ds / lam
        a = (bb[k + 1] - bb[k]) / (2 * ds)
        bm = 0.5 * (bb[k] + bb[k + 1])
        # θ̇ = θ' λ, θ̈ = θ' b'/2 on a line (θ'' = 0): h is quadratic in θ̇, so h(θ, θ') b
        (h11, h12), (_, h22) = eq31(q, d_theta)[0]
        h_unit, g = eq31(q, d_theta)[1:]
        qdd = d_theta * a
        u1 = h11 * qdd[0] + h12 * qdd[1] + h_unit[0] * bm + g[0]
        u2 = h12 * qdd[0] + h22 * qdd[1] + h_unit[1] * bm + g[1]
        u_max = TABLE_1.torque_limits
        opti.subject_to(opti.bounded(-u_max[0], u1, u_max[0]))
        opti.subject_to(opti.bounded(-u_max[1], u2, u_max[1]))
        cost += dt * (1 + BETA * (u1**2 + u2**2))
    opti.subject_to(b >= 1e-8)
    opti.set_initial(b, 1.0)
    opti.minimize(cost)
    opti.solver("ipopt", {"print_time": False}, {"print_level": 0, "tol": 1e-10})
    return float(opti.solve().value(cost))


def test_paper_line_matches_an_independent_solver() -> None:
    robot = load("two_link")
    result = optimal_timing(robot, StraightPath(THETA_0, THETA_E), PAPER_COST, grid=200)
    assert result.status == "optimal"
    reference = casadi_reference()
    assert abs(result.J - reference) / reference < 1e-3
    # the paper's J0 = 0.95859 for this path is not the optimum of its timing
    assert result.J < TABLE_2[0].J * 0.9


def test_paper_line_grid_refinement_converges() -> None:
    robot = load("two_link")
    path = StraightPath(THETA_0, THETA_E)
    values = [optimal_timing(robot, path, PAPER_COST, grid=n).J for n in (50, 100, 200, 400)]
    steps = np.abs(np.diff(values))
    assert np.all(steps[1:] < 0.5 * steps[:-1]), values  # at least first-order, in fact ~O(Δs²)
    assert steps[-1] / values[-1] < 1e-4


def test_cost_does_not_depend_on_the_scale_of_s() -> None:
    robot = load("two_link")
    unit = optimal_timing(robot, StraightPath(THETA_0, THETA_E), PAPER_COST)
    # s as the length of the joint-space line, as any other unit of s would be
    scaled = optimal_timing(robot, StraightPath(THETA_0, THETA_E, s_end=2.87), PAPER_COST)
    np.testing.assert_allclose(scaled.J, unit.J, rtol=1e-7)
    np.testing.assert_allclose(scaled.duration, unit.duration, rtol=1e-7)


# ------------------------------------------------------------------ every arm: independent checks
@pytest.mark.parametrize("cost", [TimeCost(), PAPER_COST], ids=["time", "torque2"])
def test_returned_trajectory_passes_independent_checks(
    robot: nearopt.Robot, cost: TorqueCost
) -> None:
    if robot.name == "two_link":
        path = StraightPath(THETA_0, THETA_E)
    else:
        path = random_line(robot, seed=7)
    result = optimal_timing(robot, path, cost, grid=200)
    assert_independent_checks(
        robot, result.trajectory, cost, result.J, path(0.0)[0], path(path.s_end)[0]
    )


def test_general_cost_callable_matches_builtin_optimum() -> None:
    """The local NLP on a user f0 equal to the paper's cost finds the convex solver's optimum."""
    robot = load("two_link")
    path = StraightPath(THETA_0, THETA_E)
    user = CallableCost(lambda q, qd, u: 1 + 0.03 * np.sum(u**2, axis=1), name="mine")
    builtin = optimal_timing(robot, path, PAPER_COST, grid=100)
    general = optimal_timing(robot, path, user, grid=100)
    np.testing.assert_allclose(general.J, builtin.J, rtol=1e-5)


# ------------------------------------------------------------------ TOPP-RA, time-optimal
@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_time_optimal_matches_toppra(name: str) -> None:
    ta = pytest.importorskip("toppra")
    import pinocchio as pin

    robot = load(name)
    path = random_line(robot, seed=11)
    ours = optimal_timing(robot, path, TimeCost(), grid=200)
    data = robot.model.createData()

    def inverse_dynamics(q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
        return pin.rnea(robot.model, data, q, qd, qdd) + robot.damping * qd

    spline = ta.SplineInterpolator([0.0, 1.0], np.vstack([path(0.0)[0], path(1.0)[0]]))
    lim = robot.limits
    constraints = [
        ta.constraint.JointVelocityConstraint(np.column_stack([-lim.velocity, lim.velocity])),
        ta.constraint.JointTorqueConstraint(
            inverse_dynamics,
            np.column_stack([lim.effort_lower, lim.effort_upper]),
            np.zeros(robot.n),
            discretization_scheme=ta.constraint.DiscretizationType.Interpolation,
        ),
    ]
    topp = ta.algorithm.TOPPRA(constraints, spline, gridpoints=np.linspace(0, 1, 201))
    theirs = topp.compute_trajectory(0, 0).duration
    assert abs(ours.duration - theirs) / theirs < 5e-3, (ours.duration, theirs)


# ------------------------------------------------------------------ infeasibility
def test_gravity_beyond_a_limit_is_infeasible_and_says_where() -> None:
    robot = load("two_link").with_limits(effort=[3.0, 5.0])  # g1(θe) = 3.924 N·m
    with pytest.raises(nearopt.InfeasiblePathError) as info:
        optimal_timing(robot, StraightPath(THETA_0, THETA_E), PAPER_COST)
    err = info.value
    assert err.joint == "joint1"
    assert err.s == pytest.approx(1.0)
    assert err.excess == pytest.approx(3.924 - 3.0, abs=1e-3)
    assert "joint1" in str(err) and "upper limit 3" in str(err)


def test_no_limit_is_silently_dropped_with_damping() -> None:
    """The damping torque D θ̇ counts: a damped arm is slower than the same arm undamped."""
    robot = load("xarm7")
    path = random_line(robot, seed=3)
    damped = optimal_timing(robot, path, TimeCost())
    undamped = optimal_timing(robot.with_limits(damping=0.0), path, TimeCost())
    assert damped.duration > undamped.duration


def test_robot_names_cover_six_arms() -> None:
    assert len(ROBOT_NAMES) >= 6


def test_gravity_beyond_a_limit_between_knots_is_infeasible_too() -> None:
    """On a coarse grid gravity may peak between knots (θ1 = π/2 lies between two of them)."""
    robot = load("two_link").with_limits(effort=[3.92, 5.0])  # |g1| ≤ 3.924 = 4 m g l
    path = StraightPath([0.3, 0.0], [2.9, 0.0])
    with pytest.raises(nearopt.InfeasiblePathError) as info:
        optimal_timing(robot, path, grid=21)
    assert info.value.joint == "joint1"
    assert abs(path(info.value.s)[0][0] - np.pi / 2) < 0.1


# ------------------------------------------------------------------ limits at all times
def random_path(robot: nearopt.Robot, rng: np.random.Generator, kind: str) -> nearopt.Path:
    """A random path between random configurations: the line, a spline through waypoints off the
    line, or a B-spline with control points off the line (by up to a quarter of the motion)."""
    q0, qe = random_configuration(robot, rng), random_configuration(robot, rng)
    if kind == "straight":
        return StraightPath(q0, qe)
    count = int(rng.integers(3, 9))
    at = np.linspace(0.0, 1.0, count + 2)
    if kind == "bspline":
        at = nearopt.BSplinePath.greville(count + 2)
    points = q0 + np.outer(at, qe - q0)
    points[1:-1] += rng.normal(scale=0.25, size=(count, robot.n)) * np.abs(qe - q0)
    if kind == "spline":
        return nearopt.SplinePath(at, points)
    return nearopt.BSplinePath(points)


@pytest.mark.parametrize("name", ["two_link", "ur5", "panda"])
def test_one_solve_holds_the_limits_between_samples(name: str, monkeypatch) -> None:
    """The bound of the motion between the samples is part of the one solve: on seeded lines,
    splines and B-splines (time and torque costs, with and without acceleration limits) the first
    solve already keeps it, up to the 1e-7 of a limit by which its rows may be left out (the
    check's uniform slow-down; up to 1e-5 for a damped torque, held at the points only), so
    optimal_timing solves once (with damping: most often); and it holds fewer rows than the bound
    has sums (most are implied by the segments' own samples)."""
    import nearopt.timing.driver as driver

    calls = []
    real = driver.solve_timing

    def counted(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(driver, "solve_timing", counted)
    robot = load(name)
    rng = np.random.default_rng([7, ROBOT_NAMES.index(name)])
    timed, solves = 0, []
    for k in range(12):
        arm = robot.with_limits(acceleration=20.0) if k % 4 == 3 else robot
        path = random_path(robot, rng, ("straight", "spline", "bspline")[k % 3])
        cost = (TimeCost(), PAPER_COST)[(k // 3) % 2]
        grid = (50, 120)[k % 2]
        calls.clear()
        try:
            result = optimal_timing(arm, path, cost, grid=grid)
        except nearopt.InfeasiblePathError:
            continue
        timed += 1
        solves.append(len(calls))
        problem = result.problem
        disc = Discretisation(problem)
        held = sum(
            block.stop - block.start
            for block in (
                disc.blocks.torque_between,
                disc.blocks.acceleration_between,
                disc.blocks.speed_between,
            )
        )
        limited = np.isfinite(arm.limits.effort_upper).sum() + np.isfinite(problem.velocity).sum()
        assert 0 < held < 0.5 * 16 * problem.interior.points * problem.segments * limited
        if len(calls) > 1:
            continue
        # what was solved once: its slow-down is the check's, and small
        first = real(problem, cost)
        between = BetweenSamples(arm, path, problem)
        slack = 1e-5 if np.any(arm.damping != 0.0) else 1e-6
        assert between.largest_alpha(first.b) >= 1.0 - slack
        assert between.speed_scale(first.b) >= 1.0 - 1e-6
    assert timed >= 8, timed
    # undamped: always one solve; damped (panda's URDF: the torque is held at the points only,
    # its √b at the nearer knot), most often one (measured 8 of 12; the others 2 to 5)
    damped = bool(np.any(robot.damping != 0.0))
    assert solves.count(1) >= (0.5 * timed if damped else timed), solves


@pytest.mark.slow
@pytest.mark.parametrize("name", ["two_link", "ur5", "panda"])
def test_limits_hold_between_samples_on_random_paths(name: str) -> None:
    """36 seeded paths per arm (lines, splines, B-splines; grids of 40 to 200 segments; time and
    torque costs; with and without acceleration limits): torques by RNEA, speeds and accelerations
    on 20 kHz samples stay within the limits (verify's 1e-6 / 1e-9 relative)."""
    robot = load(name)
    rng = np.random.default_rng([36, ROBOT_NAMES.index(name)])
    timed = 0
    for k in range(36):
        kind = ("straight", "spline", "bspline")[k % 3]
        cost = (TimeCost(), PAPER_COST)[(k // 3) % 2]
        arm = robot.with_limits(acceleration=20.0) if k % 4 == 3 else robot
        path = random_path(robot, rng, kind)
        try:
            result = optimal_timing(arm, path, cost, grid=(40, 100, 200)[(k // 6) % 3])
        except nearopt.InfeasiblePathError:  # gravity beyond a limit somewhere on the path
            continue
        timed += 1
        # (a given path may leave the position limits: stage 1 times it as it is)
        report = nearopt.verify(
            result.trajectory,
            arm,
            rate=20000.0,
            cost=cost,
            J=result.J,
            position_limits=False,
            simulate=False,
        )
        assert report.passed, f"path {k} ({kind}): {report}"
    assert timed >= 24, timed


def test_the_reported_excesses_are_gone() -> None:
    """The motions that broke a limit between samples: the two-link arm from θ1 = 2π, the
    double pendulum with effort 2 and tiago's arm plan and verify."""
    two_link = load("two_link")
    double_pendulum = nearopt.Robot.from_urdf(
        erd_urdf("double_pendulum_description/urdf/double_pendulum.urdf"), effort_limit=2.0
    )
    tiago = nearopt.Robot.from_urdf(
        erd_urdf("tiago_description/robots/tiago.urdf"), tip="arm_7_link"
    )
    cases = [
        (two_link, [2 * np.pi, 0.0], [0.0, 1.0], TimeCost()),
        (double_pendulum, [0.3, -0.4], [2.0, 1.0], TimeCost()),
        (tiago, tiago_pose(tiago, 0.3), tiago_pose(tiago, 0.7), PAPER_COST),
    ]
    for robot, q0, qe, cost in cases:
        result = nearopt.plan(robot, q0, qe, cost, grid=100, max_iterations=5)
        report = nearopt.verify(
            result.trajectory, robot, rate=20000.0, q0=q0, qe=qe, cost=cost, J=result.J
        )
        assert report.passed, f"{robot.name}: {report}"


def tiago_pose(robot: nearopt.Robot, fraction: float) -> np.ndarray:
    lo, hi = robot.limits.position_lower, robot.limits.position_upper
    return lo + fraction * (hi - lo)


# ------------------------------------------------------------------ joint acceleration limits
@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_time_optimal_with_acceleration_limits_matches_toppra(name: str) -> None:
    ta = pytest.importorskip("toppra")
    import pinocchio as pin

    robot = load(name).with_limits(acceleration=8.0)
    path = random_line(robot, seed=11)
    ours = optimal_timing(robot, path, TimeCost(), grid=200)
    data = robot.model.createData()
    lim = robot.limits
    spline = ta.SplineInterpolator([0.0, 1.0], np.vstack([path(0.0)[0], path(1.0)[0]]))
    scheme = ta.constraint.DiscretizationType.Interpolation
    constraints = [
        ta.constraint.JointVelocityConstraint(np.column_stack([-lim.velocity, lim.velocity])),
        ta.constraint.JointAccelerationConstraint(
            np.column_stack([-lim.acceleration, lim.acceleration]), discretization_scheme=scheme
        ),
        ta.constraint.JointTorqueConstraint(
            lambda q, qd, qdd: pin.rnea(robot.model, data, q, qd, qdd) + robot.damping * qd,
            np.column_stack([lim.effort_lower, lim.effort_upper]),
            np.zeros(robot.n),
            discretization_scheme=scheme,
        ),
    ]
    knots = build_timing_problem(robot, path, grid=200).sigma
    theirs = ta.algorithm.TOPPRA(constraints, spline, gridpoints=knots).compute_trajectory(0, 0)
    assert abs(ours.duration - theirs.duration) / theirs.duration < 1e-4
    # and the limit binds: without it the motion is faster
    assert optimal_timing(load(name), path, TimeCost(), grid=200).duration < ours.duration


def test_samples_too_coarse_for_a_phase_are_flagged() -> None:
    """so101 time-optimally has bang phases under 1 ms: 1 kHz samples miss them (a
    SamplingWarning); with acceleration limits every phase is longer than a sample period."""
    from nearopt.export import check_sampling, json_text

    robot = load("so101")
    q0, qe = tiago_pose(robot, 0.3), tiago_pose(robot, 0.7)
    fast = nearopt.plan(robot, q0, qe, TimeCost(), max_iterations=0)
    assert fast.trajectory.faithful_rate() > 1000.0
    with pytest.warns(nearopt.SamplingWarning, match="shorter than one sample period"):
        json_text(fast, 1000.0)
    limited = nearopt.plan(
        robot.with_limits(acceleration=20.0), q0, qe, TimeCost(), max_iterations=0
    )
    assert limited.trajectory.faithful_rate() < 1000.0
    assert check_sampling(limited, 1000.0) is None


@pytest.mark.parametrize(
    "cost",
    [TimeCost(), CallableCost(lambda q, qd, u: 1.0 + 0.01 * np.sum(u**2, axis=1))],
    ids=["kernel", "NLP"],
)
def test_the_time_limit_stops_stage_1_at_its_first_unfinished_solve(
    cost: nearopt.Cost, monkeypatch: pytest.MonkeyPatch
) -> None:
    """An unfinished kernel solve is not handed to Clarabel (panda is damped) and the NLP stops at
    its next iteration: the error names the caller's budget."""
    from nearopt.timing import solvers

    calls = []

    def counted(*args: object, **kwargs: object) -> object:
        calls.append(kwargs["time_limit"])
        return real(*args, **kwargs)

    real = solvers.solve_conic
    monkeypatch.setattr(solvers, "solve_conic", counted)
    panda = load("panda")
    assert panda.damping.any()
    if isinstance(cost, TimeCost):  # a budget shorter than one large solve
        grid, budget = 20000, 0.05
    else:  # a budget the convex start fits in but not the NLP after it
        grid, budget = 200, None
        start = time.perf_counter()
        optimal_timing(panda, random_line(panda, 3), TimeCost(), grid=grid)
        budget = 2.0 * (time.perf_counter() - start)
    with pytest.raises(
        nearopt.SolverError,
        match=rf"time limit \({budget:.3g} s\) on a grid of "
        rf"{grid} segments",
    ) as info:
        optimal_timing(panda, random_line(panda, 3), cost, grid=grid, time_limit=budget)
    assert info.value.status == "MaxTime"
    assert calls == []  # Clarabel was never asked


# ------------------------------------------------------------------ the interior-point kernel
def kernel_cases(name: str, count: int, seed: int) -> list[tuple[TimingProblem, nearopt.Cost]]:
    """Seeded problems on one arm: lines, splines and B-splines; time and energy costs; with and
    without acceleration limits; grids of 60 and 200 segments (gravity-infeasible ones skipped)."""
    robot = load(name)
    rng = np.random.default_rng([seed, ROBOT_NAMES.index(name)])
    cases = []
    for k in range(count):
        arm = robot.with_limits(acceleration=10.0) if k % 4 >= 2 else robot
        path = random_path(robot, rng, ("straight", "spline", "bspline")[k % 3])
        cost = (TimeCost(), TorqueCost(1e-3))[k % 2]
        try:
            problem = build_timing_problem(arm, path, grid=(60, 200)[(k // 2) % 2])
            check_gravity(problem)
        except nearopt.InfeasiblePathError:
            continue
        cases.append((problem, cost))
    return cases


@pytest.mark.parametrize("name", ["two_link", "ur5", "panda"])
def test_kernel_finds_clarabels_optimum(name: str) -> None:
    """The interior-point kernel and Clarabel's SOCP on the same rows reach the same optimum: the
    discretised J and the duration agree to 1e-7 relative (ur5 and panda are damped: the kernel
    keeps √b exactly, Clarabel re-linearises it to a fixed point), and the kernel's J is never
    above Clarabel's. Clarabel itself stops short on some problems with acceleration limits
    ("InsufficientProgress", or an answer that leaves the rows between the samples, whose
    coefficients ∝ 1/Δσ nearly cancel, by 1e-7 of a limit and more, so that it has to be slowed
    down by that much to hold them): those are not compared beyond the kernel's being no worse."""
    compared = 0
    for problem, cost in kernel_cases(name, 10, 1):
        ours = solve_timing(problem, cost)
        assert ours.solver == TimingMethod.INTERIOR, ours.message
        assert ours.slowed <= 1e-12, ours.slowed  # the kernel's answer holds every row
        try:
            reference = solve_timing(problem, cost, method=TimingMethod.SOCP)
        except nearopt.SolverError:
            continue
        assert reference.solver == TimingMethod.SOCP
        assert ours.objective <= reference.objective * (1.0 + 1e-9)
        if reference.slowed > 1e-8:
            continue
        compared += 1
        np.testing.assert_allclose(ours.objective, reference.objective, rtol=1e-7)
        durations = [segment_times(problem.sigma, sol.b).sum() for sol in (ours, reference)]
        np.testing.assert_allclose(*durations, rtol=1e-7)
    assert compared >= 6, compared


def test_implied_rows_are_left_out_without_changing_the_optimum() -> None:
    """The rows a sample's other rows imply (on the range of b its maximum velocity curve
    allows) are left out of the kernel's problem: fewer rows, the same optimum, and the answer
    keeps every row of the full problem."""
    from nearopt.timing.interior import solve_interior

    for problem, cost in kernel_cases("panda", 4, 2):
        disc = Discretisation(problem)
        weights = cost.torque_weights(problem.dof)
        full = solve_interior(disc, weights, reduce=False)
        reduced = solve_interior(disc, weights)
        assert full.converged and reduced.converged
        assert reduced.rows < 0.6 * full.rows, (reduced.rows, full.rows)
        values = [disc.objective(sol.z, cost)[0] for sol in (full, reduced)]
        np.testing.assert_allclose(*values, rtol=1e-9)
        assert disc.relative_excess(reduced.z) <= 1e-9


@pytest.mark.parametrize("name", ["two_link", "panda"])
def test_limits_that_never_bind_change_nothing(name: str) -> None:
    """A huge number meant as "no limit" gives the plan of no limit: acceleration limits from 1e6
    to 1e300 (the motion needs at most a few hundred rad/s²) and an effort limit of 1e300 on top
    of a binding one of another joint."""
    robot = load(name)
    path = random_line(robot, 4) if name != "two_link" else StraightPath(THETA_0, THETA_E)
    base = optimal_timing(robot, path, PAPER_COST, grid=100)
    for limit in (1e6, 1e12, 1e100, 1e300):
        limited = optimal_timing(robot.with_limits(acceleration=limit), path, PAPER_COST, grid=100)
        np.testing.assert_allclose(limited.b, base.b, rtol=1e-9, atol=1e-12 * base.b.max())
        np.testing.assert_allclose(limited.J, base.J, rtol=1e-9)


def test_speed_and_acceleration_limits_scale_time_exactly() -> None:
    """Without torque limits, speed limits κv and acceleration limits κ²a time any path κ times
    faster (θ̇ ∝ κ, θ̈ ∝ κ²): te(κ) κ is the same for κ from 1e-6 to 1e6 — the kernel's rows are
    normalised, so no scale of the limits is special."""
    robot = load("ur5").with_limits(effort=1e300, damping=0.0)
    rng = np.random.default_rng(9)
    path = random_path(robot, rng, "spline")
    v, a = np.asarray(robot.limits.velocity), np.full(robot.n, 5.0)
    times = []
    for kappa in (1e-6, 1e-3, 1.0, 1e3, 1e6):
        arm = robot.with_limits(velocity=kappa * v, acceleration=kappa**2 * a)
        problem = build_timing_problem(arm, path, grid=100)
        sol = solve_timing(problem, TimeCost())
        assert sol.solver == TimingMethod.INTERIOR, sol.message
        times.append(kappa * segment_times(problem.sigma, sol.b).sum())
    np.testing.assert_allclose(times, times[2], rtol=1e-8)


@pytest.mark.parametrize("name", ["two_link", "ur5", "panda"])
def test_the_kernel_solves_every_seeded_problem(name: str) -> None:
    """48 seeded problems per arm at small grids (10 to 80 segments; lines, splines, B-splines;
    time and energy; with and without acceleration limits; every limit scaled by 1e-3, 1 or 1e6):
    each is solved by the kernel itself (no fallback to Clarabel) and keeps every row."""
    robot = load(name)
    rng = np.random.default_rng([48, ROBOT_NAMES.index(name)])
    solved = 0
    for k in range(48):
        scale = (1e-3, 1.0, 1e6)[k % 3]
        lim = robot.limits
        arm = robot.with_limits(
            velocity=scale * np.asarray(lim.velocity),
            acceleration=scale**2 * 20.0 if k % 2 else np.inf,
        )
        path = random_path(robot, rng, ("straight", "spline", "bspline")[(k // 3) % 3])
        cost = (TimeCost(), TorqueCost(1e-3))[(k // 2) % 2]
        try:
            problem = build_timing_problem(arm, path, grid=(10, 30, 80)[(k // 4) % 3])
            sol = solve_timing(problem, cost)
        except nearopt.InfeasiblePathError:
            continue
        assert sol.solver == TimingMethod.INTERIOR, f"problem {k}: {sol.message}"
        assert Discretisation(problem).relative_excess(sol.b[1:-1]) <= 1e-9
        solved += 1
    assert solved >= 36, solved


def test_fine_and_coarse_grids() -> None:
    """10 to 20 000 segments: J converges (the paper's line), each solved by the kernel."""
    robot = load("two_link")
    path = StraightPath(THETA_0, THETA_E)
    values = []
    for grid in (10, 1000, 20000):
        result = optimal_timing(robot, path, PAPER_COST, grid=grid)
        assert result.solver == TimingMethod.INTERIOR, result.message
        values.append(result.J)
    assert abs(values[2] - values[1]) < 1e-5 * values[2]
    assert abs(values[0] - values[2]) < 1e-2 * values[2]


def test_heavy_damping_is_timed_in_one_solve() -> None:
    """The damping torque D θ̇ = D θ' √b kept exactly in the kernel's solve: the paper's arm with
    D = 1 to 20 N·m·s/rad (damping that dominates its 5-10 N·m) is timed by the kernel, the motion
    keeps the limits at 20 kHz, and its J is no higher than that of Clarabel's re-linearisation
    where that converges (at D = 5 and 20 it does not)."""
    robot = load("two_link")
    path = StraightPath(THETA_0, THETA_E)
    for damping in (1.0, 5.0, 20.0):
        arm = robot.with_limits(damping=damping)
        result = optimal_timing(arm, path, PAPER_COST, grid=100)
        assert result.solver == TimingMethod.INTERIOR, result.message
        report = nearopt.verify(
            result.trajectory,
            arm,
            rate=20000.0,
            cost=PAPER_COST,
            J=result.J,
            position_limits=False,
            simulate=False,
        )
        assert report.passed, f"D = {damping}: {report}"
        problem = build_timing_problem(arm, path, grid=100)
        ours = solve_timing(problem, PAPER_COST)
        try:
            reference = solve_timing(problem, PAPER_COST, method=TimingMethod.SOCP)
        except nearopt.SolverError:
            assert damping > 1.0  # re-linearising a large damping torque fails
            continue
        assert ours.objective <= reference.objective * (1.0 + 1e-9)


def test_speed_lines_stay_under_the_speed_bound() -> None:
    """The lines of speed_lines keep b Ĝ ≤ 1 on the whole interval for any line Ĝ ≥ 0 (steep,
    flat, touching 0), lose at most (ΔG/Ĝ)² of 1/Ĝ at their worse end, and the largest product
    of the check is the dense maximum."""
    from nearopt.timing.between import _largest_product, speed_lines

    rng = np.random.default_rng(3)
    g0 = rng.uniform(0.0, 10.0, 4000) * rng.choice([0.0, 1.0], 4000, p=[0.05, 0.95])
    g1 = g0 * np.exp(rng.normal(scale=rng.choice([0.01, 0.3, 3.0], 4000)))
    g1[:50] = 0.0
    start, end = speed_lines(g0, g1)
    t = np.linspace(0.0, 1.0, 2001)[:, None]
    moving = (g0 > 0) | (g1 > 0)
    assert np.all(np.isinf(start[~moving])) and np.all(start[moving] >= 0.0)
    g0, g1, start, end = g0[moving], g1[moving], start[moving], end[moving]
    line = start + (end - start) * t
    bound = g0 + (g1 - g0) * t
    assert np.all(line * bound <= 1.0 + 1e-12)
    # tight where Ĝ changes little: off by at most (ΔG/Ĝ)² at the worse end
    small = np.abs(g1 - g0) < 0.05 * np.minimum(g0, g1)
    change = np.abs(g1 - g0)[small] / np.minimum(g0, g1)[small]
    worst = np.minimum(start[small] * g0[small], end[small] * g1[small])
    assert np.all(worst >= 1.0 - change**2 - 1e-12)
    # the check's bound: the maximum of the product of two lines
    x0, dx = rng.uniform(0.0, 2.0, g0.size), rng.normal(size=g0.size)
    dense = np.max((x0 + dx * t) * (g0 + (g1 - g0) * t), axis=0)
    exact = _largest_product(x0, dx, g0, g1 - g0)
    assert np.all(exact >= dense - 1e-12)  # no sample above it
    # and none far below: the samples' spacing 1/2000 misses at most |x'g'| / 2000² / 4
    assert np.all(exact - dense <= np.abs(dx * (g1 - g0)) / 1.6e7 + 1e-12)


HEAVILY_DAMPED = """<robot name="damped"><link name="base"/>
<joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 1 0"/>
<limit effort="50" velocity="3" lower="-3" upper="3"/><dynamics damping="{damping}"/></joint>
<link name="l1"><inertial><origin xyz="0 0 0.1"/><mass value="1.0"/>
<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link></robot>"""


@pytest.mark.parametrize("damping", [20.0, 50.0])
def test_a_heavily_damped_joint_is_timed_at_its_optimum(tmp_path, damping: float) -> None:
    """A fuzz pass's arm: one joint whose damping torque D θ̇ outweighs everything else
    (f0 = 1 + 0.1 u²). The kernel's Newton matrix stayed indefinite through its 14 shifts and
    Clarabel's SOCP with the damping linearised took over: at D = 20 it stopped at J 65.8
    (t_e 0.62 s), where slowing the same b down uniformly to 1 % gives 11.3; at D = 50 it found
    the line infeasible. Now the kernel's own optimum, stationary along that slow-down, and the
    finer grid's (11.01 at D = 20)."""
    path = tmp_path / "damped.urdf"
    path.write_text(HEAVILY_DAMPED.format(damping=damping))
    robot = nearopt.Robot.from_urdf(path)
    cost = TorqueCost(0.1)
    line = StraightPath(np.zeros(1), np.ones(1))
    timing = optimal_timing(robot, line, cost)
    disc = Discretisation.of(timing.problem)
    z = timing.b[1:-1]
    for alpha in (0.3, 0.9, 0.99, 1.01, 1.1):  # no uniform change of speed lowers it
        assert disc.objective(alpha * z, cost)[0] >= timing.objective * (1 - 1e-6), alpha
    finer = optimal_timing(robot, line, cost, grid=1000)
    assert abs(timing.J / finer.J - 1.0) < 2e-3, (timing.J, finer.J)
    assert_independent_checks(robot, timing.trajectory, cost, timing.J, np.zeros(1), np.ones(1))
