"""The second start of stage 2 for a torque cost (``SCPOptions.continuation``): stage 2 under
heavier torque weights finds the slow motions that hold the arm against gravity less, which
stage 2 from the straight line, among the fastest, does not reach."""

from __future__ import annotations

import numpy as np
import pytest
from checks import assert_independent_checks
from conftest import load

import nearopt

COST = nearopt.TorqueCost(1e-3)
ALONE = nearopt.SCPOptions(continuation=1.0)


def motion(robot: nearopt.Robot, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A start and goal within 40 % of each joint's range around its middle (as
    ``scripts/bench_duration.py``)."""
    rng = np.random.default_rng(seed)
    lo = np.maximum(robot.limits.position_lower, -3.0)
    hi = np.minimum(robot.limits.position_upper, 3.0)
    mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    return tuple(mid + 0.4 * half * rng.uniform(-1, 1, robot.n) for _ in range(2))


def test_the_heavier_start_finds_a_slower_motion_a_quarter_cheaper() -> None:
    """ur5, seed 1: stage 2 from the straight line stops at J 2.711 (t_e 0.74 s); from the path
    found under three times the weights it reaches 2.02 (t_e 1.72 s, the arm held against gravity
    less). The plan is checked as every plan (forward simulation, limits, J)."""
    robot = load("ur5")
    q0, qe = motion(robot, 1)
    alone = nearopt.plan(robot, q0, qe, COST, options=ALONE)
    seen: list[nearopt.Iteration] = []
    result = nearopt.plan(robot, q0, qe, COST, callback=seen.append)
    assert result.J <= 0.8 * alone.J, (result.J, alone.J)
    assert result.duration > 1.5 * alone.duration
    assert "under 3 times the torque weights" in result.message
    # the history: the first run's iterates, then the second's from the heavier start's path
    assert [it.index for it in seen] == [it.index for it in result.history]
    assert [it.index for it in result.history] == list(range(len(result.history)))
    assert [it.alpha is None for it in result.history].count(True) == 2
    assert np.all(np.diff([it.J for it in result.history]) < 0.0)
    assert_independent_checks(robot, result.trajectory, COST, result.J, q0, qe)


@pytest.mark.parametrize(("name", "seed"), [("ur5", 2), ("panda", 3), ("kinova", 0)])
def test_the_second_start_never_costs_j(name: str, seed: int) -> None:
    """Where the heavier start finds nothing better, the first run's plan is returned as it is."""
    robot = load(name)
    q0, qe = motion(robot, seed)
    alone = nearopt.plan(robot, q0, qe, COST, options=ALONE)
    result = nearopt.plan(robot, q0, qe, COST)
    assert result.J <= alone.J
    if "torque weights" not in result.message:
        assert result.J == alone.J
    assert nearopt.verify_plan(result).passed


def test_time_optimal_plans_take_one_start() -> None:
    """f0 = 1 has no weights to make heavier: the plan is the one of stage 2 alone."""
    robot = load("ur5")
    q0, qe = motion(robot, 1)
    time_optimal = nearopt.TorqueCost(0.0)
    alone = nearopt.plan(robot, q0, qe, time_optimal, options=ALONE)
    assert nearopt.plan(robot, q0, qe, time_optimal).J == alone.J


@pytest.mark.parametrize("value", [0.5, -3.0, float("nan"), float("inf"), "3"])
def test_a_bad_continuation_is_refused(value: object) -> None:
    options = nearopt.SCPOptions(continuation=value)  # type: ignore[arg-type]
    with pytest.raises(nearopt.ConfigurationError, match="continuation must be"):
        nearopt.plan(load("ur5"), np.zeros(6), np.full(6, 0.3), COST, options=options)


def test_under_a_duration_the_first_runs_path_is_kept_as_a_start() -> None:
    """ur5, seed 12, t_e = 1.2 s: the second start's plan without the duration is slower (1.8 s)
    and cannot meet T; stage 2 under T still starts from the first run's (it was dropped for the
    lower of the two: J 3.42 against 3.17)."""
    robot = load("ur5")
    q0, qe = motion(robot, 12)
    alone = nearopt.plan(robot, q0, qe, COST, duration=1.2, options=ALONE)
    result = nearopt.plan(robot, q0, qe, COST, duration=1.2)
    assert result.duration == pytest.approx(1.2, rel=1e-9, abs=0.0)
    assert result.J <= alone.J * (1 + 1e-9), (result.J, alone.J)


def test_a_duration_limit_binds_where_the_better_motion_is_slower() -> None:
    """ur5, seed 1, t_e ≤ 1.5 s: the cheapest motion without a limit takes 1.72 s; below it the
    plan at t_e = 1.5 s (J 2.18) is the answer, not the fast one of 0.74 s (J 2.71)."""
    robot = load("ur5")
    q0, qe = motion(robot, 1)
    result = nearopt.plan(robot, q0, qe, COST, max_duration=1.5)
    exact = nearopt.plan(robot, q0, qe, COST, duration=1.5)
    assert result.duration <= 1.5 * (1 + 1e-12)
    assert result.J <= exact.J * (1 + 1e-9), (result.J, exact.J)
    assert result.J < 0.9 * nearopt.plan(robot, q0, qe, COST, options=ALONE).J
    assert nearopt.verify_plan(result).passed
