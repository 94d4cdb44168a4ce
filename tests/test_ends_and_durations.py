"""Stage 1 of motions that start or end moving, and of motions whose duration is set.

Seeded paths on several arms; every answer against Clarabel's SOCP of the same problem (the fixed
end speeds and t_e ≤ T as its own constraints: the independent reference) and checked by
``verify`` (limits at 2 kHz, the end velocities, the duration, J, the forward simulation).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import load
from console import run_cli

import nearopt
from nearopt.path import StraightPath
from nearopt.timing import TimingMethod, optimal_timing, solve_timing
from nearopt.trajectory import Trajectory, segment_times

ARMS = ("two_link", "ur5", "panda", "xarm7")  # xarm7: damped joints
RATE = 2000.0


def seeded_path(name: str, seed: int) -> tuple[nearopt.Robot, StraightPath, np.ndarray]:
    """A straight path within 30 % of each joint's range around its middle, and its direction
    dθ/ds."""
    robot = load(name)
    rng = np.random.default_rng(seed)
    lo = np.maximum(robot.limits.position_lower, -3.0)
    hi = np.minimum(robot.limits.position_upper, 3.0)
    mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    q0 = mid + 0.3 * half * rng.uniform(-1.0, 1.0, robot.n)
    qe = mid + 0.3 * half * rng.uniform(-1.0, 1.0, robot.n)
    path = StraightPath(q0, qe)
    return robot, path, (qe - q0) / path.s_end


def peak_path_speed(robot: nearopt.Robot, path: StraightPath) -> float:
    """The largest ṡ of the time-optimal motion from rest to rest."""
    fastest = optimal_timing(robot, path)
    t = np.linspace(0.0, fastest.duration, 400)
    return float(np.max(fastest.trajectory.path_parameter(t)[1]))


def verified(robot, result, q0, qe, **expected) -> None:
    report = nearopt.verify(
        result.trajectory, robot, rate=RATE, q0=q0, qe=qe, cost=result.cost, J=result.J, **expected
    )
    assert report.passed, str(report)


@pytest.mark.parametrize("name", ARMS)
def test_moving_ends_are_kept_and_the_timing_is_the_references(name: str) -> None:
    robot, path, direction = seeded_path(name, 5)
    rng = np.random.default_rng(7)
    fast = peak_path_speed(robot, path)
    for cost in (nearopt.TimeCost(), nearopt.TorqueCost(0.03)):
        f0, fe = rng.uniform(0.1, 0.6, 2)
        qd0, qde = f0 * fast * direction, fe * fast * direction
        result = optimal_timing(robot, path, cost, qd0=qd0, qde=qde)
        states = result.trajectory.states(np.array([0.0, result.duration]))[1]
        assert np.max(np.abs(states[0] - qd0)) <= 1e-9 * np.max(np.abs(qd0))
        assert np.max(np.abs(states[1] - qde)) <= 1e-9 * np.max(np.abs(qde))
        verified(robot, result, path.theta0, path.thetae, qd0=qd0, qde=qde)
        # the same problem (the grid, the margins stage 1 ended with) by Clarabel
        reference = solve_timing(result.problem, cost, method=TimingMethod.SOCP)
        assert result.problem.b_ends == pytest.approx((f0**2 * fast**2, fe**2 * fast**2), 1e-9)
        if robot.damping is None or not np.any(robot.damping):
            assert result.objective == pytest.approx(reference.objective, rel=1e-6)
        else:  # Clarabel's damping is a tangent re-linearised to a fixed point: no better
            assert result.objective <= reference.objective * (1.0 + 1e-6)
        # a start that is already moving along the path is never slower than from rest
        if isinstance(cost, nearopt.TimeCost):
            from_rest = optimal_timing(robot, path, cost, qde=qde)
            assert result.duration <= from_rest.duration * (1.0 + 1e-9)


@pytest.mark.parametrize("name", ARMS)
def test_a_duration_is_met_exactly_and_the_optimum_is_the_references(name: str) -> None:
    """t_e = T to 1e-9 at rest and moving; below the free optimum's t_e, the same J as
    Clarabel's SOCP with t_e ≤ T as a constraint; J falls as T grows up to the free optimum's
    t_e and rises beyond it."""
    robot, path, direction = seeded_path(name, 11)
    damped = robot.damping is not None and bool(np.any(robot.damping))  # Clarabel linearises
    cost = nearopt.TorqueCost(0.03)
    fast = peak_path_speed(robot, path)
    for ends in ({}, {"qd0": 0.3 * fast * direction, "qde": 0.2 * fast * direction}):
        free = optimal_timing(robot, path, cost, **ends)
        fastest = optimal_timing(robot, path, **ends).duration
        sweep = []
        for fraction in (0.0, 0.3, 0.7):
            duration = fastest + fraction * (free.duration - fastest)
            duration = max(duration, fastest * 1.001)
            result = optimal_timing(robot, path, cost, duration=duration, **ends)
            assert result.duration == pytest.approx(duration, rel=1e-9, abs=0.0)
            verified(robot, result, path.theta0, path.thetae, duration=duration, **ends)
            if not damped:
                # Clarabel with Σ t_k ≤ T (1 + 1e-6) (at T itself it may call a problem near
                # the time-optimal one infeasible); its answer lasts t_ref ≈ T (its tolerance
                # on that row): nearopt's at t_ref is no worse, and Clarabel's is no worse than
                # ours at T < t_ref. Clarabel now and then stops short (InsufficientProgress)
                # on one such problem: the reference is then the next slack's (2e-6, 5e-6)
                reference = _reference_within(result.problem, cost, duration)
                t_ref = float(np.sum(segment_times(result.problem.sigma, reference.b)))
                assert t_ref == pytest.approx(duration, rel=2e-5)
                at_ref = optimal_timing(robot, path, cost, duration=t_ref, **ends)
                assert at_ref.objective <= reference.objective * (1.0 + 1e-7)
                if t_ref >= duration:
                    assert reference.objective <= result.objective * (1.0 + 1e-7)
            bounded = optimal_timing(robot, path, cost, max_duration=duration, **ends)
            assert bounded.duration <= duration * (1.0 + 1e-12)
            assert bounded.J == pytest.approx(result.J, rel=1e-6)
            sweep.append(result.J)
        sweep.append(free.J)
        assert np.all(np.diff(sweep) < 0.0), sweep
        # beyond the free optimum's t_e, and (moving ends on most arms) beyond the torque-only
        # optimum's: J rises with T, every limit held
        longer = [free]
        for factor in (1.05, 1.6):
            result = optimal_timing(robot, path, cost, duration=factor * free.duration, **ends)
            assert result.duration == pytest.approx(factor * free.duration, rel=1e-9)
            verified(robot, result, path.theta0, path.thetae, duration=result.duration, **ends)
            longer.append(result)
        assert longer[0].J < longer[1].J < longer[2].J
        loose = optimal_timing(robot, path, cost, max_duration=1.05 * free.duration, **ends)
        assert loose.J == pytest.approx(free.J, rel=1e-12)


def test_the_time_optimal_cost_at_a_longer_duration_takes_the_least_torque() -> None:
    """f0 = 1: every timing of duration T has J = T; the one returned holds the limits, lasts T
    and needs less ∫ Σ u²/U² dt than the time-optimal motion slowed down uniformly to T."""
    robot, path, _ = seeded_path("ur5", 3)
    fastest = optimal_timing(robot, path)
    duration = 1.5 * fastest.duration
    result = optimal_timing(robot, path, duration=duration)
    assert result.duration == pytest.approx(duration, rel=1e-9)
    assert result.J == pytest.approx(duration, rel=1e-9)
    verified(robot, result, path.theta0, path.thetae, duration=duration)
    slowed = Trajectory(
        path,
        fastest.trajectory.s,
        fastest.trajectory.b * (fastest.duration / duration) ** 2,
        robot.inverse_dynamics_batch,
    )
    assert slowed.duration == pytest.approx(duration, rel=1e-12)
    effort = np.maximum(np.abs(robot.limits.effort_lower), np.abs(robot.limits.effort_upper))
    torque = nearopt.TorqueCost(weights=1.0 / effort**2)
    assert result.trajectory.integrate(torque) < slowed.integrate(torque)


def test_bad_end_velocities_and_durations_are_named() -> None:
    robot, path, direction = seeded_path("two_link", 2)
    names = robot.joint_names
    across = np.array([direction[1], -direction[0]])
    cases = [
        ({"qd0": across}, nearopt.ConfigurationError, "points elsewhere"),
        ({"qde": -0.5 * direction}, nearopt.ConfigurationError, "goes the other way"),
        ({"qd0": [1.0]}, nearopt.ConfigurationError, "must be 2 joint velocities"),
        ({"qd0": [np.nan, 0.0]}, nearopt.ConfigurationError, "qd0 of joint 'joint1' is nan"),
        ({"qd0": 1e4 * direction}, nearopt.ConfigurationError, "beyond its speed limit"),
        ({"qd0": 95.0 * direction / np.max(np.abs(direction))}, nearopt.InfeasiblePathError, "qd0"),
        ({"duration": 1e-3}, nearopt.InfeasiblePathError, "shorter than the time-optimal"),
        ({"max_duration": 1e-3}, nearopt.InfeasiblePathError, "shorter than the time-optimal"),
        ({"duration": 1.0, "max_duration": 1.0}, nearopt.ConfigurationError, "not both"),
        ({"duration": -1.0}, nearopt.ConfigurationError, "positive"),
        ({"duration": "soon"}, nearopt.ConfigurationError, "seconds"),
        ({"duration": "2"}, nearopt.ConfigurationError, "a number of seconds, got '2'"),
        ({"max_duration": True}, nearopt.ConfigurationError, "a number of seconds, got True"),
        (
            {"qd0": 0.5 * direction, "duration": 1e9},
            nearopt.InfeasiblePathError,
            "no timing of this path was found that lasts 1000000000 s",
        ),
    ]
    for options, error, words in cases:
        with pytest.raises(error, match=words) as caught:
            optimal_timing(robot, path, **options)
        message = str(caught.value)
        assert "\n" not in message
        if words in ("points elsewhere", "goes the other way", "beyond its speed limit", "qd0"):
            assert any(joint in message for joint in names), message
        if words == "shorter than the time-optimal":  # by how much the fastest misses T [s]
            fastest = optimal_timing(robot, path).duration
            assert caught.value.excess == pytest.approx(fastest - 1e-3, rel=1e-6)
    custom = nearopt.CallableCost(lambda q, qd, u: 1.0 + np.sum(u**2, axis=1))
    with pytest.raises(nearopt.ConfigurationError, match="a duration is kept for"):
        optimal_timing(robot, path, custom, duration=1.0)


@pytest.mark.parametrize("name", ["two_link", "ur5"])
def test_a_plan_under_a_duration_meets_it_and_beats_the_line(name: str) -> None:
    """Stage 2 on the duration's Lagrangian: t_e = T, every check of verify_plan (the duration
    included), J below the straight line's under the same T (where the line can be that fast)
    and, at the free plan's own t_e, the free plan's J."""
    robot, path, _ = seeded_path(name, 21)
    q0, qe = path.theta0, path.thetae
    cost = nearopt.TorqueCost(1e-3)
    free = nearopt.plan(robot, q0, qe, cost, time_limit=60.0)
    fastest = nearopt.plan(robot, q0, qe, time_limit=60.0).duration
    for factor in (0.5, 1.0, 1.2):  # between the time-optimal plan's t_e and the free one's
        duration = fastest + factor * (free.duration - fastest)
        result = nearopt.plan(robot, q0, qe, cost, duration=duration, time_limit=60.0)
        assert result.duration == pytest.approx(duration, rel=1e-9, abs=0.0)
        assert result.duration_asked == (duration, True)
        report = nearopt.verify_plan(result)
        assert report.passed and "duration" in str(report), str(report)
        try:
            line = nearopt.plan(robot, q0, qe, cost, duration=duration, max_iterations=0)
            assert result.J < line.J
        except nearopt.InfeasiblePathError:  # the line is slower than T at its fastest
            assert duration < nearopt.plan(robot, q0, qe, max_iterations=0).duration
        if factor == 1.0:  # (both stop where J changes by < 1e-4 relative per iteration)
            assert result.J <= free.J * (1.0 + 1e-3)
    most = 0.5 * (fastest + free.duration)
    bounded = nearopt.plan(robot, q0, qe, cost, max_duration=most)
    assert bounded.duration <= most * (1.0 + 1e-12)
    assert nearopt.verify_plan(bounded).passed


def test_durations_through_the_command_line_and_their_refusals(tmp_path) -> None:
    out = tmp_path / "plan.json"
    run = run_cli(
        "plan", "--robot", "two_link", "--q0", "0.2", "0.1", "--qe", "0.9", "-0.6",
        "--beta", "0.03", "--duration", "0.3", "--json", str(out),
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    document = json.loads(out.read_text())
    assert document["duration_asked"] == {"seconds": 0.3, "exact": True}
    assert document["t"][-1] == pytest.approx(0.3, rel=1e-12)
    assert document["duration"] == pytest.approx(0.3, rel=1e-9)
    robot = load("two_link")
    q0, qe = np.array([0.2, 0.1]), np.array([0.9, -0.6])
    for options, words in (
        ({"duration": 1e-3}, "along the fastest path stage 2 found"),
        ({"duration": 1.0, "max_duration": 2.0}, "not both"),
        ({"duration": 0.0}, "positive"),
    ):
        with pytest.raises(nearopt.NearoptError, match=words):
            nearopt.plan(robot, q0, qe, nearopt.TorqueCost(0.03), **options)
    custom = nearopt.CallableCost(lambda q, qd, u: 1.0 + np.sum(u**2, axis=1))
    with pytest.raises(nearopt.ConfigurationError, match="a duration is kept for"):
        nearopt.plan(robot, q0, qe, custom, duration=1.0)
    for limits in ({"jerk": 1000.0}, {"torque_rate": 1000.0}):
        with pytest.raises(nearopt.ConfigurationError, match="jerk or torque-rate limits"):
            nearopt.plan(robot.with_limits(**limits), q0, qe, duration=1.0)


def _reference_within(problem, cost: nearopt.TorqueCost, duration: float):
    """Clarabel's SOCP with Σ t_k ≤ T (1 + ε), ε = 1e-6, else 2e-6, else 5e-6 (the first it
    solves)."""
    for slack in (1e-6, 2e-6):
        try:
            return solve_timing(
                problem, cost, method=TimingMethod.SOCP, max_duration=duration * (1.0 + slack)
            )
        except nearopt.SolverError:
            continue
    return solve_timing(problem, cost, method=TimingMethod.SOCP, max_duration=duration * 1.000005)


def test_a_time_optimal_plan_asked_for_its_own_duration_is_planned() -> None:
    """z1, rest to rest, f0 = 1, t_e = T and t_e ≤ T at the plan's own t_e: stage 1 timed the
    path again 6.1e-10 slower (it is solved to 1e-9) and t_e = T was refused as too short."""
    robot = load("z1")
    q0 = np.array(
        [0.9738938241083765, 0.5036939383604526, -0.23568064172221126,
         0.9752786454565794, 1.2744351658649562, 2.7354503343057215]
    )  # fmt: skip
    qe = np.array(
        [2.575297693642027, 1.4969489966060514, -1.686492202917456,
         -0.8998147012764067, -0.5214219833102249, 1.8377088446004737]
    )  # fmt: skip
    free = nearopt.plan(robot, q0, qe, nearopt.TimeCost())
    for word in ("duration", "max_duration"):
        result = nearopt.plan(robot, q0, qe, nearopt.TimeCost(), **{word: free.duration})
        report = nearopt.verify_plan(result)  # t_e against T: to 1e-9, t_e ≤ T to 1e-12
        assert report.passed, str(report)
        assert result.J <= free.J * (1.0 + 1e-9)


def test_a_max_duration_refused_by_stage_1s_accuracy_returns_the_plan_without_it(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Where stage 1 refuses t_e ≤ T by no more than its accuracy (a ur5 re-plan asked for its
    own t_e: 1.5e-11 s), the plan without the limit is returned if its t_e keeps it; a refusal
    by more stands. (The refusal is forced here: the fuzz pass's case is planned directly now.)"""
    import nearopt.planning.planner as planner

    robot = load("ur5")
    q0, qe = np.zeros(6), np.array([0.6, -0.4, 0.5, 0.3, -0.2, 0.4])
    free = nearopt.plan(robot, q0, qe, nearopt.TimeCost())
    planned = planner._planned

    def refusing(excess: float):
        def fake(setup, callback, verbose):  # noqa: ANN001, ANN202 - the planner's own
            if setup.duration is not None:
                raise nearopt.InfeasiblePathError("too short (forced)", excess=excess)
            return planned(setup, callback, verbose)

        return fake

    monkeypatch.setattr(planner, "_planned", refusing(1e-11))
    result = nearopt.plan(robot, q0, qe, nearopt.TimeCost(), max_duration=free.duration)
    assert result.J == free.J
    assert "the plan without max_duration" in result.message
    assert nearopt.verify_plan(result).passed
    monkeypatch.setattr(planner, "_planned", refusing(1e-6))
    with pytest.raises(nearopt.InfeasiblePathError, match="forced"):
        nearopt.plan(robot, q0, qe, nearopt.TimeCost(), max_duration=free.duration)
    monkeypatch.setattr(planner, "_planned", refusing(1e-11))
    with pytest.raises(nearopt.InfeasiblePathError, match="forced"):  # its t_e would not keep it
        nearopt.plan(robot, q0, qe, nearopt.TimeCost(), max_duration=0.999 * free.duration)
