"""Goals given as tool poses (#12, first part): inverse kinematics within the limits, plans that
end at the pose (checked by forward kinematics on the written samples), and the errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from checks import assert_independent_checks
from conftest import load, random_configuration
from console import run_cli

import nearopt
from nearopt import ToolPose, UnreachablePoseError, inverse_kinematics
from nearopt.robot.kinematics import pose_error


def pose_of(robot: nearopt.Robot, q: np.ndarray, frame: str | None = None) -> ToolPose:
    """The placement of a frame at θ as a ToolPose (Pinocchio directly)."""
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    m = data.oMf[robot.frame_id(frame)]
    quat = pin.Quaternion(m.rotation)
    return ToolPose(m.translation, (quat.x, quat.y, quat.z, quat.w), frame)


@pytest.mark.parametrize("name", ["ur5", "panda", "xarm7", "kinova"])
def test_inverse_kinematics_reaches_poses_within_the_limits(
    name: str, rng: np.random.Generator
) -> None:
    robot = load(name)
    lim = robot.limits
    for _ in range(5):
        pose = pose_of(robot, random_configuration(robot, rng))
        q = inverse_kinematics(robot, pose, seed=random_configuration(robot, rng))
        distance, angle = pose_error(robot, q, pose)
        assert distance < 1e-9 and angle < 1e-9
        assert np.all(q >= lim.position_lower) and np.all(q <= lim.position_upper)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_a_plan_to_a_tool_pose_ends_there(
    name: str, rng: np.random.Generator, tmp_path: Path
) -> None:
    """Through the CLI; the last sample of the JSON is checked by forward kinematics."""
    robot = load(name)
    q0 = random_configuration(robot, rng)
    target = pose_of(robot, random_configuration(robot, rng))
    out = tmp_path / "plan.json"
    run = run_cli(
        "plan",
        "--robot",
        name,
        "--q0",
        *map(str, q0),
        "--goal-pose",
        *map(str, target.position),
        *map(str, target.quaternion),
        "--time-optimal",
        "--grid",
        "100",
        "--quiet",
        "--json",
        str(out),
    )
    assert run.returncode == 0, run.stderr
    q = np.array(json.loads(out.read_text())["q"])
    np.testing.assert_allclose(q[0], q0, atol=1e-12)
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q[-1])
    m = data.oMf[robot.frame_id()]
    assert np.linalg.norm(m.translation - target.position) < 1e-6
    assert np.linalg.norm(pin.log3(m.rotation.T @ target.placement().rotation)) < 1e-6


def test_a_position_only_goal_and_a_named_frame(rng: np.random.Generator) -> None:
    robot = load("panda")
    q0 = random_configuration(robot, rng)
    spot = robot.frame_position(random_configuration(robot, rng), "panda_link7")
    result = nearopt.plan(robot, q0, ToolPose(spot, frame="panda_link7"), grid=60, max_iterations=3)
    end = result.trajectory(np.array([result.duration]), 0)[0]
    assert np.linalg.norm(robot.frame_position(end, "panda_link7") - spot) < 1e-6
    assert result.goal is not None and result.goal.frame == "panda_link7"
    report = nearopt.verify(result.trajectory, robot, goal_pose=result.goal, simulate=False)
    assert report.passed, report
    assert_independent_checks(robot, result.trajectory, result.cost, result.J, q0, end)


def test_an_unreachable_pose_says_how_far_it_is() -> None:
    robot = load("ur5")
    with pytest.raises(
        UnreachablePoseError,
        match=r"closest placement found is [\d.]+ m and "
        r"[\d.e-]+ rad away",
    ) as info:
        nearopt.plan(robot, np.zeros(6), ToolPose((3.0, 0.0, 0.5), (0.0, 0.0, 0.0, 1.0)))
    # ur5 reaches about 0.95 m from its shoulder: the target is ≥ 1.9 m beyond
    assert 1.9 < info.value.distance < 2.3


def test_a_pose_reachable_only_outside_the_limits_is_refused() -> None:
    """ur5 with its shoulder pan held to ±0.1 rad cannot reach a point low behind it (over its
    shoulder it gets within a few centimetres)."""
    base = load("ur5")
    lower, upper = base.limits.position_lower.copy(), base.limits.position_upper.copy()
    lower[0], upper[0] = -0.1, 0.1
    robot = base.with_limits(position=(lower, upper))
    behind = base.frame_position(np.array([np.pi, -1.2, 1.2, -1.5, -1.57, 0.0]))
    inverse_kinematics(base, ToolPose(behind))  # reachable with the URDF's limits
    with pytest.raises(UnreachablePoseError) as info:
        inverse_kinematics(robot, ToolPose(behind))
    assert info.value.distance > 0.01
    assert f"{info.value.distance:.4g} m away" in str(info.value)


def test_an_unknown_frame_lists_the_frames() -> None:
    robot = load("ur5")
    with pytest.raises(
        nearopt.ConfigurationError, match="no frame 'gripper'; its links: .*wrist_3_link"
    ):
        nearopt.plan(robot, np.zeros(6), ToolPose((0.4, 0.0, 0.4), frame="gripper"))
    run = run_cli(
        "plan",
        "--robot",
        "ur5",
        "--q0",
        *["0"] * 6,
        "--goal-pose",
        "0.4",
        "0",
        "0.4",
        "--frame",
        "gripper",
    )
    lines = run.stderr.strip().splitlines()
    assert run.returncode == 2 and len(lines) == 1 and "tool0" in lines[0], run.stderr


@pytest.mark.parametrize(
    "args",
    [
        ["--qe", *["0.1"] * 6, "--goal-pose", "0.4", "0", "0.4"],
        ["--goal-pose", "0.4", "0"],
        ["--frame", "tool0", "--qe", *["0.1"] * 6],
        ["--qe", *["0.1"] * 6, "--via", "0", "0"],
        ["--qe", *["0.1"] * 6, "--via", "9", "0", "0", "0", "0", "0"],
    ],
)
def test_bad_goal_and_via_options_get_one_line(args: list[str]) -> None:
    run = run_cli("plan", "--robot", "ur5", "--q0", *["0"] * 6, *args)
    assert run.returncode == 2 and len(run.stderr.strip().splitlines()) == 1, run.stderr


@pytest.mark.slow
def test_the_goal_configuration_is_optimised_along_the_pose(rng: np.random.Generator) -> None:
    """panda is redundant: θe moves among the configurations that hold the pose. J never ends
    above the plan with inverse kinematics' θe, and every iterate ends exactly at the pose."""
    robot = load("panda")
    cost = nearopt.TorqueCost(0.001)
    gains = []
    for _ in range(3):
        q0 = random_configuration(robot, rng)
        goal = pose_of(robot, random_configuration(robot, rng))
        fixed = nearopt.plan(robot, q0, goal, cost, optimise_goal=False, time_limit=60.0)
        moved = nearopt.plan(robot, q0, goal, cost, time_limit=60.0)
        assert moved.J <= fixed.J * (1 + 1e-6)
        gains.append(1 - moved.J / fixed.J)
        for it in moved.history:
            distance, angle = pose_error(robot, it.path(np.array([it.path.s_end]))[0], goal)
            assert distance < 1e-9 and angle < 1e-9
        report = nearopt.verify(
            moved.trajectory, robot, goal_pose=goal, cost=moved.cost, J=moved.J, simulate=False
        )
        assert report.passed, report
    assert max(gains) > 0.01  # the freedom is worth something on some of them


