"""Tasks (#12): targets stopped at or passed through, planned as rest-to-rest segments and written
out as one motion; the task file; the pick-and-place example."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from checks import assert_independent_checks
from conftest import load
from console import run_cli

import nearopt
from nearopt import ChainedTrajectory, Target, Task, TaskError, ToolPose, Waypoint
from nearopt.robot.kinematics import pose_error

ROOT = Path(__file__).resolve().parents[1]
UR5_START = np.array([-0.8, -1.2, 1.2, -1.5, -1.57, 0.0])
UR5_PASS = np.array([-0.3, -1.6, 0.8, -1.0, -1.57, 0.5])
UR5_STOP = np.array([0.2, -1.3, 1.0, -1.4, -1.2, 0.3])
UR5_GOAL = np.array([0.8, -1.2, 1.2, -1.5, -1.57, 0.0])


def test_a_chained_trajectory_is_its_parts_one_after_another() -> None:
    robot = load("two_link")
    a = nearopt.plan(robot, [0.7, -1.5], [-1.5, 0.0], max_iterations=0)
    b = nearopt.plan(robot, [-1.5, 0.0], [0.3, 0.2], max_iterations=0)
    chain = ChainedTrajectory([a.trajectory, b.trajectory])
    assert chain.duration == pytest.approx(a.duration + b.duration, rel=1e-14)
    t = np.linspace(0.0, b.duration, 7)
    for order in (0, 1, 2):
        np.testing.assert_allclose(
            chain(a.duration + t[1:], order), b.trajectory(t[1:], order), rtol=1e-12, atol=1e-12
        )
        np.testing.assert_allclose(
            chain(t[:-1] * a.duration / b.duration, order),
            a.trajectory(t[:-1] * a.duration / b.duration, order),
            rtol=1e-12,
            atol=1e-12,
        )
    np.testing.assert_allclose(chain.part_at([0.0, a.duration, chain.duration]), [0, 1, 1])
    assert chain.integrate(lambda q, qd, u: np.ones(len(q))) == pytest.approx(chain.duration)
    report = nearopt.verify(
        chain,
        robot,
        q0=[0.7, -1.5],
        qe=[0.3, 0.2],
        waypoints=[Waypoint(a.duration, [-1.5, 0.0], stop=True)],
    )
    assert report.passed, str(report)
    with pytest.raises(nearopt.ConfigurationError, match="starts where the previous one ends"):
        ChainedTrajectory([b.trajectory, a.trajectory])


def test_a_task_stops_where_it_says_and_passes_where_it_says() -> None:
    """ur5: pass, stop, goal. The stop is at rest from both sides, the pass-through is exact and
    moving, J is the segments' sum, and the whole motion passes the independent checks."""
    robot = load("ur5")
    cost = nearopt.TorqueCost(0.001)
    result = nearopt.plan_task(
        robot,
        UR5_START,
        [Target(UR5_PASS, stop=False, name="pass"), Target(UR5_STOP, name="stop"), UR5_GOAL],
        cost,
        nearopt.PlanSettings(grid=100, max_iterations=8),
    )
    assert [t.name for t in result.targets] == ["pass", "stop", "target 3"]
    assert len(result.segments) == 2 and len(result.segments[0].via) == 1
    t_pass, t_stop, t_end = result.target_times
    assert 0 < t_pass < t_stop < t_end == pytest.approx(result.duration)
    q, qd, _ = result.trajectory.states(np.array([t_pass, t_stop]))
    np.testing.assert_allclose(q, [UR5_PASS, UR5_STOP], atol=1e-10)
    assert np.abs(qd[0]).max() > 0.3  # passes
    before = result.trajectory(np.array([t_stop - 1e-9]), 1)[0]
    assert np.abs(qd[1]).max() < 1e-12 and np.abs(before).max() < 1e-3  # stops
    assert result.J == pytest.approx(sum(s.J for s in result.segments), rel=1e-14)
    assert result.J == pytest.approx(result.trajectory.integrate(cost), rel=1e-6)
    assert_independent_checks(robot, result.trajectory, cost, result.J, UR5_START, UR5_GOAL)
    report = nearopt.verify(result.trajectory, robot, waypoints=result.waypoints, simulate=False)
    assert {"via-point positions", "rest at stops"} <= {c.name for c in report.checks}
    assert report.passed, str(report)
    # a stop is planned like a goal: the second segment alone costs what the task's does
    alone = nearopt.plan(robot, UR5_STOP, UR5_GOAL, cost, grid=100, max_iterations=8)
    assert result.segments[1].J == pytest.approx(alone.J, rel=1e-9)


