"""The paper's figures, drawn headless and read back: the plan's data, the right limits."""

from __future__ import annotations

from pathlib import Path

import matplotlib
import numpy as np
import pytest
from conftest import load
from urdfs import write_urdf

import nearopt
from nearopt.paper_example import COST, TABLE_2, THETA_0, THETA_E
from nearopt.viz.figures import (
    plot_accelerations,
    plot_history,
    plot_speeds,
    plot_torques,
    plot_workspace,
    save_figures,
)

matplotlib.use("Agg")


@pytest.fixture(scope="module")
def paper_plan() -> nearopt.PlanResult:
    return nearopt.plan(load("two_link"), THETA_0, THETA_E, COST, grid=60, max_iterations=15)


def test_torque_plot_shows_the_trajectory_torques_and_the_limits(
    paper_plan: nearopt.PlanResult,
) -> None:
    robot, traj = paper_plan.robot, paper_plan.trajectory
    fig = plot_torques(robot, traj, rate=500.0)
    for i, ax in enumerate(fig.axes):
        curve, *limits = ax.get_lines()
        t, u = curve.get_xydata().T
        np.testing.assert_allclose(t[-1], traj.duration)
        np.testing.assert_allclose(u, traj.torque(t)[:, i], atol=1e-9)
        levels = sorted(float(line.get_ydata()[0]) for line in limits)
        assert levels == [robot.limits.effort_lower[i], robot.limits.effort_upper[i]]
        assert ax.get_ylabel() == f"{robot.joint_names[i]}\n[N·m]"
    assert [t.get_text() for t in fig.legends[0].get_texts()] == ["u (plan)", "limit"]


def test_speed_plot_shows_the_speeds_at_their_limits() -> None:
    """ur5 timed optimally along a line: the speed limits bind, and the figure shows it."""
    robot = load("ur5")
    q0 = np.array([0.0, -1.2, 1.2, -1.5, -1.5, 0.0])
    traj = nearopt.optimal_timing(robot, nearopt.StraightPath(q0, q0 + 1.0), grid=60).trajectory
    fig = plot_speeds(robot, traj, rate=500.0)
    peaks = []
    for i, ax in enumerate(fig.axes):
        curve, *limits = ax.get_lines()
        t, qd = curve.get_xydata().T
        np.testing.assert_allclose(qd, traj(t, 1)[:, i], atol=1e-9)
        v = robot.limits.velocity[i]
        assert sorted(float(line.get_ydata()[0]) for line in limits) == [-v, v]
        assert ax.get_ylabel().endswith("[rad/s]")
        peaks.append(np.max(np.abs(qd)) / v)
    assert max(peaks) == pytest.approx(1.0, abs=1e-3)  # at the limit, not beyond


def test_prismatic_joints_get_linear_units_and_acceleration_limits_their_figure(
    tmp_path: Path,
) -> None:
    robot = nearopt.Robot.from_urdf(write_urdf(tmp_path, types=("prismatic", "revolute")))
    robot = robot.with_limits(acceleration=[2.0, np.inf])
    traj = nearopt.optimal_timing(
        robot, nearopt.StraightPath([0.0, 0.0], [0.2, 0.3]), grid=40
    ).trajectory
    units = {"torque": plot_torques, "speed": plot_speeds, "acceleration": plot_accelerations}
    expected = {
        "torque": ("[N]", "[N·m]"),
        "speed": ("[m/s]", "[rad/s]"),
        "acceleration": ("[m/s²]", "[rad/s²]"),
    }
    for kind, plot in units.items():
        fig = plot(robot, traj, rate=500.0)
        assert tuple(ax.get_ylabel().split("\n")[1] for ax in fig.axes) == expected[kind]
    fig = plot_accelerations(robot, traj, rate=500.0)
    first, second = (ax.get_lines() for ax in fig.axes)
    assert sorted(float(line.get_ydata()[0]) for line in first[1:]) == [-2.0, 2.0]
    assert len(second) == 1  # no limit, no line


