"""ROS 2 outputs (nearopt.ros): the bag read back by ``rosbags`` (independent of the writer,
mcap-ros2-support), the JointTrajectory interpolated as joint_trajectory_controller does (a
quintic through position, velocity and acceleration at both ends, solved here from its six
conditions) against the planned motion at 10 kHz, and the goal YAML through a YAML parser."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import load

import nearopt
from nearopt.export import json_text
from nearopt.ros import goal_yaml, joint_trajectory, write_ros_bag

rosbags = pytest.importorskip("rosbags")
from rosbags.highlevel import AnyReader  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402

START = 1_767_225_600_000_000_000  # 2026-01-01, ns since the epoch


@pytest.fixture(scope="module")
def plans() -> dict[str, nearopt.Plan]:
    """A stage-1 motion (θ̈ jumps at its knots), a jerk-limited one and a two-part task."""
    ur5 = load("ur5")
    q0, qe = np.array([0, -1.5, 1.5, 0, 0, 0.0]), np.array([1.0, -1.0, 1.0, 0.5, 0.5, 0.5])
    plans = {"stage 1": nearopt.plan(ur5, q0, qe, nearopt.TimeCost(), max_iterations=2)}
    smooth = load("panda").with_limits(jerk=50.0, acceleration=10.0)
    start = np.array([0.0, -0.5, 0.0, -2.0, 0.0, 1.5, 0.5])
    plans["jerk"] = nearopt.plan(
        smooth, start, start + 0.4, nearopt.TimeCost(), max_iterations=0, grid=60
    )
    plans["task"] = nearopt.plan_task(
        load("two_link"),
        np.zeros(2),
        [np.array([1.0, 0.5]), np.array([0.2, -0.4])],
        nearopt.TimeCost(),
        nearopt.PlanSettings(max_iterations=1),
    )
    return plans


NAMES = ["stage 1", "jerk", "task"]


def _quintic(t0, t1, ends, t):  # noqa: ANN001
    """The quintic with the given θ, θ̇, θ̈ at t0 and t1 (each (n,)), at times t: (M, n)."""
    shift = t0  # solve in τ − t0 for conditioning
    rows = []
    for tau in (0.0, t1 - shift):
        rows += [
            [tau**k for k in range(6)],
            [k * tau ** (k - 1) if k else 0.0 for k in range(6)],
            [k * (k - 1) * tau ** (k - 2) if k > 1 else 0.0 for k in range(6)],
        ]
    coef = np.linalg.solve(np.array(rows), np.array(ends))  # (6, n)
    x = (t - shift)[:, None] ** np.arange(6)[None, :]
    return x @ coef


@pytest.mark.parametrize("name", NAMES)
def test_the_trajectory_at_its_knots_replays_the_motion_as_the_controller_interpolates_it(
    plans: dict[str, nearopt.Plan], name: str
) -> None:
    result = plans[name]
    trajectory = joint_trajectory(result)
    motion = result.trajectory
    t = trajectory.seconds
    assert t[0] == 0.0 and abs(t[-1] - motion.duration) <= 1e-9
    assert np.all(np.diff(trajectory.time_from_start) > 0)
    assert trajectory.joint_names == tuple(result.robot.joint_names)
    q, qd, qdd = motion.states(t)
    np.testing.assert_allclose(trajectory.positions, q, atol=1e-6)  # (t rounded to 1 ns)
    # the effort: the point's own state's inverse dynamics (the feed-forward torque)
    feed_forward = result.robot.inverse_dynamics_batch(
        trajectory.positions, trajectory.velocities, trajectory.accelerations
    )
    np.testing.assert_allclose(trajectory.effort, feed_forward, rtol=1e-12, atol=1e-9)
    clock = np.arange(0.0, motion.duration, 1e-4)
    worst = 0.0
    for k in range(t.size - 1):
        inside = clock[(clock >= t[k]) & (clock < t[k + 1])]
        if inside.size == 0:
            continue
        ends = [
            trajectory.positions[k],
            trajectory.velocities[k],
            trajectory.accelerations[k],
            trajectory.positions[k + 1],
            trajectory.velocities[k + 1],
            trajectory.accelerations[k + 1],
        ]
        guess = _quintic(t[k], t[k + 1], ends, inside)
        worst = max(worst, float(np.max(np.abs(guess - motion(inside)))))
    assert worst <= 1e-6 + 1e-6  # the tolerance, and the ns rounding of the points' times
    assert t.size < motion.duration * 1e4 / 5  # sparse: far fewer points than 10 kHz samples


def test_the_bag_reads_back_with_rosbags(plans: dict[str, nearopt.Plan], tmp_path: Path) -> None:
    result = plans["stage 1"]
    folder = tmp_path / "plan"
    written = write_ros_bag(result, folder, rate=2000.0, start_ns=START)
    record = json.loads(json_text(result, 2000.0))
    t = np.array(record["t"])
    store = get_typestore(Stores.ROS2_HUMBLE)
    with AnyReader([folder], default_typestore=store) as reader:
        topics = {c.topic: (c.msgtype, c.msgcount) for c in reader.connections}
        assert topics == {
            "/joint_trajectory": ("trajectory_msgs/msg/JointTrajectory", 1),
            "/joint_states": ("sensor_msgs/msg/JointState", t.size),
            "/tf": ("tf2_msgs/msg/TFMessage", t.size),
        }
        assert written.messages == {topic: count for topic, (_, count) in topics.items()}
        states, tf, plans = [], [], []
        for connection, stamp, raw in reader.messages():
            msg = reader.deserialize(raw, connection.msgtype)
            {"/joint_states": states, "/tf": tf, "/joint_trajectory": plans}[
                connection.topic
            ].append((stamp, msg))
    names = list(result.robot.joint_names)
    stamps = np.array([stamp for stamp, _ in states])
    np.testing.assert_array_equal(stamps, START + np.rint(t * 1e9).astype(np.int64))
    for stamp, msg in states:
        assert msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec == stamp
        assert list(msg.name) == names
    position = np.array([msg.position for _, msg in states])
    np.testing.assert_allclose(position, np.array(record["q"]), rtol=0, atol=1e-12)
    np.testing.assert_allclose(
        np.array([msg.velocity for _, msg in states]), np.array(record["qd"]), atol=1e-12
    )
    np.testing.assert_allclose(
        np.array([msg.effort for _, msg in states]), np.array(record["tau"]), atol=1e-9
    )
    # the tool frame in the root link's frame, as Pinocchio places it
    k = len(tf) // 2
    transform = tf[k][1].transforms[0]
    assert transform.child_frame_id == result.robot.tip
    pose = result.robot.frame_placement(np.array(record["q"][k]))
    moved = transform.transform.translation
    np.testing.assert_allclose([moved.x, moved.y, moved.z], pose.translation, atol=1e-12)
    r = transform.transform.rotation
    x, y, z, w = r.x, r.y, r.z, r.w
    rotation = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    np.testing.assert_allclose(rotation, pose.rotation, atol=1e-12)
    # the trajectory message: the one joint_trajectory gives, at the start
    ((stamp, plan),) = plans
    assert stamp == START and list(plan.joint_names) == names
    mine = joint_trajectory(result)
    assert len(plan.points) == mine.time_from_start.size
    last = plan.points[-1].time_from_start
    assert last.sec * 1_000_000_000 + last.nanosec == mine.time_from_start[-1]
    np.testing.assert_array_equal(np.array([p.positions for p in plan.points]), mine.positions)


def test_the_goal_yaml_round_trips(plans: dict[str, nearopt.Plan]) -> None:
    trajectory = joint_trajectory(plans["task"])
    goal = yaml.safe_load(goal_yaml(trajectory))
    message = goal["trajectory"]
    assert message["joint_names"] == list(trajectory.joint_names)
    points = message["points"]
    assert len(points) == trajectory.time_from_start.size
    for key in ("positions", "velocities", "accelerations", "effort"):
        np.testing.assert_array_equal(np.array([p[key] for p in points]), getattr(trajectory, key))
    ns = [p["time_from_start"]["sec"] * 10**9 + p["time_from_start"]["nanosec"] for p in points]
    np.testing.assert_array_equal(ns, trajectory.time_from_start)
    assert all(0 <= p["time_from_start"]["nanosec"] < 10**9 for p in points)


def test_at_a_rate_the_points_are_the_records_samples(plans: dict[str, nearopt.Plan]) -> None:
    result = plans["jerk"]
    trajectory = joint_trajectory(result, rate=250.0)
    record = json.loads(json_text(result, 250.0))
    np.testing.assert_allclose(trajectory.seconds, record["t"], atol=1e-9)
    np.testing.assert_array_equal(trajectory.positions, np.array(record["q"]))


def test_an_existing_bag_is_replaced_and_anything_else_refused(
    plans: dict[str, nearopt.Plan], tmp_path: Path
) -> None:
    result = plans["task"]
    folder = tmp_path / "bag"
    write_ros_bag(result, folder, rate=100.0, start_ns=START)
    write_ros_bag(result, folder, rate=50.0, start_ns=START)
    assert sorted(p.name for p in folder.iterdir()) == ["bag_0.mcap", "metadata.yaml"]
    meta = yaml.safe_load((folder / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["topics_with_message_count"][1]["message_count"] == int(
        np.floor(result.duration * 50.0 + 1e-9)
    ) + 1 + (1 if result.duration * 50.0 % 1 > 1e-9 else 0)
    other = tmp_path / "notes"
    other.mkdir()
    (other / "keep.txt").write_text("mine")
    with pytest.raises(nearopt.ConfigurationError, match="is not a rosbag2 folder"):
        write_ros_bag(result, other)
    assert (other / "keep.txt").read_text() == "mine"
    (other / "metadata.yaml").write_text("name: mine")  # a metadata.yaml alone makes no bag
    (other / "images").mkdir()
    with pytest.raises(nearopt.ConfigurationError, match="holds 'images' and 1 more besides a"):
        write_ros_bag(result, other)
    assert sorted(p.name for p in other.iterdir()) == ["images", "keep.txt", "metadata.yaml"]
    with pytest.raises(nearopt.ConfigurationError, match="rate"):
        write_ros_bag(result, tmp_path / "x", rate=0.0)
    with pytest.raises(nearopt.ConfigurationError, match="tolerance"):
        joint_trajectory(result, tolerance=-1.0)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bag", "notes"]


def test_the_command_line_writes_the_goal_and_the_bag(tmp_path: Path) -> None:
    """``nearopt plan … --ros-yaml --ros-bag``: both written, the bag's joint states the JSON's
    samples; a place for the bag that holds something else is refused before planning, and
    nothing is written."""
    from test_cli import run

    plan = ["plan", "--robot", "two_link", "--q0", "0", "0", "--qe", "1", "0.5", "--quiet"]
    files = ["--json", str(tmp_path / "p.json"), "--ros-yaml", str(tmp_path / "goal.yaml")]
    done = run(*plan, *files, "--ros-bag", str(tmp_path / "bag"), "--rate", "2000")
    assert done.returncode == 0, done.stderr
    assert f"wrote {tmp_path / 'bag'} (rosbag2, MCAP" in done.stdout
    goal = yaml.safe_load((tmp_path / "goal.yaml").read_text())
    assert goal["trajectory"]["joint_names"] == ["joint1", "joint2"]
    record = json.loads((tmp_path / "p.json").read_text())
    with AnyReader([tmp_path / "bag"], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as r:
        states = [
            r.deserialize(raw, c.msgtype).position
            for c, _, raw in r.messages()
            if c.topic == "/joint_states"
        ]
    np.testing.assert_allclose(np.array(states), np.array(record["q"]), rtol=0, atol=1e-12)
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "notes.txt").write_text("mine")
    again = run(
        *plan, "--ros-yaml", str(tmp_path / "g2.yaml"), "--ros-bag", str(tmp_path / "other")
    )
    assert again.returncode == 2
    assert again.stderr.strip().endswith(
        "is not a rosbag2 folder: it would be replaced; give another"
    )
    assert not (tmp_path / "g2.yaml").exists()
    assert [p.name for p in (tmp_path / "other").iterdir()] == ["notes.txt"]
    for inside in (["--json", "bag/p.json"], ["--plots", "bag"], ["--csv", "bag"]):
        again = run(
            *plan, "--ros-bag", str(tmp_path / "bag"), *inside[:1], str(tmp_path / inside[1])
        )
        assert again.returncode == 2
        assert "which the bag replaces whole: give a place outside it" in again.stderr
    assert sorted(p.name for p in (tmp_path / "bag").iterdir()) == ["bag_0.mcap", "metadata.yaml"]
    here = subprocess.run(
        [sys.executable, "-m", "nearopt.cli", *plan, "--ros-bag", "."],
        capture_output=True, text=True, timeout=600, cwd=tmp_path / "other",
    )  # fmt: skip
    assert here.returncode == 2 and "is the folder this command runs in" in here.stderr
    assert [p.name for p in (tmp_path / "other").iterdir()] == ["notes.txt"]


def test_joint_vectors_in_a_controllers_order() -> None:
    """``joint_order`` (``--joint-order``): q0, qe, via-points and per-joint limits and weights
    given in another order reach the planner in the URDF's; the same plan as the request in
    the URDF's order; a bad order names what is unknown, repeated or missing."""
    from nearopt.api import PlanRequest, prepare

    names = list(nearopt.Robot.from_name("ur5").joint_names)
    order = names[::-1]
    q0, qe = [0.0, -1.5, 1.5, 0.0, 0.0, 0.0], [1.0, -1.0, 1.0, 0.5, 0.5, 0.3]
    via = [0.5, -1.2, 1.2, 0.2, 0.2, 0.1]
    speed = [3.0, 3.1, 3.2, 3.3, 3.4, 3.5]
    urdf = PlanRequest(
        robot="ur5", q0=tuple(q0), qe=tuple(qe), via=(tuple(via),), velocity_limit=tuple(speed),
        weights=tuple(range(1, 7)), stage1_only=True,
    )  # fmt: skip
    theirs = PlanRequest.from_mapping(
        {
            "robot": "ur5",
            "joint_order": order,
            "q0": q0[::-1],
            "qe": qe[::-1],
            "via": [via[::-1]],
            "velocity_limit": speed[::-1],
            "weights": list(range(1, 7))[::-1],
            "stage1_only": True,
        }
    )
    a, b = prepare(urdf), prepare(theirs)
    np.testing.assert_array_equal(a.q0, b.q0)
    np.testing.assert_array_equal(a.qe, b.qe)
    np.testing.assert_array_equal(a.via[0], b.via[0])
    np.testing.assert_array_equal(a.robot.limits.velocity, b.robot.limits.velocity)
    np.testing.assert_array_equal(b.robot.limits.velocity, speed)
    np.testing.assert_array_equal(a.cost.torque_weights(6), b.cost.torque_weights(6))
    np.testing.assert_array_equal(b.cost.torque_weights(6), np.arange(1.0, 7.0))
    assert b.request.joint_order == ()  # prepared: in the URDF's order
    for bad, said in (
        ([*names[:-1], "nope"], "unknown: nope; missing: wrist_3_joint"),
        ([*names[:-1], names[0]], f"twice: {names[0]}; missing: wrist_3_joint"),
        (names[:-1], "missing: wrist_3_joint"),
    ):
        with pytest.raises(nearopt.ConfigurationError, match=said):
            prepare(PlanRequest(robot="ur5", q0=tuple(q0), qe=tuple(qe), joint_order=tuple(bad)))