def test_the_verifier_sees_a_missed_target_and_a_moving_stop() -> None:
    robot = load("two_link")
    a = nearopt.plan(robot, [0.7, -1.5], [-1.5, 0.0], max_iterations=0)
    late = nearopt.verify(
        a.trajectory,
        robot,
        simulate=False,
        waypoints=[Waypoint(0.5 * a.duration, [-1.5, 0.0], stop=True)],
    )
    assert {c.name for c in late.failures()} == {"via-point positions", "rest at stops"}


def test_a_task_file_is_read_and_bad_ones_name_the_target_and_field(tmp_path: Path) -> None:
    good = tmp_path / "task.toml"
    good.write_text(
        'start = [0, -45, 0, -135, 0, 90, 45]\nunits = "deg"\nframe = "panda_hand"\n'
        '[[target]]\nname = "above"\npose = [0.5, 0.1, 0.4]\nstop = false\n'
        "[[target]]\nq = [10, -30, 0, -120, 0, 90, 45]\n"
    )
    task = Task.from_file(good)
    np.testing.assert_allclose(task.start, np.deg2rad([0, -45, 0, -135, 0, 90, 45]))
    above, second = task.targets
    assert above == Target(ToolPose((0.5, 0.1, 0.4), None, "panda_hand"), False, "above")
    np.testing.assert_allclose(second.goal, np.deg2rad([10, -30, 0, -120, 0, 90, 45]))
    assert second.stop and second.name == "target 2"
    cases = {
        "speed = 1\n[[target]]\nq = [0]\n": ("speed", None),
        '[[target]]\nname = "a"\nq = [0]\npose = [1, 2, 3]\n': ("q", "a"),
        '[[target]]\nname = "a"\n': ("q", "a"),
        '[[target]]\nname = "b"\nq = [0]\nstop = "no"\n': ("stop", "b"),
        '[[target]]\nname = "c"\npose = [1, 2, 3, 4]\n': ("pose", "c"),
        '[[target]]\nname = "d"\nq = [0, nan]\n': ("q", "d"),
        '[[target]]\nname = "e"\nq = [0]\nframe = "tool"\n': ("frame", "e"),
        '[[target]]\nname = "f"\nq = [0]\ncolour = 1\n': ("colour", "f"),
        'units = "grad"\n[[target]]\nq = [0]\n': ("units", None),
        "start = 3\n[[target]]\nq = [0]\n": ("start", None),
        'frame = "x"\n': ("target", None),
    }
    for text, (field, target) in cases.items():
        bad = tmp_path / "bad.toml"
        bad.write_text(text)
        with pytest.raises(TaskError) as caught:
            Task.from_file(bad)
        assert (caught.value.field, caught.value.target) == (field, target), text
        assert str(bad) in str(caught.value)
    for text in ("[[target]\n", "\xff\xfe"):
        (tmp_path / "broken.toml").write_bytes(text.encode("latin-1"))
        with pytest.raises(TaskError, match="not valid TOML"):
            Task.from_file(tmp_path / "broken.toml")
    with pytest.raises(TaskError, match="cannot read"):
        Task.from_file(tmp_path / "missing.toml")


