"""One request model: the command line, a batch's motions and Python make the same PlanRequest;
numbers in any float syntax reach the planner as they were written."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from conftest import load
from console import run_cli

import nearopt
from nearopt.api import _KINDS, PlanRequest, run
from nearopt.cli import parse_plan, plan_request


def test_the_options_table_names_every_field() -> None:
    assert set(_KINDS) == {f.name for f in dataclasses.fields(PlanRequest)}
    parser_fields = vars(
        parse_plan(["plan", "--robot", "two_link", "--q0", "0", "0", "--qe", "1", "1"])
    )
    assert set(_KINDS) <= set(parser_fields)  # every field is an option of `nearopt plan`


def test_the_command_line_and_a_mapping_make_the_same_request() -> None:
    argv = [
        "plan",
        "--robot",
        "ur5",
        "--q0",
        "-1e-05",
        "-1.57",
        "-.5",
        "0",
        "1e-3",
        "-inf",
        "--goal-pose",
        "0.307",
        "-2.69e-16",
        "0.4",
        "--via",
        "-1e-05",
        "0",
        "0",
        "0",
        "0",
        "0",
        "--via",
        "1",
        "2",
        "3",
        "4",
        "5",
        "6",
        "--beta",
        "1e-3",
        "--grid",
        "80",
        "--effort-limit",
        "-1e12",
        "--no-self-collision",
        "--time-limit",
        "inf",
        "--quiet",
        "--verify",
    ]
    from_cli = plan_request(parse_plan(argv))
    mapping = {
        "robot": "ur5",
        "q0": [-1e-05, -1.57, -0.5, 0, 1e-3, "-inf"],
        "goal_pose": np.array([0.307, -2.69e-16, 0.4]),
        "via": [[-1e-05, 0, 0, 0, 0, 0], (1, 2, 3, 4, 5, 6)],
        "beta": 1e-3,
        "grid": 80.0,
        "effort_limit": -1e12,
        "self_collision": False,
        "time_limit": float("inf"),
        "quiet": True,
        "verify": True,
    }
    assert PlanRequest.from_mapping(mapping) == from_cli
    assert from_cli.q0[0] == -1e-05 and from_cli.goal_pose[1] == -2.69e-16
    assert from_cli.q0[-1] == -np.inf and from_cli.self_collision is False


@pytest.mark.parametrize(
    "options, message",
    [
        ({"grid": 1.5}, "option 'grid' takes an integer"),
        ({"deg": 1}, "option 'deg' takes true or false"),
        ({"q0": []}, "takes at least one number"),
        ({"q0": ["a"]}, "option 'q0' takes a number or a list of numbers"),
        ({"robot": "two_link", "urdf": "x.urdf"}, "give the arm as robot"),
        (
            {"robot": "two_link", "q0": [0, 0], "qe": [1, 1], "beta": 1.0, "time_optimal": True},
            "give the cost as beta, weights or time_optimal, once",
        ),
        (
            {"robot": "two_link", "q0": [0, 0], "qe": [1, 1], "method": "newton"},
            "method must be one of",
        ),
    ],
)
def test_a_bad_mapping_says_which_option(options: dict, message: str) -> None:
    with pytest.raises(nearopt.ConfigurationError, match=message):
        PlanRequest.from_mapping(options).check()


def test_the_fingerprint_names_the_motion_and_the_files_it_reads(tmp_path: Path) -> None:
    """The same motion spelled two ways has one fingerprint; another value, another rate or
    other contents of a file it names change it; defaults are left out."""
    task = tmp_path / "t.toml"
    task.write_text("[[target]]\nq = [0.2, -0.3]\n")
    a = PlanRequest.from_mapping({"robot": "two_link", "q0": [0, 0], "task": str(task)})
    b = PlanRequest(robot="two_link", q0=(0.0, 0.0), task=str(task), grid=200, deg=False)
    assert a.fingerprint() == b.fingerprint()
    fingerprint = json.loads(a.fingerprint())
    assert set(fingerprint) == {"robot", "q0", "task", "file_sha256"}
    assert fingerprint["file_sha256"]["task"] is not None
    assert a.with_rate(500.0).fingerprint() != a.fingerprint()
    assert dataclasses.replace(a, q0=(0.0, 1e-12)).fingerprint() != a.fingerprint()
    task.write_text("[[target]]\nq = [0.2, -0.31]\n")
    assert a.fingerprint() != json.dumps(fingerprint, sort_keys=True)


def test_small_negative_numbers_are_planned_by_a_batch() -> None:
    """What a batch once turned back into argv (``-1e-05`` read as an option) is planned, and
    each motion starts and ends where it was asked to."""
    robot = load("two_link")
    spot = robot.frame_position(np.array([0.4, -1.2]))
    spot[np.abs(spot) < 1e-12] = -1e-17  # a zero written as a tiny negative number
    common = {"robot": "two_link", "grid": 60, "max_iterations": 2}
    motions = [
        {**common, "q0": [-1e-05, -1.57], "qe": [-0.5, -1e-05]},
        {**common, "q0": [-1e-05, -1.57], "qe": [0.5, -0.2], "via": [[-1e-05, -0.8]]},
        {**common, "q0": [-1e-05, -1.57], "goal_pose": spot.tolist()},
    ]
    outcomes = nearopt.plan_many(motions, workers=2)
    for outcome, motion in zip(outcomes, motions, strict=True):
        assert outcome.status == "planned", outcome.error
        trajectory = outcome.result.trajectory
        np.testing.assert_allclose(trajectory(np.array([0.0]), 0)[0], motion["q0"], atol=1e-12)
        end = trajectory(np.array([outcome.te]), 0)[0]
        if "qe" in motion:
            np.testing.assert_allclose(end, motion["qe"], atol=1e-9)
        else:
            assert np.linalg.norm(robot.frame_position(end) - spot) < 1e-6


def test_small_negative_numbers_on_the_command_line(tmp_path: Path) -> None:
    out = tmp_path / "plan.json"
    done = run_cli(
        "plan",
        "--robot",
        "two_link",
        "--q0",
        "-1e-3",
        "0.5",
        "--qe",
        "-.5",
        "-1e-05",
        "--stage1-only",
        "--grid",
        "60",
        "--quiet",
        "--json",
        str(out),
    )
    assert done.returncode == 0, done.stderr
    q = np.array(json.loads(out.read_text())["q"])
    np.testing.assert_allclose(q[0], [-1e-3, 0.5], atol=1e-12)
    np.testing.assert_allclose(q[-1], [-0.5, -1e-05], atol=1e-9)


def test_run_plans_and_verifies_in_this_process() -> None:
    request = PlanRequest(
        robot="two_link",
        q0=(0.7, -1.5),
        qe=(-1.5, 0.0),
        beta=0.03,
        grid=60,
        max_iterations=3,
        rate=500.0,
    )
    outcome = run(request)
    assert outcome.report.passed and outcome.prepared.request is request
    assert isinstance(outcome.result, nearopt.PlanResult)
    np.testing.assert_array_equal(outcome.result.cost.torque_weights(2), [0.03, 0.03])


def test_single_plans_and_tasks_are_plans(tmp_path: Path) -> None:
    """One Plan protocol: what export, figures and the batch read of either kind."""
    task = tmp_path / "t.toml"
    task.write_text("[[target]]\nq = [0.2, -0.3]\nstop = false\n[[target]]\nq = [0.5, 0.4]\n")
    common = {"robot": "two_link", "q0": (0.7, -1.5), "grid": 60, "max_iterations": 2}
    single = run(PlanRequest(**common, qe=(-1.5, 0.0))).result
    chained = run(PlanRequest(**common, task=str(task))).result
    for result in (single, chained):
        assert isinstance(result, nearopt.Plan)
        assert result.iterations == sum(len(p.history) - 1 for p in result.parts)
    assert single.parts == (single,) and chained.parts == chained.segments


PRISMATIC_LIMIT = '<limit effort="50" velocity="1" lower="-0.1" upper="0.3"/>'


def test_degrees_are_a_revolute_joints_and_a_prismatic_joint_stays_in_metres(
    tmp_path: Path,
) -> None:
    """``--deg`` (and a task file's ``units = "deg"``) convert the revolute joints' values only:
    a prismatic joint's goal of 0.2 m was planned to 0.2·π/180 m, and 0.5 m beyond its 0.3 m
    limit was taken. Its limit error says m."""
    from urdfs import LIMIT, write_urdf

    from nearopt.api import prepare
    from nearopt.planning import Task

    urdf = str(
        write_urdf(tmp_path, types=("revolute", "prismatic"), limits=(LIMIT, PRISMATIC_LIMIT))
    )
    given = PlanRequest(urdf=urdf, q0=(0.0, 0.0), qe=(30.0, 0.2), via=((10.0, 0.1),), deg=True)
    prepared = prepare(given)
    np.testing.assert_allclose(prepared.qe, [np.pi / 6, 0.2], rtol=0, atol=1e-15)
    np.testing.assert_allclose(prepared.via[0], [np.pi / 18, 0.1], rtol=0, atol=1e-15)
    with pytest.raises(nearopt.ConfigurationError, match=r"qe\[1\] = 0.5 m is outside .* m of"):
        prepare(dataclasses.replace(given, qe=(30.0, 0.5)))
    task = tmp_path / "t.toml"
    task.write_text(
        'units = "deg"\nstart = [0, 0.05]\n[[target]]\nq = [30, 0.2]\nstop = false\n'
        "velocity = [10, 0.1]\n[[target]]\nq = [-20, 0.1]\n"
    )
    robot = nearopt.Robot.from_urdf(urdf)
    read = Task.from_file(task).for_robot(robot)
    np.testing.assert_allclose(read.start, [0.0, 0.05], rtol=0, atol=1e-15)
    np.testing.assert_allclose(read.targets[0].goal, [np.pi / 6, 0.2], rtol=0, atol=1e-15)
    np.testing.assert_allclose(read.targets[0].velocity, [np.pi / 18, 0.1], rtol=0, atol=1e-15)
    from_file = prepare(PlanRequest(urdf=urdf, task=str(task)))
    np.testing.assert_allclose(from_file.q0, [0.0, 0.05], rtol=0, atol=1e-15)
    np.testing.assert_allclose(from_file.task.targets[1].goal, [-np.pi / 9, 0.1], atol=1e-15)


def test_a_named_robots_own_urdf_and_srdf_are_inputs_no_output_may_replace() -> None:
    """``--robot ur5 --json …/ur5_robot.urdf`` wrote the plan over the bundled URDF: the files a
    robot named by its catalogue name is read from are the request's inputs too."""
    from nearopt.api import prepare

    prepared = prepare(PlanRequest(robot="ur5", q0=(0.0,) * 6, qe=(0.3,) * 6))
    files = prepared.input_files()
    assert files["the URDF of ur5"] == prepared.robot.urdf_path
    assert files["the SRDF of ur5"] == prepared.robot.srdf
    assert prepared.robot.urdf_path.name == "ur5_robot.urdf"