def test_a_batch_writes_a_bag_per_motion_planned(tmp_path: Path) -> None:
    """``nearopt batch … --ros-bag``: ``DIR/bags/<id>/`` for each planned motion, its
    joint states the JSON's samples; none for a motion that failed."""
    from test_batch import batch, write_motions

    motions = [
        {"id": "line", "robot": "two_link", "q0": [0, 0], "qe": [1, 0.5], "stage1_only": True},
        {"id": "away", "robot": "two_link", "q0": [0, 0], "qe": [99, 0], "stage1_only": True},
    ]
    tasks = write_motions(tmp_path, motions)
    done = batch(str(tasks), "--out", str(tmp_path / "out"), "--workers", "1", "--ros-bag")
    assert done.returncode == 1, done.stderr  # one failed
    out = tmp_path / "out"
    assert (out / "bags" / "line" / "metadata.yaml").is_file() and not (
        out / "bags" / "away"
    ).exists()
    record = json.loads((out / "line.json").read_text())
    with AnyReader(
        [out / "bags" / "line"], default_typestore=get_typestore(Stores.ROS2_HUMBLE)
    ) as r:
        states = [
            r.deserialize(raw, c.msgtype).position
            for c, _, raw in r.messages()
            if c.topic == "/joint_states"
        ]
    np.testing.assert_allclose(np.array(states), np.array(record["q"]), rtol=0, atol=1e-12)
    assert sorted(p.name for p in (out / "bags" / "line").iterdir()) == [
        "line_0.mcap",
        "metadata.yaml",
    ]
