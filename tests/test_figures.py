"""The paper's figures, drawn headless and read back: the plan's data, the right limits."""

from __future__ import annotations

from pathlib import Path

import matplotlib
import numpy as np
import pytest
from conftest import load

import nearopt
from nearopt.paper_example import COST, TABLE_2, THETA_0, THETA_E
from nearopt.viz.figures import plot_history, plot_torques, plot_workspace, save_figures

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


def test_planar_workspace_plot_is_in_the_arm_plane_with_the_tip_path(
    paper_plan: nearopt.PlanResult,
) -> None:
    robot = paper_plan.robot
    fig = plot_workspace(robot, {"initial": paper_plan.initial.trajectory,
                                 "final": paper_plan.trajectory})
    assert [ax.name for ax in fig.axes] == ["rectilinear", "rectilinear"]
    for ax, traj in zip(fig.axes, (paper_plan.initial.trajectory, paper_plan.trajectory),
                        strict=True):
        tip = [line for line in ax.get_lines() if line.get_label() == "tip path"][0]
        xy = tip.get_xydata()
        world = robot.frame_position(traj(np.linspace(0, traj.duration, len(xy)), 0))
        # the arm moves in the x-z plane (axes along y); seen from −y: right = x, up = z
        np.testing.assert_allclose(xy, world[:, [0, 2]], atol=1e-9)
    # the straight line's tip starts at θ0's tip and ends at θe's: (0, 0.2828) → (−0.4, 0)
    start = fig.axes[0].get_lines()[-1].get_xydata()
    np.testing.assert_allclose(start[0], [0.0, 0.2 * np.sqrt(2)], atol=1e-9)
    np.testing.assert_allclose(start[-1], [-0.4, 0.0], atol=1e-9)


def test_spatial_arm_gets_a_3d_workspace_plot() -> None:
    robot = load("ur5")
    traj = nearopt.optimal_timing(robot, nearopt.StraightPath(np.zeros(6), np.full(6, 0.5)),
                                  grid=40).trajectory
    fig = plot_workspace(robot, {"line": traj})
    assert fig.axes[0].name == "3d"


def test_history_plot_and_files(paper_plan: nearopt.PlanResult, tmp_path: Path) -> None:
    fig = plot_history(paper_plan, {row.index: row.J for row in TABLE_2})
    ours, paper = fig.axes[0].get_lines()
    np.testing.assert_allclose(ours.get_ydata(), [it.J for it in paper_plan.history])
    np.testing.assert_array_equal(paper.get_xydata(), [[row.index, row.J] for row in TABLE_2])
    written = save_figures(paper_plan, tmp_path / "figures")
    assert [p.name for p in written] == ["torques.png", "workspace.png", "history.png"]
    assert all(p.stat().st_size > 10_000 and p.read_bytes()[:4] == b"\x89PNG" for p in written)