def test_bad_targets_are_configuration_errors() -> None:
    robot = load("ur5")
    for targets in (
        [],
        UR5_GOAL.tolist(),
        "goal",
        [Target(UR5_GOAL, stop="yes")],
        [Target(UR5_GOAL, name="")],
    ):
        with pytest.raises(nearopt.ConfigurationError):
            nearopt.plan_task(robot, UR5_START, targets)
    with pytest.raises(TaskError, match=r"target 'target 2': q must have 6 values"):
        nearopt.plan_task(
            robot, UR5_START, [UR5_GOAL, np.zeros(5)], None, nearopt.PlanSettings(max_iterations=0)
        )


def test_the_cli_plans_a_task_file_and_marks_the_segments(tmp_path: Path) -> None:
    task = tmp_path / "task.toml"
    rows = "\n".join(
        f'[[target]]\nname = "{name}"\nq = {q.tolist()}\nstop = {str(stop).lower()}\n'
        for name, q, stop in (
            ("pass", UR5_PASS, False),
            ("stop", UR5_STOP, True),
            ("end", UR5_GOAL, True),
        )
    )
    task.write_text(f"start = {UR5_START.tolist()}\n{rows}")
    out, table = tmp_path / "task.json", tmp_path / "task.csv"
    run = run_cli(
        "plan",
        "--robot",
        "ur5",
        "--task",
        str(task),
        "--beta",
        "0.001",
        "--max-iterations",
        "3",
        "--grid",
        "100",
        "--quiet",
        "--json",
        str(out),
        "--csv",
        str(table),
    )
    assert run.returncode == 0, run.stderr
    assert "2 segments" in run.stdout and "segment 2 (to end)" in run.stdout
    doc = json.loads(out.read_text())
    assert [t["name"] for t in doc["targets"]] == ["pass", "stop", "end"]
    assert [t["stop"] for t in doc["targets"]] == [False, True, True]
    first, second = doc["segments"]
    assert first["targets"] == ["pass", "stop"] and second["targets"] == ["end"]
    assert first["t_end"] == second["t_start"] == doc["targets"][1]["t"]
    assert doc["J"] == pytest.approx(first["J"] + second["J"], rel=1e-12)
    with table.open() as stream:
        samples = list(csv.DictReader(stream))
    t = np.array([float(r["t"]) for r in samples])
    segment = np.array([int(r["segment"]) for r in samples])
    np.testing.assert_array_equal(segment, np.where(t < first["t_end"], 1, 2))
    # the samples beside the stop: still but for what their acceleration makes of the time to it
    names = load("ur5").joint_names
    for k in np.argsort(np.abs(t - first["t_end"]))[:2]:
        qd = np.array([float(samples[k][f"qd_{j}"]) for j in names])
        qdd = np.array([float(samples[k][f"qdd_{j}"]) for j in names])
        assert np.all(np.abs(qd) <= 1.5 * np.abs(qdd) * abs(t[k] - first["t_end"]) + 1e-9)
    for args, message in (
        (["--qe", *map(str, UR5_GOAL)], "once"),
        (["--via", *map(str, UR5_PASS)], "--via applies"),
    ):
        run = run_cli("plan", "--robot", "ur5", "--task", str(task), *args)
        assert run.returncode == 2 and message in run.stderr and "Traceback" not in run.stderr
    task.write_text(rows)  # no start in the file, none on the command line
    run = run_cli("plan", "--robot", "ur5", "--task", str(task))
    assert run.returncode == 2 and "start configuration" in run.stderr


