"""Stage 2 under jerk limits (nearopt.planning.smooth): the model's jerk rows are the discrete
jerk's restriction at the knots, exact in b and in the path's control points at the point they
are built at; a plan continues from the better of its two paths under the limits and lowers J
below both, every iterate of that phase lower than the one before, verified."""

from __future__ import annotations

import numpy as np
import pytest

import nearopt
from nearopt.planning import jerk_rows
from nearopt.planning.records import SCPOptions
from nearopt.planning.scp import knot_breaks
from nearopt.timing import Discretisation, optimal_timing, time_with_jerk_limits


def _discrete_jerk(sigma: np.ndarray, b: np.ndarray, path: nearopt.BSplinePath) -> np.ndarray:
    """√b (θ‴b + 3θ″a + θ′a′) at the inner knots, a = b′/2 and a′ = b″/2 by the derivatives of
    the parabola through each knot and its two neighbours (np.polyfit), shape (N − 1, n)."""
    out = []
    for k in range(1, sigma.size - 1):
        c2, c1, _ = np.polyfit(sigma[k - 1 : k + 2] - sigma[k], b[k - 1 : k + 2], 2)
        a, da = 0.5 * c1, c2  # b′ = c1, b″ = 2 c2 at the knot
        d1, d2, d3 = (path(sigma[k : k + 1], order)[0] for order in (1, 2, 3))
        out.append(np.sqrt(b[k]) * (d3 * b[k] + 3.0 * d2 * a + d1 * da))
    return np.array(out)


@pytest.mark.parametrize("name", ["ur5", "two_link"])
def test_the_jerk_rows_are_the_discrete_jerk_and_a_restriction_of_it(name: str) -> None:
    robot = nearopt.Robot.from_name(name)
    rng = np.random.default_rng(3)
    q0 = 0.5 * rng.uniform(robot.limits.position_lower, robot.limits.position_upper) / np.pi
    qe = q0 + rng.uniform(-1.0, 1.0, robot.n)
    options = SCPOptions()
    k = options.control_points
    line = nearopt.BSplinePath.line(q0, qe, k, knot_breaks(options, k))
    disc = Discretisation.of(optimal_timing(robot, line, grid=40).problem)
    sigma = disc.problem.sigma
    b_bar = time_with_jerk_limits(robot.with_limits(jerk=100.0), line, nearopt.TimeCost()).timing
    b_bar = b_bar.evaluate(sigma)[0]
    jerk = np.linspace(50.0, 150.0, robot.n)
    matrix, lower, upper = jerk_rows(disc, line, b_bar, jerk)
    assert np.all(lower == -np.inf)
    rows = np.arange(1, sigma.size - 1)
    keep = b_bar[rows] > 0
    # at b = b̄ with the control points moved, each row is (±√b̄ L − j)/(1.5 j) with L the
    # moved path's: L is linear in the control points, so the rows' path part is exact there
    step = 0.05 * rng.normal(size=(k, robot.n))
    moved = nearopt.BSplinePath(
        np.vstack([q0, line.control_points[1:-1] + step, qe]), line.knots[4:-4]
    )
    x = np.concatenate([b_bar[1:-1], step.ravel()])
    value = (matrix @ x - upper).reshape(2, -1, robot.n)
    expected = _discrete_jerk(sigma, b_bar, moved)[keep]
    np.testing.assert_allclose(value[0], (expected - jerk) / (1.5 * jerk), atol=1e-9)
    np.testing.assert_allclose(value[1], (-expected - jerk) / (1.5 * jerk), atol=1e-9)
    # for another b, rows that hold keep the discrete jerk within its limits (the tangent of
    # the convex j/√b lies below it)
    held = 0
    for _ in range(20):
        b = b_bar * rng.uniform(0.5, 2.0, b_bar.size)
        b[[0, -1]] = b_bar[[0, -1]]
        x = np.concatenate([b[1:-1], np.zeros(k * robot.n)])
        hold = (matrix @ x <= upper).reshape(2, -1, robot.n).all(axis=0)
        jerk_at = np.abs(_discrete_jerk(sigma, b, line)[keep])
        assert np.all(jerk_at[hold] <= jerk[np.nonzero(hold)[1]] * (1 + 1e-9))
        held += int(hold.sum())
    assert held > 0  # (the check compared something)


def _ur5_case() -> tuple[nearopt.Robot, np.ndarray, np.ndarray, nearopt.TorqueCost]:
    free = nearopt.Robot.from_name("ur5")
    rng = np.random.default_rng(0)
    lo, hi = np.maximum(free.limits.position_lower, -3), np.minimum(free.limits.position_upper, 3)
    q0, qe = (0.5 * (lo + hi) + 0.2 * (hi - lo) * rng.uniform(-1, 1, 6) for _ in range(2))
    return free.with_limits(jerk=300.0), q0, qe, nearopt.TorqueCost(1e-3)