def test_the_workspace_figure_marks_the_target() -> None:
    import matplotlib

    matplotlib.use("Agg")
    from nearopt.viz.figures import plot_workspace

    robot = load("ur5")
    goal = ToolPose((0.4, 0.2, 0.3))
    result = nearopt.plan(
        robot, np.array([0.0, -1.2, 1.2, -1.5, -1.57, 0.0]), goal, grid=60, max_iterations=2
    )
    fig = plot_workspace(robot, {"final": result.trajectory}, targets=(goal,))
    star = [c for c in fig.axes[0].collections if c.get_label() == "target"][0]
    np.testing.assert_allclose(np.ravel(star._offsets3d), goal.position, atol=1e-12)


@pytest.mark.slow
def test_via_points_are_passed_exactly_without_stopping(tmp_path: Path) -> None:
    """ur5 through a joint via-point (CLI) and panda through a tool pose: every iterate's path
    goes through, the written motion is there at the reported time, moving."""
    q0, qe = [-0.8, -1.2, 1.2, -1.5, -1.57, 0.0], [0.8, -1.2, 1.2, -1.5, -1.57, 0.0]
    via = [0.0, -1.6, 0.8, -1.0, -1.57, 0.5]
    out = tmp_path / "via.json"
    run = run_cli(
        "plan",
        "--robot",
        "ur5",
        "--q0",
        *map(str, q0),
        "--qe",
        *map(str, qe),
        "--via",
        *map(str, via),
        "--beta",
        "0.001",
        "--quiet",
        "--rate",
        "2000",
        "--json",
        str(out),
    )
    assert run.returncode == 0, run.stderr
    doc = json.loads(out.read_text())
    (mark,) = doc["via"]
    t, q, qd = (np.array(doc[k]) for k in ("t", "q", "qd"))
    np.testing.assert_allclose(mark["q"], via, atol=1e-12)
    k = int(np.argmin(np.abs(t - mark["t"])))
    speed = np.abs(qd).max(axis=1)
    assert np.abs(q[k] - via).max() < speed[k] / 2000.0 + 1e-9  # within one sample's motion
    assert speed[k] > 0.5  # passes, does not stop

    robot = load("panda")
    start = np.array([0.0, -0.5, 0.0, -2.0, 0.0, 1.5, 0.8])
    pose = pose_of(robot, np.array([0.6, -0.2, 0.3, -1.8, 0.1, 1.8, 0.5]))
    result = nearopt.plan(
        robot, start, [1.0, 0.0, 0.5, -1.5, 0.0, 2.0, 0.0], via=[pose], grid=100, max_iterations=20
    )
    (tv,) = result.via_times
    at = result.trajectory(np.array([tv]), 0)[0]
    assert max(pose_error(robot, at, pose)) < 1e-9
    assert np.abs(result.trajectory(np.array([tv]), 1)[0]).max() > 0.1
    for it in result.history:
        assert max(pose_error(robot, it.path(np.array(result.via_s))[0], pose)) < 1e-9
    assert_independent_checks(
        robot,
        result.trajectory,
        result.cost,
        result.J,
        start,
        np.array([1.0, 0.0, 0.5, -1.5, 0.0, 2.0, 0.0]),
    )


