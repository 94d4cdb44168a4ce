"""The paper's figures for a plan (matplotlib, imported only when a figure is drawn).

* :func:`plot_torques` — u_i(t) against the actuator limits (Figs. 6-8);
* :func:`plot_workspace` — the tip's path and link poses of the initial and final paths in the
  workspace (Figs. 3-5): in the arm's plane for a planar arm, in 3-D otherwise;
* :func:`plot_history` — J over the iterations (Table 2);
* :func:`save_figures` — all three as PNG files.

Every function returns the ``matplotlib.figure.Figure`` it drew; its artists carry the plotted data
(tests read them back).
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..errors import ConfigurationError
from ..outputs import write_atomically
from .geometry import chain_points, plane_axes, tip_path

if TYPE_CHECKING:
    from matplotlib.figure import Figure
    from numpy.typing import NDArray

    from ..planning import PlanResult
    from ..robot import Robot
    from ..trajectory import Trajectory

__all__ = [
    "plot_torques",
    "plot_workspace",
    "plot_history",
    "render_figures",
    "save_figures",
]


def _pyplot():  # noqa: ANN202 - the module, imported lazily
    """matplotlib.pyplot (it falls back to the Agg backend by itself where there is no display)."""
    import matplotlib.pyplot as plt

    return plt


def plot_torques(robot: Robot, trajectory: Trajectory, rate: float = 2000.0) -> Figure:
    """u_i(t) of a motion, one panel per joint, with its limits as dashed lines (Figs. 6-8).

    Parameters
    ----------
    robot
        The arm (its effort limits are drawn).
    trajectory
        The motion.
    rate
        Sampling rate of the curves [Hz].
    """
    plt = _pyplot()
    samples = trajectory.sample(rate)
    n = robot.n
    fig, axes = plt.subplots(n, 1, sharex=True, figsize=(7, 1.8 * n + 0.6), squeeze=False)
    for i, ax in enumerate(axes[:, 0]):
        ax.plot(samples.t, samples.tau[:, i], color="C0", label=f"u{i + 1}")
        for limit in (robot.limits.effort_lower[i], robot.limits.effort_upper[i]):
            ax.axhline(limit, color="0.4", linestyle="--", linewidth=1)
        ax.set_ylabel(f"u{i + 1} [N·m]\n{robot.joint_names[i]}", fontsize=8)
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("t [s]")
    fig.suptitle(f"{robot.name}: torques and limits (te = {trajectory.duration:.4f} s)")
    fig.tight_layout()
    return fig


def plot_workspace(
    robot: Robot, motions: dict[str, Trajectory], poses: int = 6
) -> Figure:
    """The tip's path and ``poses`` link poses of each motion in the workspace (Figs. 3-5).

    Parameters
    ----------
    robot
        The arm.
    motions
        Label → motion, e.g. ``{"initial": …, "final": …}``; one panel each.
    poses
        Link poses drawn per motion, evenly spaced in time.
    """
    plt = _pyplot()
    tips = {label: tip_path(robot, traj) for label, traj in motions.items()}
    frames = {
        label: [chain_points(robot, q) for q in traj(np.linspace(0, traj.duration, poses), 0)]
        for label, traj in motions.items()
    }
    everything = np.vstack([*tips.values(), *(c for f in frames.values() for c in f)])
    plane = plane_axes(everything)
    fig = plt.figure(figsize=(5 * len(motions), 5))
    for k, label in enumerate(motions):
        if plane is not None:
            ax = fig.add_subplot(1, len(motions), k + 1)

            def flat(p: NDArray[np.float64]) -> NDArray[np.float64]:
                return p @ plane.T

            for chain in frames[label]:
                ax.plot(*flat(chain).T, "-o", color="0.3", linewidth=1.5, markersize=3)
            ax.plot(*flat(tips[label]).T, color="C3", linewidth=2, label="tip path")
            ax.set_aspect("equal")
            ax.set_xlabel("in-plane horizontal [m]")
            ax.set_ylabel("up [m]")
        else:
            ax = fig.add_subplot(1, len(motions), k + 1, projection="3d")
            for chain in frames[label]:
                ax.plot(*chain.T, "-o", color="0.3", linewidth=1.5, markersize=3)
            ax.plot(*tips[label].T, color="C3", linewidth=2, label="tip path")
            ax.set_xlabel("x [m]")
            ax.set_ylabel("y [m]")
            ax.set_zlabel("z [m]")
        ax.set_title(f"{label} (te = {motions[label].duration:.3f} s)")
        ax.legend(loc="best", fontsize=8)
    fig.suptitle(f"{robot.name}: workspace path and link poses")
    fig.tight_layout()
    return fig


def plot_history(result: PlanResult, reference: dict[int, float] | None = None) -> Figure:
    """J^j over the iterations j (Table 2), optionally beside reference values.

    Parameters
    ----------
    result
        The plan.
    reference
        Iteration → J of another method (e.g. the paper's Table 2), drawn as markers.
    """
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6, 4))
    j = [it.index for it in result.history]
    label = f"nearopt ({result.method})"
    ax.plot(j, [it.J for it in result.history], "-o", markersize=3, label=label)
    if reference:
        ax.plot(list(reference), list(reference.values()), "s", color="C1", label="reference")
    ax.set_xlabel("iteration j")
    ax.set_ylabel("J^j")
    ax.grid(alpha=0.3)
    ax.legend()
    ax.set_title(f"{result.robot.name}: J = {result.J:.6f} after {len(j) - 1} iterations")
    fig.tight_layout()
    return fig


def render_figures(
    result: PlanResult, reference: dict[int, float] | None = None
) -> dict[str, bytes]:
    """torques.png, workspace.png and history.png of a plan, as PNG bytes by file name."""
    plt = _pyplot()
    figures = {
        "torques.png": plot_torques(result.robot, result.trajectory),
        "workspace.png": plot_workspace(
            result.robot, {"initial": result.initial.trajectory, "final": result.trajectory}
        ),
        "history.png": plot_history(result, reference),
    }
    rendered = {}
    for name, fig in figures.items():
        buffer = io.BytesIO()
        fig.savefig(buffer, format="png", dpi=120)
        plt.close(fig)
        rendered[name] = buffer.getvalue()
    return rendered


def save_figures(
    result: PlanResult, folder: str | Path, reference: dict[int, float] | None = None
) -> list[Path]:
    """Write torques.png, workspace.png and history.png for a plan into ``folder`` (made if it is
    missing, with its parents).

    Raises
    ------
    ConfigurationError
        If ``folder`` is a file or cannot be made.
    """
    folder = Path(folder).expanduser()
    if folder.exists() and not folder.is_dir():
        raise ConfigurationError(f"cannot write figures into {folder}: it is not a folder")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigurationError(
            f"cannot make the folder {folder}: {exc.strerror or exc}"
        ) from None
    return [
        write_atomically(folder / name, png)
        for name, png in render_figures(result, reference).items()
    ]
