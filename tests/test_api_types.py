"""The public API called with wrong types and shapes: every call either works or raises a
NearoptError naming what is wrong — never a TypeError, AttributeError or a Pinocchio error.

Each case takes one good call of a public function and puts one bad value in one argument
(every argument in turn, every bad value in turn)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from conftest import load

import nearopt
from nearopt import NearoptError
from nearopt.paper_example import COST, THETA_0, THETA_E

BAD: tuple[Any, ...] = (
    None,
    "5",
    "abc",
    -1,
    0,
    2.5,
    np.nan,
    np.inf,
    True,
    [1.0, 2.0, 3.0],
    [[0.0, 0.0], [1.0, 1.0]],
    {"a": 1},
    object(),
    np.zeros((2, 2)),
    np.float32(0.5),
    (),
)


def good_calls() -> dict[str, tuple[Callable[..., object], tuple, dict[str, Any]]]:
    """Name → (function, positional arguments, keyword arguments) of a call that works."""
    robot = load("two_link")
    plan = nearopt.plan(robot, THETA_0, THETA_E, COST, grid=20, max_iterations=1)
    cheap = {"grid": 20, "max_iterations": 1, "time_limit": 60.0, "callback": lambda it: None}
    # where the tip is at θe: a pose the arm reaches
    reachable = nearopt.ToolPose(robot.frame_placement(THETA_E).translation.tolist())
    return {
        "plan": (nearopt.plan, (robot, THETA_0, THETA_E, COST), cheap),
        "optimal_timing": (
            nearopt.optimal_timing,
            (robot, nearopt.StraightPath(THETA_0, THETA_E), COST),
            {"grid": 20},
        ),
        "verify": (nearopt.verify, (plan.trajectory, robot), {"rate": 200.0}),
        "verify_plan": (nearopt.verify_plan, (plan,), {"rate": 200.0}),
        "TorqueCost": (nearopt.TorqueCost, (0.03,), {}),
        "with_limits": (robot.with_limits, (), {"velocity": 3.0, "effort": [10.0, 5.0]}),
        "StraightPath": (nearopt.StraightPath, (THETA_0, THETA_E), {}),
        "Scene": (nearopt.Scene, ((),), {"margin": 0.01}),
        "ToolPose": (nearopt.ToolPose, ([0.5, 0.2, 0.0],), {}),
        "inverse_kinematics": (
            nearopt.inverse_kinematics,
            (robot, reachable),
            {"seed": THETA_0},
        ),
        "from_name": (nearopt.Robot.from_name, ("two_link",), {}),
        "check_configuration": (robot.check_configuration, (THETA_0,), {}),
        "sample": (plan.trajectory.sample, (100.0,), {}),
    }


CALLS = good_calls()


def variants() -> list[tuple[str, str, int]]:
    """(call, argument, bad value's index) of every case."""
    out = []
    for name, (_, args, kwargs) in CALLS.items():
        places = [str(k) for k in range(len(args))] + list(kwargs)
        out += [(name, place, b) for place in places for b in range(len(BAD))]
    return out


@pytest.mark.parametrize("name", list(CALLS))
def test_the_good_calls_work(name: str) -> None:
    function, args, kwargs = CALLS[name]
    function(*args, **kwargs)


@pytest.mark.parametrize(("name", "place", "bad"), variants())
def test_a_wrong_argument_is_a_nearopt_error(name: str, place: str, bad: int) -> None:
    function, args, kwargs = CALLS[name]
    args, kwargs = list(args), dict(kwargs)
    if place.isdigit():
        args[int(place)] = BAD[bad]
    else:
        kwargs[place] = BAD[bad]
    try:
        function(*args, **kwargs)
    except NearoptError as exc:
        assert str(exc).strip(), "an error says what is wrong"
    except Exception as exc:  # noqa: BLE001 - the point: nothing but a NearoptError
        pytest.fail(f"{name} with {place} = {BAD[bad]!r}: {type(exc).__name__}: {exc}")


def test_numpy_numbers_are_numbers() -> None:
    """A NumPy scalar where a number is asked for is taken as that number (it was refused as a
    scene's margin)."""
    assert nearopt.Scene((), margin=np.float32(0.01)).margin == pytest.approx(0.01)
    assert type(nearopt.Scene((), margin=np.float32(0.01)).margin) is float
    assert nearopt.TorqueCost(np.float64(0.03)).beta == pytest.approx(0.03)
    robot = load("two_link")
    result = nearopt.plan(
        robot, THETA_0, THETA_E, COST, grid=np.int64(20), max_iterations=np.int32(1),
        time_limit=np.float32(60.0),
    )  # fmt: skip
    assert result.J > 0
    model = nearopt.CollisionModel(robot, margin=np.float32(0.02))  # it was refused here
    assert model.margin == pytest.approx(0.02) and type(model.margin) is float
    with pytest.raises(nearopt.ConfigurationError, match="margin must be a distance"):
        nearopt.CollisionModel(robot, margin=True)
    task = nearopt.plan_task(
        robot,
        THETA_0,
        [THETA_E],
        COST,
        nearopt.PlanSettings(grid=20, max_iterations=0, time_limit=np.float64(60.0)),
    )  # fmt: skip  (a task's time limit was refused as a NumPy number)
    assert task.J > 0