@pytest.mark.slow
def test_the_pick_and_place_example_runs_and_its_files_hold_the_task(tmp_path: Path) -> None:
    """scripts/02_pick_and_place.py (as CI runs it): the JSON's samples reach every pose
    (independent forward kinematics), at rest where the task stops, moving where it passes."""
    run = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "02_pick_and_place.py"), "--out", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert run.returncode == 0, run.stderr + run.stdout
    assert "verification" in run.stdout and "FAIL" not in run.stdout
    names = {p.name for p in tmp_path.iterdir()}
    assert {
        "pick_and_place.html",
        "pick_and_place.json",
        "pick_and_place.csv",
        "workspace.png",
        "torques.png",
        "speeds.png",
        "history.png",
    } <= names
    doc = json.loads((tmp_path / "pick_and_place.json").read_text())
    robot = load("panda")
    data = robot.model.createData()
    frame = robot.model.getFrameId("panda_hand_tcp")
    for target in doc["targets"]:
        pin.framesForwardKinematics(robot.model, data, np.array(target["q"]))
        x, y, z, qx, qy, qz, qw = target["pose"]
        np.testing.assert_allclose(data.oMf[frame].translation, [x, y, z], atol=1e-6)
        wanted = pin.Quaternion(qw, qx, qy, qz).toRotationMatrix()
        np.testing.assert_allclose(data.oMf[frame].rotation, wanted, atol=1e-6)
        assert (
            max(
                pose_error(
                    robot,
                    np.array(target["q"]),
                    ToolPose((x, y, z), (qx, qy, qz, qw), "panda_hand_tcp"),
                )
            )
            < 1e-6
        )
    t, q = np.array(doc["t"]), np.array(doc["q"])
    pin.framesForwardKinematics(robot.model, data, q[-1])
    np.testing.assert_allclose(
        data.oMf[frame].translation, doc["targets"][-1]["pose"][:3], atol=1e-6
    )
    assert [x["stop"] for x in doc["targets"]] == [False, True, False, True]
    assert len(doc["segments"]) == 2
    qd, qdd = np.abs(np.array(doc["qd"])), np.abs(np.array(doc["qdd"]))
    for target in doc["targets"][:3]:  # the sample beside each target: moving unless it stops
        k = int(np.argmin(np.abs(t - target["t"])))
        if target["stop"]:  # at rest at t_stop: |θ̇(t_k)| ≤ max |θ̈| · |t_k − t_stop|, the
            # max over 10 ms around it: stage 1's knots cluster at a stop, and θ̈ (piecewise
            # constant on them) may peak on a segment shorter than the 1 ms between samples
            reach = qdd[max(k - 10, 0) : k + 11].max(axis=0) * abs(t[k] - target["t"])
            assert np.all(qd[k] <= reach * 1.01 + 1e-9), target["name"]
        else:
            assert qd[k].max() > 0.5, target["name"]


def test_a_first_path_through_a_via_point_at_a_limit_stays_within_the_limits() -> None:
    """panda's joint 4 turns back at a via-point 1 mrad inside its upper limit: the B-spline
    corrected to pass it exactly keeps every control point (so the whole path) within the
    limits, and the plan verifies."""
    robot = load("panda")
    upper = robot.limits.position_upper
    q0 = np.array([0.0, -0.5, 0.0, -1.2, 0.0, 1.5, 0.8])
    via = np.array([0.4, -0.3, 0.2, upper[3] - 1e-3, 0.1, 1.6, 0.6])
    qe = np.array([0.9, -0.4, 0.3, -1.3, 0.2, 1.8, 0.4])
    for iterations in (0, 5):
        result = nearopt.plan(robot, q0, qe, via=[via], grid=100, max_iterations=iterations)
        s = np.linspace(0.0, 1.0, 4001)
        q = result.path(s * result.path.s_end, 0)
        assert np.all(q <= upper + 1e-9) and np.all(q >= robot.limits.position_lower - 1e-9)
        np.testing.assert_allclose(result.trajectory(result.via_times, 0)[0], via, atol=1e-10)
        report = nearopt.verify(
            result.trajectory, robot, q0=q0, qe=qe, waypoints=result.waypoints, simulate=False
        )
        assert report.passed, str(report)


