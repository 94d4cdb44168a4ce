"""The paper's figures for a plan (matplotlib, imported only when a figure is drawn).

* :func:`plot_torques` — u_i(t) against the actuator limits (Figs. 6-8);
* :func:`plot_speeds`, :func:`plot_accelerations`, :func:`plot_jerks` — θ̇_i(t), θ̈_i(t), θ⃛_i(t)
  against their limits;
* :func:`plot_workspace` — the tip's path and link poses of the initial and final paths in the
  workspace (Figs. 3-5): in the arm's plane for a planar arm, in 3-D otherwise;
* :func:`plot_history` — J over the iterations (Table 2);
* :func:`save_figures` — all of them as PNG files.

Every function returns the ``matplotlib.figure.Figure`` it drew; its artists carry the plotted data
(tests read them back).
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..outputs import make_folder, write_atomically
from ..planning import Plan, TaskResult, check_plan
from ..verify import torque_rates
from .geometry import chain_points, plane_axes, target_poses, tip_path

if TYPE_CHECKING:
    from matplotlib.figure import Figure
    from numpy.typing import NDArray

    from ..collision import Scene
    from ..robot import Robot
    from ..robot.kinematics import ToolPose
    from ..trajectory import ChainedTrajectory, Motion, Trajectory

__all__ = [
    "plot_torques",
    "plot_speeds",
    "plot_accelerations",
    "plot_jerks",
    "plot_torque_rates",
    "plot_workspace",
    "plot_history",
    "render_figures",
    "save_figures",
    "FIGURE_NAMES",
]

FIGURE_NAMES = (
    "torques.png",
    "speeds.png",
    "accelerations.png",
    "jerks.png",
    "torque_rates.png",
    "workspace.png",
    "history.png",
)
"""Every file :func:`render_figures` may write (the acceleration, jerk and torque-rate figures
where the robot has such limits): places no other output may take."""


def _pyplot():  # noqa: ANN202 - the module, imported lazily
    """matplotlib.pyplot (it falls back to the Agg backend by itself where there is no display)."""
    import matplotlib.pyplot as plt

    return plt


def _joint_panels(
    robot: Robot,
    t: NDArray[np.float64],
    values: NDArray[np.float64],
    limits: tuple[NDArray[np.float64], NDArray[np.float64]],
    quantity: tuple[str, str, str],
    title: str,
    stops: NDArray[np.float64] | None = None,
) -> Figure:
    """One panel per joint: values[:, i] against t and its limits (dashed), a shared legend.

    ``quantity`` is (symbol, unit of a revolute joint, unit of a prismatic joint); ``stops``
    the times where a task's arm stops at a target (dotted grey lines).
    """
    plt = _pyplot()
    n = robot.n
    linear = robot.prismatic
    fig, axes = plt.subplots(n, 1, sharex=True, figsize=(7.5, 1.5 * n + 1.2), squeeze=False)
    symbol, rot_unit, lin_unit = quantity
    for i, ax in enumerate(axes[:, 0]):
        ax.plot(t, values[:, i], color="C0", linewidth=1.4, label=f"{symbol} (plan)")
        for k, stop in enumerate(() if stops is None else stops):
            ax.axvline(
                stop,
                color="0.5",
                linestyle=":",
                linewidth=1,
                label="stop at a target" if k == 0 else "_nolegend_",
            )
        for k, limit in enumerate((limits[0][i], limits[1][i])):
            if np.isfinite(limit):
                ax.axhline(
                    limit,
                    color="C3",
                    linestyle="--",
                    linewidth=1,
                    label="limit" if k == 0 else "_nolegend_",
                )
        unit = lin_unit if linear[i] else rot_unit
        ax.set_ylabel(
            f"{robot.joint_names[i]}\n[{unit}]", fontsize=9, rotation=0, ha="right", va="center"
        )
        ax.tick_params(labelsize=8)
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("t [s]")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    for ax in axes[1:, 0]:  # a limit line only some joints have
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
    fig.legend(handles, labels, loc="upper right", fontsize=9, ncol=2)
    fig.suptitle(title, x=0.02, ha="left", fontsize=11)
    fig.tight_layout(rect=(0, 0, 1, 0.97))
    return fig


def _stops(trajectory: Trajectory | ChainedTrajectory) -> NDArray[np.float64] | None:
    """The times where a chained motion (a task) stops between its parts, else None."""
    starts = getattr(trajectory, "starts", None)
    return None if starts is None else np.asarray(starts[1:])


def plot_torques(robot: Robot, trajectory: Trajectory, rate: float = 2000.0) -> Figure:
    """u_i(t) of a motion, one panel per joint, with its effort limits (Figs. 6-8).

    Parameters
    ----------
    robot
        The arm (its effort limits are drawn).
    trajectory
        The motion.
    rate
        Sampling rate of the curves [Hz]. The torque steps where the path's acceleration jumps
        (stage 1's knots): it is piecewise smooth, as the time-optimal control is.
    """
    samples = trajectory.sample(rate)
    lim = robot.limits
    return _joint_panels(
        robot,
        samples.t,
        samples.tau,
        (lim.effort_lower, lim.effort_upper),
        ("u", "N·m", "N"),
        f"{robot.name}: actuator torques and limits (te = {trajectory.duration:.4f} s)",
        _stops(trajectory),
    )


def plot_speeds(robot: Robot, trajectory: Trajectory, rate: float = 2000.0) -> Figure:
    """θ̇_i(t) of a motion, one panel per joint, with the speed limits ±v_i (what binds on most
    industrial arms).

    Parameters
    ----------
    robot
        The arm (its velocity limits are drawn).
    trajectory
        The motion.
    rate
        Sampling rate of the curves [Hz].
    """
    samples = trajectory.sample(rate)
    v = robot.limits.velocity
    return _joint_panels(
        robot,
        samples.t,
        samples.qd,
        (-v, v),
        ("θ̇", "rad/s", "m/s"),
        f"{robot.name}: joint speeds and limits (te = {trajectory.duration:.4f} s)",
        _stops(trajectory),
    )


def plot_accelerations(robot: Robot, trajectory: Trajectory, rate: float = 2000.0) -> Figure:
    """θ̈_i(t) of a motion, one panel per joint, with the acceleration limits ±a_i where the
    robot has any (:meth:`~nearopt.Robot.with_limits`)."""
    samples = trajectory.sample(rate)
    a = robot.limits.acceleration
    return _joint_panels(
        robot,
        samples.t,
        samples.qdd,
        (-a, a),
        ("θ̈", "rad/s²", "m/s²"),
        f"{robot.name}: joint accelerations and limits (te = {trajectory.duration:.4f} s)",
        _stops(trajectory),
    )


def plot_jerks(robot: Robot, trajectory: Motion, rate: float = 2000.0) -> Figure:
    """θ⃛_i(t) of a jerk-limited motion (one with a ``jerk(t)``: a
    :class:`~nearopt.timing.SmoothTrajectory` or a task of them), one panel per joint, with the
    jerk limits ±j_i."""
    t = np.linspace(0.0, trajectory.duration, max(2, int(trajectory.duration * rate) + 1))
    j = robot.limits.jerk
    return _joint_panels(
        robot,
        t,
        trajectory.jerk(t),  # type: ignore[attr-defined]
        (-j, j),
        ("d³θ/dt³", "rad/s³", "m/s³"),
        f"{robot.name}: joint jerks and limits (te = {trajectory.duration:.4f} s)",
        _stops(trajectory),
    )


def plot_torque_rates(robot: Robot, trajectory: Motion, rate: float = 2000.0) -> Figure:
    """u̇_i(t) of a motion (:func:`nearopt.verify.torque_rates`: central differences of its
    torques), one panel per joint, with the torque-rate limits ±r_i where the robot has any."""
    t = np.linspace(0.0, trajectory.duration, max(2, int(trajectory.duration * rate) + 1))
    rates = torque_rates(robot, trajectory, t)
    r = robot.limits.torque_rate
    return _joint_panels(
        robot,
        t,
        rates,
        (-r, r),
        ("du/dt", "N·m/s", "N/s"),
        f"{robot.name}: torque rates and limits (te = {trajectory.duration:.4f} s)",
        _stops(trajectory),
    )


def plot_workspace(
    robot: Robot,
    motions: dict[str, Trajectory],
    poses: int = 5,
    scene: Scene | None = None,
    targets: tuple[ToolPose, ...] = (),
) -> Figure:
    """The tip's path and ``poses`` link poses of each motion in the workspace (Figs. 3-5).

    The poses are drawn from light (t = 0) to dark (t = te) with their times written at the tip;
    start and goal are marked. A planar arm is drawn in its plane, any other in 3-D with equal
    axis scales.

    Parameters
    ----------
    robot
        The arm.
    motions
        Label → motion, e.g. ``{"initial": …, "final": …}``; one panel each.
    poses
        Link poses drawn per motion, evenly spaced in time.
    scene
        Obstacles: a planar arm's panels show their sections by its plane (orange).
    targets
        Tool poses: their positions are marked (a blue star, "target").
    """
    plt = _pyplot()
    tips = {label: tip_path(robot, traj) for label, traj in motions.items()}
    times = {label: np.linspace(0, traj.duration, poses) for label, traj in motions.items()}
    frames = {
        label: [chain_points(robot, q) for q in traj(times[label], 0)]
        for label, traj in motions.items()
    }
    everything = np.vstack([*tips.values(), *(c for f in frames.values() for c in f)])
    plane = plane_axes(everything)
    if plane is not None:

        def flat(p: NDArray[np.float64]) -> NDArray[np.float64]:
            return p @ plane.T
    else:

        def flat(p: NDArray[np.float64]) -> NDArray[np.float64]:
            return p

    low, high = everything.min(axis=0), everything.max(axis=0)
    centre, half = 0.5 * (low + high), 0.55 * float(np.max(high - low))
    fig = plt.figure(figsize=(5.2 * len(motions), 5.2))
    shades = np.linspace(0.75, 0.1, poses)
    for k, label in enumerate(motions):
        if plane is not None:
            ax = fig.add_subplot(1, len(motions), k + 1)
            ax.set_aspect("equal")
            ax.set_xlabel("in-plane horizontal [m]")
            ax.set_ylabel("up [m]")
        else:
            ax = fig.add_subplot(1, len(motions), k + 1, projection="3d")
            for axis, c in zip("xyz", centre, strict=True):  # equal scales: a cube
                getattr(ax, f"set_{axis}lim")(c - half, c + half)
            ax.set_box_aspect((1, 1, 1))
            ax.set_xlabel("x [m]")
            ax.set_ylabel("y [m]")
            ax.set_zlabel("z [m]")
        if plane is not None and scene is not None:
            origin = everything.mean(axis=0)
            for name, polygon in obstacle_sections(scene, origin, plane, half):
                ax.fill(*polygon.T, color="C1", alpha=0.45, linewidth=0)
                ax.text(
                    *polygon.mean(axis=0), name, fontsize=7, ha="center", color="C1", clip_on=True
                )
            ax.set_xlim(flat(centre)[0] - half, flat(centre)[0] + half)
            ax.set_ylim(flat(centre)[1] - half, flat(centre)[1] + half)
        for chain, shade, t in zip(frames[label], shades, times[label], strict=True):
            pts = flat(chain)
            ax.plot(*pts.T, "-o", color=str(shade), linewidth=1.5, markersize=3)
            ax.text(*pts[-1], f" {t:.2f} s", fontsize=7, color=str(shade))
        ax.plot(*flat(tips[label]).T, color="C3", linewidth=2, label="tip path")
        ends = flat(tips[label][[0, -1]])
        ax.scatter(*ends[:1].T, s=50, color="C2", zorder=5, label="start")
        ax.scatter(*ends[1:].T, s=50, color="k", marker="s", zorder=5, label="goal")
        if targets:
            spots = flat(np.array([t.position for t in targets]))
            ax.scatter(*spots.T, s=120, color="C0", marker="*", zorder=6, label="target")
        ax.set_title(f"{label} (te = {motions[label].duration:.3f} s)")
        ax.legend(loc="best", fontsize=8)
    fig.suptitle(f"{robot.name}: tip path and link poses (light: early, dark: late)")
    fig.tight_layout()
    return fig


def obstacle_sections(
    scene: Scene, origin: NDArray[np.float64], plane: NDArray[np.float64], extent: float
) -> list[tuple[str, NDArray[np.float64]]]:
    """Each obstacle's section by the plane through ``origin`` spanned by ``plane`` (right,
    up), as a polygon in the coordinates (x·right, x·up) [m] (those that cross the plane only);
    a half-space is clipped to a square of half-side 4 ``extent`` around ``origin``."""
    import trimesh

    from ..collision.scene import Box, Capsule, Cylinder, HalfSpace, Mesh, Sphere

    normal = np.cross(plane[0], plane[1])
    out = []
    for ob in scene.obstacles:
        shape = ob.shape
        if isinstance(shape, Box):
            mesh = trimesh.creation.box(shape.size)
        elif isinstance(shape, Sphere):
            mesh = trimesh.creation.icosphere(3, shape.radius)
        elif isinstance(shape, Cylinder):
            mesh = trimesh.creation.cylinder(shape.radius, shape.length, sections=48)
        elif isinstance(shape, Capsule):
            mesh = trimesh.creation.capsule(shape.length, shape.radius, count=(24, 24))
        elif isinstance(shape, Mesh):
            mesh = trimesh.load_mesh(shape.path, force="mesh").convex_hull
            mesh.apply_scale(shape.scale)
        elif isinstance(shape, HalfSpace):  # a big square of the plane, cut by the half-space
            side = 4.0 * extent
            corners = origin + side * np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) @ plane
            mesh = trimesh.Trimesh(corners, [[0, 1, 2], [0, 2, 3]])
            n = ob.rotation() @ np.asarray(shape.normal)
            d = shape.offset + n @ np.asarray(ob.position)
            sliced = trimesh.intersections.slice_mesh_plane(mesh, -n, n * d)
            if len(sliced.vertices):
                points = sliced.vertices @ plane.T
                out.append((ob.name, _hull(points)))
            continue
        else:
            continue
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = ob.rotation(), ob.position
        mesh.apply_transform(pose)
        lines = trimesh.intersections.mesh_plane(mesh, normal, origin)
        if len(lines):
            out.append((ob.name, _hull(lines.reshape(-1, 3) @ plane.T)))
    return out


def _hull(points: NDArray[np.float64]) -> NDArray[np.float64]:
    from scipy.spatial import ConvexHull

    return points[ConvexHull(points).vertices]


def plot_history(
    result: Plan,
    reference: dict[int, float] | None = None,
    reference_label: str = "paper, Table 2",
) -> Figure:
    """J^j over the iterations j (Table 2), optionally beside reference values.

    Parameters
    ----------
    result
        The plan.
    reference
        Iteration → J of another method (e.g. the paper's Table 2), drawn as squares.
    reference_label
        The legend's name for ``reference``.
    """
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6, 4))
    segments = result.segments if isinstance(result, TaskResult) else None
    if segments is None:
        j = [it.index for it in result.history]
        label = f"nearopt ({result.method})"
        ax.plot(j, [it.J for it in result.history], "-o", markersize=3, label=label)
    else:  # a task: one line per rest-to-rest segment
        for k, (seg, reached) in enumerate(zip(segments, result.segment_targets, strict=True)):
            ax.plot(
                [it.index for it in seg.history],
                [it.J for it in seg.history],
                "-o",
                markersize=3,
                label=f"segment {k + 1} (to {reached[-1].name})",
            )
    if reference:
        ax.plot(list(reference), list(reference.values()), "s", color="C1", label=reference_label)
    ax.set_xlabel("iteration $j$")
    ax.set_ylabel("$J^j$")
    ax.grid(alpha=0.3)
    ax.legend()
    if segments is None:
        ax.set_title(f"{result.robot.name}: $J$ = {result.J:.6f} after {len(j) - 1} iterations")
    else:
        ax.set_title(f"{result.robot.name}: $J$ = {result.J:.6f} over {len(segments)} segments")
    fig.tight_layout()
    return fig


def render_figures(result: Plan, reference: dict[int, float] | None = None) -> dict[str, bytes]:
    """torques.png, speeds.png (accelerations.png if the robot has acceleration or jerk limits,
    jerks.png if it has jerk limits, torque_rates.png if it has torque-rate limits),
    workspace.png and history.png of a plan, as PNG bytes by file name."""
    check_plan(result)
    plt = _pyplot()
    robot, traj = result.robot, result.trajectory
    figures = {
        "torques.png": plot_torques(robot, traj),
        "speeds.png": plot_speeds(robot, traj),
    }
    if np.any(np.isfinite(robot.limits.acceleration) | np.isfinite(robot.limits.jerk)):
        figures["accelerations.png"] = plot_accelerations(robot, traj)
    if np.any(np.isfinite(robot.limits.jerk)) and hasattr(traj, "jerk"):
        figures["jerks.png"] = plot_jerks(robot, traj)
    if np.any(np.isfinite(robot.limits.torque_rate)):
        figures["torque_rates.png"] = plot_torque_rates(robot, traj)
    figures["workspace.png"] = plot_workspace(
        robot,
        {"initial": result.initial_trajectory, "final": traj},
        scene=None if result.collisions is None else result.collisions.scene,
        targets=target_poses(result),
    )
    figures["history.png"] = plot_history(result, reference)
    rendered = {}
    for name, fig in figures.items():
        buffer = io.BytesIO()
        fig.savefig(buffer, format="png", dpi=120)
        plt.close(fig)
        rendered[name] = buffer.getvalue()
    return rendered


def save_figures(
    result: Plan, folder: str | Path, reference: dict[int, float] | None = None
) -> list[Path]:
    """Write the figures of :func:`render_figures` for a plan into ``folder`` (made if it is
    missing, with its parents).

    Raises
    ------
    ConfigurationError
        If ``folder`` is a file or cannot be made.
    """
    check_plan(result)  # before the folder is made
    folder = make_folder(folder, "figures")
    return [
        write_atomically(folder / name, png)
        for name, png in render_figures(result, reference).items()
    ]