# a panda start and goal (pair 1 of bench_cell.py's seed 13) and its cell plan's configuration
# halfway (clear, on the plan's own path)
PANDA_HALFWAY = (
    np.array([1.0784977518341199, -0.06236072564168671, -1.739671809620453,
              -1.3196409408895144, 1.1447182446131854, 2.179072289486437, 0.23904997069078027]),
    np.array([1.9863495686780808, 1.2571233665879387, 1.7377757959902929,
              -1.879060645801851, -1.0765436221599132, 1.6373893793496446, 0.7153327663088236]),
    np.array([0.6538219027427153, -0.4306386612586585, 0.031378101812264074,
              -2.874165859413555, -0.626554167173879, 0.5748261889831564, -0.9950792101094225]),
)  # fmt: skip


def test_a_tool_pose_via_point_is_solved_for_a_short_way_through_it() -> None:
    """The tool pose of a panda cell plan's own configuration qm halfway: inverse kinematics
    from the start alone came out on a far branch (the way q0 → via → qe 12.1 rad, the plan
    then J 4.84 against 2.55); of the solutions from the start, the goal and their midpoint the
    one with the shortest way is taken, about as short as through qm itself."""
    robot = load("panda")
    q0, qe, qm = PANDA_HALFWAY
    pose = pose_of(robot, qm)

    def way(q: np.ndarray) -> float:
        return float(np.linalg.norm(q - q0) + np.linalg.norm(qe - q))

    result = nearopt.plan(robot, q0, qe, via=[pose], max_iterations=0)
    qv = result.trajectory(np.array(result.via_times), 0)[0]
    assert max(pose_error(robot, qv, pose)) < 1e-9
    assert way(qv) < 0.8 * way(inverse_kinematics(robot, pose, seed=q0))
    assert way(qv) <= 1.05 * way(qm)