def test_planar_workspace_plot_is_in_the_arm_plane_with_the_tip_path(
    paper_plan: nearopt.PlanResult,
) -> None:
    robot = paper_plan.robot
    fig = plot_workspace(
        robot, {"initial": paper_plan.initial.trajectory, "final": paper_plan.trajectory}
    )
    assert [ax.name for ax in fig.axes] == ["rectilinear", "rectilinear"]
    for ax, traj in zip(
        fig.axes, (paper_plan.initial.trajectory, paper_plan.trajectory), strict=True
    ):
        tip = [line for line in ax.get_lines() if line.get_label() == "tip path"][0]
        xy = tip.get_xydata()
        world = robot.frame_position(traj(np.linspace(0, traj.duration, len(xy)), 0))
        # the arm moves in the x-z plane (axes along y); seen from −y: right = x, up = z
        np.testing.assert_allclose(xy, world[:, [0, 2]], atol=1e-9)
    # the straight line's tip starts at θ0's tip and ends at θe's: (0, 0.2828) → (−0.4, 0)
    start = fig.axes[0].get_lines()[-1].get_xydata()
    np.testing.assert_allclose(start[0], [0.0, 0.2 * np.sqrt(2)], atol=1e-9)
    np.testing.assert_allclose(start[-1], [-0.4, 0.0], atol=1e-9)


def test_a_planar_arm_s_workspace_shows_the_obstacles_sections(
    paper_plan: nearopt.PlanResult,
) -> None:
    """A ball of radius 3 cm centred 1 cm off the arm's plane is cut in a disc of radius
    √(3² − 1²) cm; a box crossing the plane in a rectangle; a floor as the region below it."""
    from nearopt.collision import Box, HalfSpace, Obstacle, Scene, Sphere

    scene = Scene(
        (
            Obstacle("ball", Sphere(0.03), (-0.14, 0.01, -0.1)),
            Obstacle("block", Box((0.1, 0.2, 0.04)), (0.1, 0.0, -0.05)),
            Obstacle("floor", HalfSpace((0.0, 0.0, 1.0), -0.15)),
            Obstacle("away", Sphere(0.03), (0.0, 0.5, 0.0)),  # does not cross the plane
        )
    )
    fig = plot_workspace(paper_plan.robot, {"final": paper_plan.trajectory}, scene=scene)
    ax = fig.axes[0]
    assert len(ax.patches) == 3  # the one away from the plane is not drawn
    assert [t.get_text() for t in ax.texts[:3]] == ["ball", "block", "floor"]
    ball, block, floor = (p.get_xy() for p in ax.patches[:3])
    radius = np.linalg.norm(ball - [-0.14, -0.1], axis=1)
    np.testing.assert_allclose(radius, np.sqrt(0.03**2 - 0.01**2), rtol=0.02)
    np.testing.assert_allclose(
        [block[:, 0].min(), block[:, 0].max(), block[:, 1].min(), block[:, 1].max()],
        [0.05, 0.15, -0.07, -0.03],
        atol=1e-9,
    )
    assert floor[:, 1].max() == pytest.approx(-0.15, abs=1e-9)


def test_spatial_arm_gets_a_3d_workspace_plot() -> None:
    robot = load("ur5")
    traj = nearopt.optimal_timing(
        robot, nearopt.StraightPath(np.zeros(6), np.full(6, 0.5)), grid=40
    ).trajectory
    fig = plot_workspace(robot, {"line": traj})
    ax = fig.axes[0]
    assert ax.name == "3d"
    spans = [np.diff(getattr(ax, f"get_{a}lim")())[0] for a in "xyz"]
    np.testing.assert_allclose(spans, spans[0])  # equal scales
    start, goal = (c.get_offsets() for c in ax.collections[-2:])
    tip = robot.frame_position(np.array([np.zeros(6), np.full(6, 0.5)]))
    assert [c.get_label() for c in ax.collections[-2:]] == ["start", "goal"]
    np.testing.assert_allclose([start[0], goal[0]], tip[:, :2], atol=1e-9)  # x, y on screen
    stamps = [t.get_text() for t in ax.texts]
    assert stamps[0] == " 0.00 s" and stamps[-1] == f" {traj.duration:.2f} s"


