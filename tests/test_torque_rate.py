"""Torque-rate limits |u̇_i| ≤ r_i (nearopt.timing.rates, held by the jerk-limited timing's
construction): the rate's coefficients against central differences of the torques, every limit
at 20 kHz on three arms (two of them damped) with jerk, acceleration, torque, speed and
torque-rate limits, a lower limit taking longer, and plans, the command and verify holding and
checking them."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from conftest import load
from console import run_cli

import nearopt
from nearopt.timing import jerk_limited_timing
from nearopt.timing.jerk import SmoothTrajectory, _grid, _Model, _Rows
from nearopt.timing.rates import torque_rate_coefficients

JERK, ACCELERATION = 50.0, 10.0


def _spline(robot: nearopt.Robot, seed: int) -> nearopt.SplinePath:
    rng = np.random.default_rng(seed)
    lo = np.maximum(robot.limits.position_lower, -np.pi)
    hi = np.minimum(robot.limits.position_upper, np.pi)
    return nearopt.SplinePath(np.linspace(0.0, 1.0, 5), rng.uniform(lo, hi, size=(5, robot.n)))


def _rates(robot: nearopt.Robot, motion: nearopt.Motion, t: np.ndarray, h: float = 1e-6):
    """u̇ by central differences of RNEA + D θ̇ over the motion's states (independent of the
    planner's coefficients; across a knot, where u̇ jumps, a value between its two sides)."""

    def u(x: np.ndarray) -> np.ndarray:
        return robot.inverse_dynamics_batch(*motion.states(x))

    return (u(t + h) - u(t - h)) / (2 * h)


def _inside(motion: nearopt.Motion, count: int) -> np.ndarray:
    return np.linspace(1e-5, motion.duration - 1e-5, count)


@pytest.mark.parametrize("name", ["ur5", "xarm7"])
def test_the_coefficients_give_the_torque_rate(name: str) -> None:
    """u̇ = √b (m' a + m a' + c' b + 2 c a + g') + δ' b + δ a at points inside the segments of a
    jerk-limited timing, against central differences of the torques in time (xarm7: damped)."""
    robot = load(name).with_limits(acceleration=ACCELERATION)
    path = _spline(robot, 2)
    timing = jerk_limited_timing(robot, path, JERK, grid=40)
    motion = SmoothTrajectory(path, timing, robot.inverse_dynamics_batch)
    x = np.random.default_rng(0).uniform(0.05, 0.95, size=60)
    seg = np.random.default_rng(1).integers(1, timing.s.size - 2, size=60)
    s = timing.s[seg] + x * np.diff(timing.s)[seg]
    mid = timing.s[seg] + 0.5 * np.diff(timing.s)[seg]
    coef = torque_rate_coefficients(
        robot, path(s, 0), path(s, 1), path(s, 2), np.asarray(path(mid, 3)), path.s_end
    )
    ours = coef.rate(*timing.evaluate(s))
    theirs = _rates(robot, motion, timing.time_at(s))
    assert np.max(np.abs(ours - theirs)) <= 1e-6 * np.max(np.abs(theirs))


@pytest.mark.parametrize(("name", "seed"), [("ur5", 0), ("panda", 1), ("xarm7", 2)])
def test_every_limit_holds_at_20_khz_with_torque_rate_limits(name: str, seed: int) -> None:
    """Torque-rate limits at half the largest |u̇| of the jerk-limited timing, with jerk,
    acceleration, torque and speed limits (panda and xarm7 with their joint damping): at 20 kHz
    every limit within 1e-6 relative, the torque-rate limit binding, θ̈ continuous and 0 at
    rest, and the motion longer than without it."""
    robot = load(name).with_limits(acceleration=ACCELERATION)
    path = _spline(robot, seed)
    free = jerk_limited_timing(robot, path, JERK, grid=60)
    before = SmoothTrajectory(path, free, robot.inverse_dynamics_batch)
    rate = 0.5 * np.max(np.abs(_rates(robot, before, _inside(before, 4001))), axis=0)
    timing = jerk_limited_timing(robot, path, JERK, grid=60, torque_rate=rate)
    motion = SmoothTrajectory(path, timing, robot.inverse_dynamics_batch)
    assert timing.duration > free.duration
    t = _inside(motion, int(20_000 * motion.duration))
    ratio = np.abs(_rates(robot, motion, t)) / rate
    assert np.max(ratio) <= 1.0 + 1e-6
    assert np.max(ratio) >= 0.99  # it binds: held, not absent
    q, qd, qdd = motion.states(t)
    lim = robot.limits
    assert np.max(np.abs(qd) / lim.velocity) <= 1.0 + 1e-6
    assert np.max(np.abs(qdd)) <= ACCELERATION * (1 + 1e-6)
    assert np.max(np.abs(motion.jerk(t))) <= JERK * (1 + 1e-6)
    u = robot.inverse_dynamics_batch(q, qd, qdd)
    assert np.all(u <= lim.effort_upper * (1 + 1e-6)) and np.all(u >= lim.effort_lower * (1 + 1e-6))
    assert np.max(np.abs(np.diff(qdd, axis=0))) <= JERK * np.max(np.diff(t)) * (1 + 1e-6)
    ends = motion.states(np.array([0.0, motion.duration]))[2]
    assert np.max(np.abs(ends)) <= 1e-2 * ACCELERATION


