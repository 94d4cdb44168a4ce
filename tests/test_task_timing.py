"""Tasks whose targets carry a velocity (passed through at it) and a time window (#29): the
segments end and start moving there, meet the windows, and verify checks both."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import load
from console import run_cli

import nearopt
from nearopt import Target, Task, TaskError, Waypoint

START = np.array([0.3, -1.2, 1.4, -1.6, -1.4, 0.2])
PASS = np.array([0.9, -1.0, 1.0, -1.3, -1.5, 0.6])
STOP = np.array([1.5, -0.7, 0.6, -1.0, -1.7, 1.0])
GOAL = np.array([0.6, -1.8, 2.0, -0.6, -0.9, -0.8])
COST = nearopt.TorqueCost(1e-3)
VELOCITY = 0.8 * (STOP - START) / np.max(np.abs(STOP - START))  # [rad/s]


def test_a_target_is_passed_at_its_velocity_and_windows_are_met() -> None:
    """ur5: the first target passed at its velocity (θ̇ there to 1e-9 on both sides), the second
    reached 0.3 s later than without a window (at the window's start, 1e-9), the goal before its
    window closes; each segment no worse than its first path; verify_plan checks it all."""
    robot = load("ur5")
    moving = Target(PASS, stop=False, velocity=VELOCITY)
    free = nearopt.plan_task(robot, START, [moving, Target(STOP), Target(GOAL)], COST)
    assert len(free.segments) == 3
    assert free.segments[0].qde == pytest.approx(VELOCITY, rel=1e-15)
    assert free.segments[1].qd0 == pytest.approx(VELOCITY, rel=1e-15)
    earliest = free.target_times[1] + 0.3
    latest = free.target_times[2] + 0.6
    task = [
        moving,
        Target(STOP, window=(earliest, earliest + 0.5)),
        Target(GOAL, window=(0, latest)),
    ]
    result = nearopt.plan_task(robot, START, task, COST)
    times = result.target_times
    assert times[1] == pytest.approx(earliest, rel=1e-9)
    assert times[2] <= latest * (1.0 + 1e-9)
    for t in (times[0] - 1e-9, times[0], times[0] + 1e-9):
        qd = result.trajectory.states(np.array([t]))[1][0]
        assert np.max(np.abs(qd - VELOCITY)) <= 1e-6 * np.max(np.abs(VELOCITY))
    assert result.J > free.J  # waiting costs: the free task is the optimum without the window
    for segment in result.segments:
        assert segment.J <= segment.initial.J * (1.0 + 1e-9)
    report = nearopt.verify_plan(result)
    assert report.passed, str(report)
    names = {c.name for c in report.checks}
    assert {"velocities at targets", "arrival windows"} <= names


def test_the_verifier_sees_a_wrong_velocity_and_a_missed_window() -> None:
    robot = load("two_link")
    a = nearopt.plan(robot, [0.7, -1.5], [-1.5, 0.0], max_iterations=0)
    t = 0.5 * a.duration
    q, qd = (x[0] for x in a.trajectory.states(np.array([t]))[:2])
    right = nearopt.verify(
        a.trajectory, robot, simulate=False, waypoints=[Waypoint(t, q, qd=qd, window=(0.0, t))]
    )
    assert right.passed, str(right)
    wrong = nearopt.verify(
        a.trajectory,
        robot,
        simulate=False,
        waypoints=[Waypoint(t, q, qd=1.01 * qd, window=(t + 0.01, t + 1.0))],
    )
    assert {c.name for c in wrong.failures()} == {"velocities at targets", "arrival windows"}


def test_a_task_file_carries_velocities_and_windows_to_the_json(tmp_path: Path) -> None:
    """The task file's velocity (in its units per second) and window reach the plan and the
    JSON; the CLI verifies what it wrote."""
    task = tmp_path / "task.toml"
    deg = np.rad2deg
    task.write_text(
        f'start = {deg(START).tolist()}\nunits = "deg"\n'
        f'[[target]]\nname = "pass"\nq = {deg(PASS).tolist()}\nstop = false\n'
        f"velocity = {deg(VELOCITY).tolist()}\n"
        f'[[target]]\nname = "end"\nq = {deg(GOAL).tolist()}\nwindow = [1.5, inf]\n'
    )
    read = Task.from_file(task)
    np.testing.assert_allclose(read.targets[0].velocity, VELOCITY, rtol=1e-12)
    assert read.targets[1].window == (1.5, np.inf)
    out = tmp_path / "task.json"
    run = run_cli(
        "plan", "--robot", "ur5", "--task", str(task), "--beta", "0.001", "--max-iterations",
        "3", "--quiet", "--verify", "--json", str(out),
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    doc = json.loads(out.read_text())
    first, last = doc["targets"]
    assert first["velocity"] == pytest.approx(list(VELOCITY), rel=1e-12)
    assert first["window"] is None and last["window"] == [1.5, None]
    assert last["t"] == pytest.approx(1.5, rel=1e-9)
    assert [s["targets"] for s in doc["segments"]] == [["pass"], ["end"]]


@pytest.mark.parametrize(
    ("targets", "message"),
    [
        ([Target(PASS, velocity=VELOCITY), Target(GOAL)], "is a stop with a velocity"),
        ([Target(PASS, stop=False, window=(0.0, 1.0)), Target(GOAL)], "a window needs"),
        (
            [Target(STOP, stop=False), Target(PASS, stop=False, velocity=VELOCITY), Target(GOAL)],
            "in a segment that starts or ends moving",
        ),
        ([Target(PASS, window=(1.0, 0.5)), Target(GOAL)], "is not a time window"),
    ],
)
def test_bad_velocities_and_windows_are_refused(targets: list[Target], message: str) -> None:
    with pytest.raises(nearopt.ConfigurationError, match=message):
        nearopt.plan_task(load("ur5"), START, targets, COST)


def test_a_velocity_beyond_a_limit_and_a_window_too_soon_name_the_target() -> None:
    robot = load("ur5")
    fast = VELOCITY.copy()
    fast[2] = 10.0
    with pytest.raises(TaskError, match="'elbow_joint' is 10 rad/s, beyond its speed limit") as e:
        nearopt.plan_task(robot, START, [Target(PASS, stop=False, velocity=fast), Target(GOAL)])
    assert "'target 1'" in str(e.value)
    with pytest.raises(nearopt.InfeasiblePathError, match="window .0, 0.05. s of 'soon'"):
        nearopt.plan_task(robot, START, [Target(GOAL, window=(0.0, 0.05), name="soon")], COST)


def test_a_stop_long_after_the_start_verifies_at_rest() -> None:
    """A window 1000 s after the start: the arm brakes into the stop at ~27 rad/s², so θ̇ a
    nanosecond before it (1e-12 of t_e, what verify read as "just before") is 3e-8 rad/s;
    verify reads it a few ulps before and the plan passes."""
    robot = load("ur5")
    targets = [Target(PASS, window=(1000.0, np.inf)), Target(STOP)]
    result = nearopt.plan_task(robot, START, targets, COST)
    assert result.target_times[0] == pytest.approx(1000.0, rel=1e-9)
    braking = result.trajectory.states(np.array([result.target_times[0] - 1e-9]))[2][0]
    assert np.max(np.abs(braking)) > 1.0  # the case: still braking hard just before the stop
    report = nearopt.verify_plan(result)
    assert report.passed, str(report)


def test_a_velocity_through_a_position_limit_is_refused_up_front() -> None:
    robot = load("ur5")
    on = PASS.copy()
    on[1] = robot.limits.position_upper[1]
    v = np.zeros(robot.n)
    v[1] = -0.5  # coming from beyond the limit, or leaving through it: either way
    with pytest.raises(TaskError, match="on its position limits") as caught:
        nearopt.plan_task(robot, START, [Target(on, stop=False, velocity=v), Target(GOAL)])
    assert "'target 1'" in str(caught.value) and robot.joint_names[1] in str(caught.value)


def test_a_target_passed_at_a_velocity_in_a_cell_is_refused_before_any_segment() -> None:
    """Moving segment ends are not planned with obstacles yet: said before anything is planned,
    naming the target (the first segment was planned in full, then the second refused)."""
    from nearopt.collision import Box, Obstacle, Scene

    far = Scene((Obstacle("box", Box((0.1, 0.1, 0.1)), (5.0, 5.0, 5.0)),))
    targets = [Target(STOP), Target(PASS, stop=False, velocity=VELOCITY, name="handover"),
               Target(GOAL)]  # fmt: skip
    heard = []
    with pytest.raises(nearopt.ConfigurationError, match="target 'handover' is passed at a veloc"):
        nearopt.plan_task(
            load("ur5"), START, targets, COST, nearopt.PlanSettings(scene=far),
            callback=lambda k, entry: heard.append(k),
        )  # fmt: skip
    assert heard == []