def test_a_tool_pose_via_points_configuration_moves_along_its_pose() -> None:
    """A panda pose taken from a free plan's own path at half its duration (a fuzz pass's
    case): the via-point was the inverse-kinematics solution with the shortest way and stayed
    there, J 2.302 against the plan's 2.153 (+6.9 %); its configuration now moves along the
    pose as a goal pose's does, each step put back onto the pose, and the plan costs what the
    plan whose pose it was does. verify_plan checks the pose."""
    robot = load("panda")
    q0 = np.array([-2.1608976024625988, -0.8351107901503118, 1.5711885144764892,
                   -1.3488146109612908, -2.1166759527064043, 1.6405997082223558,
                   -0.109250413013811])  # fmt: skip
    qe = np.array([-2.60757, -0.1734906261436503, -0.21970437621425942, -1.610040988666909,
                   -2.039073822932201, 1.431373817791516, 0.2931199886305493])  # fmt: skip
    cost = nearopt.TorqueCost(1e-3)
    free = nearopt.plan(robot, q0, qe, cost)
    pose = pose_of(robot, free.trajectory(np.array([0.5 * free.duration]))[0])
    through = nearopt.plan(robot, q0, qe, cost, via=[pose])
    assert through.J <= free.J * (1 + 1e-3), (through.J, free.J)
    at = through.trajectory(np.array(through.via_times), 0)[0]
    assert max(pose_error(robot, at, pose)) < 1e-9
    np.testing.assert_allclose(through.via[0], at, rtol=0, atol=1e-12)
    report = nearopt.verify_plan(through, q0=q0, qe=qe)
    assert report.passed and "via-point poses" in str(report), str(report)
    fixed = nearopt.plan(robot, q0, qe, cost, via=[pose], optimise_goal=False)
    assert fixed.J > 1.05 * free.J  # (the solution with the shortest way, kept: +6.9 %)


def test_a_six_joint_arms_pose_via_point_is_solved_on_the_paths_branch() -> None:
    """ur5 (no redundancy to move along): the pose of a free plan's configuration at 0.3 of its
    duration. Inverse kinematics from the start, the goal and their midpoint came out on another
    branch (elbow flipped; J +47 % over the plan whose pose it was); from points along the line
    between them too, it finds the path's own."""
    robot = load("ur5")
    q0 = np.array([1.149833933474273, 1.1609094273321694, 0.057776003978562196,
                   -0.8075097728690002, -1.6816416340676965, -0.43968896076500563])  # fmt: skip
    qe = np.array([-0.3450478865509852, -1.7142721322893457, -1.701143353162283,
                   1.881849619123106, 0.5744180179185907, -1.00087296004454])  # fmt: skip
    cost = nearopt.TorqueCost(1e-3)
    free = nearopt.plan(robot, q0, qe, cost)
    qm = free.trajectory(np.array([0.3 * free.duration]))[0]
    through = nearopt.plan(robot, q0, qe, cost, via=[pose_of(robot, qm)], optimise_goal=False)
    assert np.max(np.abs(through.via[0] - qm)) < 1e-6, (through.via[0], qm)
    assert through.J <= free.J * (1 + 1e-3), (through.J, free.J)


def test_a_step_is_put_back_onto_the_via_points_exactly() -> None:
    """Stage 2's model keeps the via-points to its own accuracy only (a kinova cell plan's
    iterates drifted 1.6e-8 rad off one, and verify asks 1e-8): each trial step is moved back
    onto them by the least change of the control points, those at a position limit left where
    they are."""
    from nearopt.path import BSplinePath
    from nearopt.planning.scp import path_through, through_vias

    rng = np.random.default_rng(3)
    n, k = 3, 12
    points = rng.uniform(-1.0, 1.0, (4, n))
    start, sigma = path_through(points, k, None, [1, 2])
    ends = start.control_points[[0, -1]]

    def path_of(p: np.ndarray) -> BSplinePath:
        return BSplinePath(np.vstack([ends[:1], p.reshape(k, n), ends[1:]]))

    p = start.control_points[1:-1].ravel() + 1e-7 * rng.normal(size=k * n)
    assert np.abs(path_of(p)(sigma) - points[1:3]).max() > 1e-8
    lower, upper = np.full(k * n, -np.inf), np.full(k * n, np.inf)
    lower[4] = p[4]  # control point 1 of joint 1 at its lower limit
    moved = through_vias(start, (tuple(sigma), ()), path_of, (lower, upper), p)
    np.testing.assert_allclose(path_of(moved)(sigma), points[1:3], rtol=0, atol=1e-14)
    assert moved[4] == p[4]
    # the least change: per joint, the minimum-norm solution over the other control points
    basis = start.basis(sigma)[:, 1:-1]
    for j in range(n):
        free = np.arange(k) != (1 if j == 1 else -1)
        miss = points[1:3, j] - path_of(p)(sigma)[:, j]
        least = np.linalg.pinv(basis[:, free]) @ miss
        np.testing.assert_allclose((moved - p).reshape(k, n)[free, j], least, atol=1e-15)


