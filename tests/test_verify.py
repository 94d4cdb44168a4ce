"""verify(): passes a planned motion and catches each kind of broken one."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
import textwrap

import numpy as np
import pinocchio as pin
import pytest
from conftest import load

import nearopt
from nearopt import Trajectory, VerificationError, verify, verify_plan
from nearopt.paper_example import COST, THETA_0, THETA_E


@pytest.fixture(scope="module")
def plan() -> nearopt.PlanResult:
    return nearopt.plan(load("two_link"), THETA_0, THETA_E, COST, grid=60, max_iterations=20)


def test_a_plan_passes_every_check(plan: nearopt.PlanResult) -> None:
    report = verify(
        plan.trajectory, plan.robot, rate=500.0, q0=THETA_0, qe=THETA_E, cost=COST, J=plan.J
    )
    assert report.passed, str(report)
    assert [c.name for c in report.checks] == [
        "torque limits (RNEA)",
        "joint speed limits",
        "joint position limits",
        "end positions",
        "rest at both ends",
        "J recomputed",
        "simulated end position",
        "simulated end speed",
        "simulation window defect",
    ]
    assert report.samples == int(np.floor(plan.duration * 500)) + 1 + 1  # 0 … te inclusive
    assert report["torque limits (RNEA)"].worst < 0  # strictly inside somewhere short of limits
    report.raise_if_failed()


def test_verify_plan_checks_what_the_plan_carries(plan: nearopt.PlanResult) -> None:
    """verify_plan takes the robot, cost, J and motion from the plan (at 1 kHz at least), the
    same checks as verify with them; the plan's robot is the one checked against."""
    report = verify_plan(plan, rate=250.0, q0=THETA_0, qe=THETA_E)
    assert report.passed, str(report)
    assert report.rate == 1000.0
    by_hand = verify(
        plan.trajectory, plan.robot, rate=1000.0, q0=THETA_0, qe=THETA_E, cost=COST, J=plan.J
    )
    assert report == by_hand
    damped = dataclasses.replace(plan, robot=plan.robot.with_limits(damping=[0.5, 0.5]))
    failed = {c.name for c in verify_plan(damped).failures()}
    assert {"simulated end position", "simulation window defect"} <= failed


def test_a_faster_motion_breaks_the_torque_limits(plan: nearopt.PlanResult) -> None:
    traj = plan.trajectory
    fast = Trajectory(traj.path, traj.s, traj.b * 1.5, plan.robot.inverse_dynamics_batch)
    report = verify(fast, plan.robot)
    assert [c.name for c in report.failures()] == ["torque limits (RNEA)"]
    assert "joint" in report["torque limits (RNEA)"].where
    with pytest.raises(VerificationError, match="torque limits"):
        report.raise_if_failed()


def test_wrong_goal_limits_and_cost_are_caught(plan: nearopt.PlanResult) -> None:
    robot, traj = plan.robot, plan.trajectory
    assert not verify(traj, robot, qe=THETA_E + 1e-6)["end positions"].passed
    assert not verify(traj, robot, cost=COST, J=plan.J * 1.01)["J recomputed"].passed
    slow = robot.with_limits(velocity=[5.0, 5.0])
    assert not verify(traj, slow)["joint speed limits"].passed
    narrow = robot.with_limits(position=([-1.0, -2.0], [1.0, 2.0]))  # θ0 = 0.785, θe = −1.57
    assert not verify(traj, narrow)["joint position limits"].passed


def test_forward_simulation_catches_a_model_mismatch(plan: nearopt.PlanResult) -> None:
    """The same motion checked on an arm with damping it was not planned for: u(t) of the plan
    does not take the damped arm to θe, and RNEA wants more torque."""
    damped = plan.robot.with_limits(damping=[0.5, 0.5])
    report = verify(plan.trajectory, damped)
    failed = {c.name for c in report.failures()}
    assert {"simulated end position", "simulation window defect"} <= failed


def test_rate_must_be_positive(plan: nearopt.PlanResult) -> None:
    with pytest.raises(nearopt.ConfigurationError, match="rate"):
        verify(plan.trajectory, plan.robot, rate=0.0)


def test_joints_without_a_speed_or_position_limit_are_not_failures(
    plan: nearopt.PlanResult,
) -> None:
    free = plan.robot.with_limits(
        velocity=[np.inf, 100.0], position=([-np.inf, -7.0], [np.inf, 7.0])
    )
    report = verify(plan.trajectory, free)
    assert report.passed, str(report)