def test_via_points_on_a_path_along_a_limit_give_a_first_path_within_it() -> None:
    """Four points of a panda plan whose joint 6 runs along its lower limit (two of them 7 and
    9 nrad inside it): the first B-spline through them passes them exactly within the limits
    (the correction after the bounded one spread its rounding over the control points at the
    limit too, 1e-9 beyond it, and the request was refused), and the plan verifies."""
    robot = load("panda")
    lower, upper = robot.limits.position_lower, robot.limits.position_upper
    q0 = [
        -0.4693215968173048,
        0.020258183122942697,
        -1.2575643602887234,
        -1.2100936552773918,
        2.184723037869777,
        1.0533391145468882,
        -0.17230456672993721,
    ]
    qe = [
        1.8153967240623792,
        0.1449751464000637,
        -0.36406433355468426,
        -1.1666329448849615,
        -2.174967269689126,
        0.6870949724724299,
        1.7213363863670827,
    ]
    via = np.array([
        [0.2519228166470918, 0.011494781728777704, -1.8822128823522728, -0.7467461260618437,
         1.3188879819273218, 0.2240036574988827, 0.6035909046429224],
        [0.9816434160916723, -0.08954695054612306, -1.3459687802646836, -0.2581523112892924,
         0.44322325953525304, -0.017499991064317204, 1.1626249817028718],
        [1.7113509719210296, -0.07623502085560328, -0.6849039676945665, -0.40311725744487764,
         -0.4324258100709056, -0.017499992830667627, 1.190041353491792],
        [2.42278180026177, -0.07401130150477613, -0.9733327776738243, -1.110557168611919,
         -1.3080913355925015, -0.013090439064309536, 1.1515272024347065],
    ])  # fmt: skip
    assert np.min(via[:, 5] - lower[5]) < 1e-8
    result = nearopt.plan(robot, q0, qe, via=list(via), max_iterations=3)
    c = result.path.control_points
    assert np.all(c >= lower - 1e-12) and np.all(c <= upper + 1e-12)
    np.testing.assert_allclose(result.trajectory(result.via_times, 0), via, rtol=0, atol=1e-12)
    report = nearopt.verify(
        result.trajectory, robot, q0=q0, qe=qe, waypoints=result.waypoints, simulate=False
    )
    assert report.passed, str(report)


def test_every_target_is_checked_before_any_planning(tmp_path: Path) -> None:
    """A bad later target is reported before the first segment is planned, naming the file, the
    target and the field; a stop where the arm already is, likewise."""
    robot = load("panda")
    start = "start = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]\n"
    pick = '[[target]]\nname = "pick"\npose = [0.5, -0.3, 0.12, 1.0, 0.0, 0.0, 0.0]\n'
    cases = {
        pick + '[[target]]\nname = "short"\nq = [0, 0, 0, 0, 0, 0]\n': ("short", "q"),
        pick + '[[target]]\nname = "far"\nq = [0, 0, 0, 0.5, 0, 1, 0]\n': ("far", "q"),
        pick + '[[target]]\nname = "again"\npose = [0.5, -0.3, 0.12, 1.0, 0.0, 0.0, 0.0]\n': (
            "again",
            "pose",
        ),
        '[[target]]\nname = "home"\nq = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]\n': (
            "home",
            "q",
        ),
        '[[target]]\nname = "tool"\nframe = "gripper"\npose = [0.5, 0, 0.3]\n': ("tool", "frame"),
    }
    for text, (target, field) in cases.items():
        path = tmp_path / "task.toml"
        path.write_text(start + text)
        task = Task.from_file(path)
        with pytest.raises(TaskError) as caught:
            nearopt.plan_task(
                robot, None, task, None, nearopt.PlanSettings(time_limit=1e-9)
            )  # would stop at once
        assert (caught.value.target, caught.value.field) == (target, field), str(caught.value)
        assert str(path) in str(caught.value)
    with pytest.raises(nearopt.ConfigurationError, match="time_limit"):
        nearopt.plan_task(robot, None, task, None, nearopt.PlanSettings(time_limit="5"))
    with pytest.raises(nearopt.ConfigurationError, match="settings must be a nearopt.PlanSettings"):
        nearopt.plan_task(robot, None, task, None, {"grid": 60})
    with pytest.raises(nearopt.ConfigurationError, match="has no goal"):
        nearopt.plan_task(robot, np.zeros(7), [Target(None)])