def test_bad_tool_poses_and_via_lists_are_configuration_errors() -> None:
    robot = load("ur5")
    for make in (
        lambda: ToolPose("abc"),
        lambda: ToolPose((0.4j, 0.2, 0.3)),
        lambda: ToolPose((0.4, 0.2, 0.3), "abcd"),
        lambda: ToolPose((0.4, 0.2, 0.3), frame=5),
    ):
        with pytest.raises(nearopt.ConfigurationError):
            make()
    # a huge quaternion is the same orientation, not an overflow to zero
    assert ToolPose((0.4, 0.2, 0.3), (1e300, 0, 0, 0)).quaternion == (1.0, 0.0, 0.0, 0.0)
    q0, qe = np.zeros(6), np.full(6, 0.5)
    with pytest.raises(nearopt.ConfigurationError, match="each a joint vector of 6 values"):
        nearopt.plan(robot, q0, qe, via=[0.0, -1.2, 1.2, -1.5, -1.57, 0.0])
    assert not nearopt.plan(robot, q0, qe, via=None, max_iterations=0).via


def test_a_pose_goal_is_reached_in_the_turn_nearest_the_start() -> None:
    """ur5, a fuzz pass's pose: inverse kinematics from θ0 came out with joints 1 and 6 a turn
    (2π) away from θ0 (5.06 against 0.06, −6.23 against −0.39), and stage 2 cannot leave the turn
    it starts in: J 4.80 against 2.14 for the same pose in the nearer turn. Each revolute joint of
    the solution now lies within π of θ0 where its limits allow, the pose kept to 1e-10."""
    robot = load("ur5")
    q0 = np.array([0.059, 2.264, -0.894, 2.255, -0.946, -0.385])
    qe = np.array([1.647, -0.456, 0.125, -2.375, 1.274, 0.192])
    m = robot.frame_placement(qe)
    pose = ToolPose(tuple(m.translation), tuple(pin.Quaternion(m.rotation).coeffs()))
    solved = inverse_kinematics(robot, pose, seed=q0)
    assert max(pose_error(robot, solved, pose)) < 1e-9
    lim = robot.limits
    for i in range(robot.n):
        for turn in (-2.0 * np.pi, 2.0 * np.pi):
            other = solved[i] + turn
            if lim.position_lower[i] <= other <= lim.position_upper[i]:
                assert abs(solved[i] - q0[i]) <= abs(other - q0[i]), (i, solved[i], q0[i])
    result = nearopt.plan(robot, q0, pose, nearopt.TorqueCost(1e-3))
    end = result.trajectory(np.array([result.duration]))[0]
    assert np.all(np.abs(end - q0) <= np.pi + 1e-9), end
    assert nearopt.verify_plan(result).passed


def test_a_pose_goal_for_a_one_joint_arm(tmp_path: Path) -> None:
    """Pinocchio gives a one-joint arm's frame Jacobian as a vector: inverse kinematics raised
    numpy's ValueError from its solve (a fuzz pass's `--goal-pose` on a 1-DOF URDF)."""
    from urdfs import write_urdf

    robot = nearopt.Robot.from_urdf(write_urdf(tmp_path), locked_joints=("j2",))
    assert robot.n == 1
    pose = ToolPose(tuple(robot.frame_placement(np.array([0.8])).translation))
    result = nearopt.plan(robot, np.array([0.0]), pose, nearopt.TorqueCost(1e-3))
    end = result.trajectory(np.array([result.duration]))[0]
    assert abs(end[0] - 0.8) < 1e-8, end
    assert nearopt.verify_plan(result).passed