def test_a_two_hour_motion_verifies_in_bounded_memory() -> None:
    """The paper's arm at 3e-4 rad/s: a 2.2-hour motion, verified at 1 kHz (7.9 million
    samples, J recomputed, simulated) in a process whose address space may grow by at most
    300 MB beyond what verifying a 0.4 s motion left it: a check's memory does not grow with the
    duration (all samples at once would take about 600 MB, J's nodes more)."""
    script = textwrap.dedent(
        """
        import os, resource
        import nearopt
        from nearopt.paper_example import COST, THETA_0, THETA_E

        robot = nearopt.Robot.from_name("two_link")
        short = nearopt.plan(robot, THETA_0, THETA_E, COST, max_iterations=0)
        slow = robot.with_limits(velocity=[3e-4, 3e-4])
        long = nearopt.plan(slow, THETA_0, THETA_E, COST, max_iterations=0)
        assert nearopt.verify_plan(short, q0=THETA_0, qe=THETA_E).passed
        used = int(open("/proc/self/statm").read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
        resource.setrlimit(resource.RLIMIT_AS, (used + 300 * 2**20, resource.RLIM_INFINITY))
        report = nearopt.verify_plan(long, q0=THETA_0, qe=THETA_E)
        print(long.duration, report.samples, report.passed)
        """
    )
    run = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=300
    )
    assert run.returncode == 0, run.stderr[-2000:]
    duration, samples, passed = run.stdout.split()
    assert float(duration) > 7200.0 and int(samples) > 7_200_000 and passed == "True"


@pytest.mark.parametrize("name", ["two_link", "xarm7"])
def test_the_simulated_end_state_agrees_with_scipys_dop853(name: str) -> None:
    """verify's forward simulation (Dormand-Prince 5, Richardson's check) against SciPy's
    DOP853 at rtol 1e-12 over the same last window, piece by piece between the knots where the
    torque jumps, on an arm with more damping than the motion was planned for (so that u(t)
    takes it far from θe): the end states within the accuracy verify asks of itself (1 % of its
    tolerance, 1e-7). xarm7's strong joint damping is stiff: its simulation is implicit (Radau
    IIA), its Newton iterations started from the motion's states, which u(t) here leaves."""
    from scipy.integrate import solve_ivp

    robot = load(name)
    rng = np.random.default_rng(0)
    if name == "two_link":
        q0, qe = THETA_0, THETA_E
    else:
        lo, hi = robot.limits.position_lower, robot.limits.position_upper
        q0, qe = rng.uniform(0.7 * lo + 0.3 * hi, 0.3 * lo + 0.7 * hi, (2, robot.n))
    motion = nearopt.plan(robot, q0, qe, nearopt.TorqueCost(0.01), max_iterations=0).trajectory
    robot, n = robot.with_limits(damping=robot.damping + 0.2), robot.n
    report = verify(motion, robot, q0=q0, qe=qe, simulate=True)
    simulated = next(c for c in report.checks if c.name == "simulated end position")
    assert simulated.worst > 1e-4  # far from θe

    def rate(t: float, x: np.ndarray) -> np.ndarray:
        u = motion.torque(np.array([t]))[0] - robot.damping * x[n:]
        return np.concatenate([x[n:], pin.aba(robot.model, data, x[:n], x[n:], u)])

    data = robot.model.createData()
    start = np.arange(0.0, motion.duration, 0.25)[-1]
    cuts = np.concatenate([[start], motion.t[motion.t > start], [motion.duration]])
    cuts = np.unique(cuts[cuts <= motion.duration])
    q, qd, _ = motion.states(np.array([start]))
    x = np.concatenate([q[0], qd[0]])
    for a, b in zip(cuts[:-1], cuts[1:], strict=True):
        inside = 1e-12 * max(1.0, b)
        x = solve_ivp(rate, (a + inside, b - inside), x, "DOP853", rtol=1e-12, atol=1e-13).y[:, -1]
    assert simulated.worst == pytest.approx(np.max(np.abs(x[:n] - qe)), abs=1e-7)


def test_an_implicit_simulation_lane_that_fails_leaves_the_others_alone() -> None:
    """Windows are simulated side by side (lanes); where Radau IIA's Newton iterations fail in
    one (here its state is NaN), that lane ends in NaN (its check fails) and the others are
    integrated as they would be alone (the convergence test was one for all lanes: all NaN)."""
    import importlib

    checks = importlib.import_module("nearopt.verify")
    robot = load("xarm7")
    lo, hi = robot.limits.position_lower, robot.limits.position_upper
    q0, qe = 0.6 * lo + 0.4 * hi, 0.4 * lo + 0.6 * hi
    motion = nearopt.plan(robot, q0, qe, nearopt.TorqueCost(0.01), max_iterations=0).trajectory
    starts = np.array([0.0, 0.25 * motion.duration])
    cuts = [
        np.concatenate([[a], motion.t[(motion.t > a) & (motion.t < a + 0.1)], [a + 0.1]])
        for a in starts
    ]
    x = np.hstack(motion.states(starts)[:2])
    simulate = checks._Collocation(robot, motion, checks.MAX_STEP, 1e-10)
    alone = simulate(cuts[1:], x[1:], [1])
    x[0, 0] = np.nan
    both = simulate(cuts, x, [1, 1])
    assert np.all(np.isnan(both[0]))
    np.testing.assert_allclose(both[1], alone[0], rtol=0, atol=1e-12)
    end = np.hstack(motion.states(starts[1:] + 0.1)[:2])[0]
    assert np.max(np.abs(both[1] - end)) < 1e-7  # and it is where the motion is