def test_history_plot_and_files(paper_plan: nearopt.PlanResult, tmp_path: Path) -> None:
    fig = plot_history(paper_plan, {row.index: row.J for row in TABLE_2})
    ours, paper = fig.axes[0].get_lines()
    np.testing.assert_allclose(ours.get_ydata(), [it.J for it in paper_plan.history])
    np.testing.assert_array_equal(paper.get_xydata(), [[row.index, row.J] for row in TABLE_2])
    assert paper.get_label() == "paper, Table 2" and fig.axes[0].get_ylabel() == "$J^j$"
    written = save_figures(paper_plan, tmp_path / "figures")
    assert [p.name for p in written] == [
        "torques.png",
        "speeds.png",
        "workspace.png",
        "history.png",
    ]
    assert all(p.stat().st_size > 10_000 and p.read_bytes()[:4] == b"\x89PNG" for p in written)


def test_a_jerk_limited_plan_gets_its_jerk_figure() -> None:
    """With jerk limits the figures include jerks.png: θ⃛_i(t) of the motion against ±j_i,
    reaching the limit and not beyond it."""
    from nearopt.viz.figures import plot_jerks, render_figures

    robot = load("two_link").with_limits(jerk=300.0)
    result = nearopt.plan(
        robot, np.array([0.5, -0.5]), np.array([-0.4, 0.6]), max_iterations=1, grid=60
    )
    fig = plot_jerks(robot, result.trajectory, rate=2000.0)
    peaks = []
    for i, ax in enumerate(fig.axes):
        curve, *limits = ax.get_lines()
        t, jerk = curve.get_xydata().T
        np.testing.assert_allclose(jerk, result.trajectory.jerk(t)[:, i], atol=1e-9)
        assert sorted(float(line.get_ydata()[0]) for line in limits) == [-300.0, 300.0]
        assert ax.get_ylabel().endswith("[rad/s³]")
        peaks.append(np.max(np.abs(jerk)) / 300.0)
    assert 0.9 < max(peaks) <= 1.0
    assert {"jerks.png", "accelerations.png"} <= set(render_figures(result))


def test_a_torque_rate_limited_plan_gets_its_torque_rate_figure() -> None:
    """With torque-rate limits the figures include torque_rates.png: u̇_i(t) against ±r_i (by
    differences of the torques, independent of the planner), reaching the limit and not
    beyond it; without them there is none."""
    from nearopt.viz.figures import plot_torque_rates, render_figures

    robot = load("two_link").with_limits(torque_rate=400.0)
    result = nearopt.plan(
        robot, np.array([0.5, -0.5]), np.array([-0.4, 0.6]), max_iterations=1, grid=60
    )
    fig = plot_torque_rates(robot, result.trajectory, rate=2000.0)
    peaks = []
    for ax in fig.axes:
        curve, *limits = ax.get_lines()
        assert sorted(float(line.get_ydata()[0]) for line in limits) == [-400.0, 400.0]
        assert ax.get_ylabel().endswith("[N·m/s]")
        peaks.append(np.max(np.abs(curve.get_ydata())) / 400.0)
    assert 0.9 < max(peaks) <= 1.0 + 1e-6
    assert "torque_rates.png" in render_figures(result)
    plain = nearopt.plan(
        load("two_link"), np.array([0.5, -0.5]), np.array([-0.4, 0.6]), max_iterations=1
    )
    assert "torque_rates.png" not in render_figures(plain)