def test_torque_rate_limits_alone_and_a_lower_one_takes_longer() -> None:
    """No jerk limit: the torque rate alone makes the timing C¹; halving the limit lengthens
    the motion, and each holds its limit at 20 kHz."""
    robot = load("ur5")
    path = _spline(robot, 3)
    durations = []
    for rate in (80.0, 40.0):
        timing = jerk_limited_timing(robot, path, np.inf, grid=60, torque_rate=rate)
        motion = SmoothTrajectory(path, timing, robot.inverse_dynamics_batch)
        t = _inside(motion, int(20_000 * motion.duration))
        assert np.max(np.abs(_rates(robot, motion, t))) <= rate * (1 + 1e-6)
        durations.append(timing.duration)
    assert durations[1] > durations[0]


def test_the_restriction_keeps_the_last_iterate_feasible() -> None:
    """A damped arm's torque-rate rows at the last iterate's split: the iterate itself holds
    every one of them (so the next one is no longer), and J never increases."""
    robot = load("xarm7").with_limits(acceleration=ACCELERATION, torque_rate=60.0)
    path = _spline(robot, 4)
    lim = robot.limits
    model = _Model(
        robot, path, _grid(path, 60), lim.jerk, lim.acceleration, True, rate=lim.torque_rate
    )
    bbar = model.first_linearisation()
    x, first = model.solve(bbar, None)
    bbar = np.maximum(x[model.iB], 1e-300)
    rows = _Rows()
    model._rate_rows(rows, bbar, x)
    a, h = rows.matrix(model.nv)
    assert np.max(a @ x - h) <= 1e-9 * np.max(np.abs(h))
    _, second = model.solve(bbar, x)
    assert second <= first * (1 + 1e-8)


def test_a_plan_and_the_command_hold_torque_rate_limits(tmp_path: Path) -> None:
    """--torque-rate-limit: the plan is timed under it, its verification checks the rate by
    central differences of the torques, and the 1 kHz record's torques change by at most the
    limit per step."""
    out = tmp_path / "plan.json"
    done = run_cli(
        "plan", "--robot", "ur5", "--q0", "0", "-1.5", "1.5", "0", "0", "0",
        "--qe", "1.5", "-1", "1", "0.5", "0.5", "0.5", "--time-optimal", "--quiet",
        "--max-iterations", "2", "--grid", "80", "--torque-rate-limit", "40", "--verify",
        "--json", str(out),
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert re.search(r"ok +torque-rate limits", done.stdout)
    record = json.loads(out.read_text())
    u, t = np.array(record["tau"]), np.array(record["t"])
    assert np.max(np.abs(np.diff(u, axis=0)) / np.diff(t)[:, None]) <= 40.0 * (1 + 1e-6)


def test_verify_fails_a_motion_whose_torque_jumps() -> None:
    """A stage-1 motion (θ̈, and so u, jumps at its knots) against torque-rate limits: the
    check fails rather than being left out; a plan under them passes it."""
    robot = nearopt.Robot.from_name("two_link")
    q0, qe = np.array([0.0, 0.0]), np.array([1.0, -0.5])
    result = nearopt.plan(robot, q0, qe, max_iterations=0, grid=40)
    report = nearopt.verify(result.trajectory, robot.with_limits(torque_rate=500.0))
    assert "torque-rate limits (RNEA, central differences)" in {
        c.name for c in report.checks if not c.passed
    }
    limited = nearopt.plan(robot.with_limits(torque_rate=500.0), q0, qe, max_iterations=2, grid=40)
    assert isinstance(limited.trajectory, SmoothTrajectory)
    report = nearopt.verify_plan(limited)
    assert report.passed, report
    assert "torque-rate limits (RNEA, central differences)" in {c.name for c in report.checks}


@pytest.mark.parametrize(
    ("value", "message"),
    [
        (0.0, "torque-rate limit of joint 'joint1' is 0"),
        ([1.0, 2.0, 3.0], "torque-rate limit must have 2 values"),
        (np.nan, "torque-rate limit of joint 'joint1' is nan"),
    ],
)
def test_a_bad_torque_rate_limit_names_the_joint(value: object, message: str) -> None:
    with pytest.raises(nearopt.ConfigurationError, match=message):
        nearopt.Robot.from_name("two_link").with_limits(torque_rate=value)


@pytest.mark.parametrize(("name", "seed", "rate"), [("panda", 0, 5.0), ("xarm7", 0, 1.0)])
def test_small_limits_on_damped_arms_give_slow_timings_that_hold_them(
    name: str, seed: int, rate: float
) -> None:
    """Limits far below the motion's natural rates on damped arms (a fuzz pass's cases, which
    ended in the convex solver's 'infeasible' or 'insufficient progress'): after a refinement
    the last iterate is first slowed down until the new points hold (a restriction linearised
    where it breaks them may hold no timing), so a long motion comes back, holding the limit
    at 2 kHz (the motions last 60–180 s) and binding."""
    robot = load(name).with_limits(acceleration=ACCELERATION)
    path = _spline(robot, seed)
    timing = jerk_limited_timing(robot, path, JERK, grid=60, torque_rate=rate)
    motion = SmoothTrajectory(path, timing, robot.inverse_dynamics_batch)
    free = jerk_limited_timing(robot, path, JERK, grid=60)
    assert timing.duration > 3 * free.duration
    ratio = np.max(np.abs(_rates(robot, motion, _inside(motion, int(2_000 * motion.duration)))))
    assert 0.99 < ratio / rate <= 1.0 + 1e-6