def test_a_plan_under_jerk_limits_goes_on_under_them() -> None:
    """ur5 at 300 rad/s³ (f0 = 1 + 1e-3 Σu²): stage 2 without the limit finds a path better
    than the line under them too; stage 2 under the limits, from there, lowers J further, every
    accepted iterate below the one before; the plan is verified (the jerk at every sample)."""
    robot, q0, qe, cost = _ur5_case()
    # the path stage 2 finds without the limit from the line alone (a plan under jerk limits
    # takes no second start)
    alone = nearopt.SCPOptions(continuation=1.0)
    found = nearopt.plan(robot.with_limits(jerk=np.inf), q0, qe, cost, options=alone)
    result = nearopt.plan(robot, q0, qe, cost)
    line = nearopt.plan(robot, q0, qe, cost, max_iterations=0)
    before = min(line.J, time_with_jerk_limits(robot, found.trajectory.path, cost).J)
    assert result.J < 0.97 * before, result.message
    assert "stage 2 under the limits from there" in result.message
    starts = [i for i, it in enumerate(result.history) if it.alpha is None]
    # the first path, the second start's path (here it wins), where the phase under the limits
    # begins
    assert starts[0] == 0 and len(starts) == 3, starts
    phase = [it.J for it in result.history[starts[-1] :]]
    assert len(phase) > 1 and np.all(np.diff(phase) < 0.0)
    report = nearopt.verify_plan(result)
    assert report.passed, report
    assert "joint jerk limits" in {c.name for c in report.checks}


def test_the_phase_under_the_limits_reports_stops_and_can_be_interrupted() -> None:
    """Its iterates reach the callback like stage 2's; Ctrl-C in it ends the plan with its best
    iterate (status interrupted, verified); Ctrl-C in stage 2 ends planning there (no phase);
    with too few iterations for it the status says the iteration limit."""
    robot, q0, qe, cost = _ur5_case()
    seen: list[nearopt.Iteration] = []
    whole = nearopt.plan(robot, q0, qe, cost, callback=seen.append)
    assert [it.index for it in seen] == [it.index for it in whole.history]
    begins = [it.index for it in whole.history if it.alpha is None][-1]  # the phase's start

    def stop_at(index: int):
        def callback(entry: nearopt.Iteration) -> None:
            if entry.index == index:
                raise KeyboardInterrupt

        return callback

    late = nearopt.plan(robot, q0, qe, cost, callback=stop_at(begins + 2))
    assert late.status == nearopt.StopReason.INTERRUPTED
    assert late.history[-1].index == begins + 2
    assert late.J < whole.history[begins].J  # (the phase's second iterate, timed on the grid)
    assert nearopt.verify_plan(late).passed
    early = nearopt.plan(robot, q0, qe, cost, callback=stop_at(3))
    assert early.status == nearopt.StopReason.INTERRUPTED
    assert "stage 2 under the limits" not in early.message
    assert [it.alpha for it in early.history].count(None) == 1
    short = nearopt.plan(robot, q0, qe, cost, max_iterations=begins)  # one iteration left
    assert short.status == nearopt.StopReason.ITERATION_LIMIT, short.message
    assert "iteration limit (1)" in short.message


def test_a_jerk_limit_far_below_the_path_s_needs_is_said_or_planned_on_the_first_path() -> None:
    """At 1e-9 rad/s³ the jerk-limited timing of stage 2's path came out NaN (a plan then
    failed on 'sample 0 … is nan'): it is a SolverError saying so, and the plan returns the
    straight line timed under the limit (4257 s)."""
    ur5 = nearopt.Robot.from_name("ur5")
    q0 = np.array([0.028372, 1.081113, -0.854017, 1.076759, -0.451605, -0.184017])
    qe = np.array([0.786486, -0.217922, 0.119025, -1.133858, 0.608431, 0.091544])
    cost = nearopt.TorqueCost(1e-3)
    tiny = ur5.with_limits(jerk=1e-9)
    # (the path stage 2 finds from the line alone: the one whose timing came out NaN)
    alone = nearopt.SCPOptions(continuation=1.0)
    found = nearopt.plan(ur5, q0, qe, cost, options=alone).trajectory.path
    with pytest.raises(nearopt.SolverError, match="not finite"):
        time_with_jerk_limits(tiny, found, cost)
    result = nearopt.plan(tiny, q0, qe, cost, max_iterations=40)
    assert np.isfinite(result.J) and result.duration > 1000.0
    assert "the first path is returned" in result.message
