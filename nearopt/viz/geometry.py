"""Geometry of a motion shared by the figures and the viewer: the tip's path, the links' centre
lines, the plane of a planar arm (numpy only)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from ..planning import PlanResult, TaskResult
    from ..robot import Robot
    from ..robot.kinematics import ToolPose
    from ..trajectory import Trajectory

__all__ = ["plane_axes", "tip_path", "chain_points", "target_poses"]


def target_poses(result: PlanResult | TaskResult) -> tuple[ToolPose, ...]:
    """The placements a plan was asked to reach, in order: its via-points (a task: its
    targets) and its goal pose. A tool-pose target as given; a joint-vector via-point or target
    as the tip's placement there (the goal as joint values is not marked: it is the end pose)."""
    import pinocchio as pin

    from ..robot.kinematics import ToolPose

    robot = result.robot

    def at(q: NDArray[np.float64]) -> ToolPose:
        m = robot.frame_placement(q)
        quat = pin.Quaternion(m.rotation)
        return ToolPose(m.translation, (quat.x, quat.y, quat.z, quat.w))

    targets = getattr(result, "targets", None)
    if targets is not None:  # a task: every target but a last one given as joint values
        out = [
            t.goal if isinstance(t.goal, ToolPose) else at(q)
            for t, q in zip(targets, result.target_configurations, strict=True)
        ]
        return tuple(out if isinstance(targets[-1].goal, ToolPose) else out[:-1])
    out = [at(q) for q in result.via]
    return (*out, result.goal) if result.goal is not None else tuple(out)


def chain_points(robot: Robot, q: NDArray[np.float64]) -> NDArray[np.float64]:
    """Positions of the moving joints' frames and of the tip (the links' centre lines)."""
    placements = robot.link_placements(q)
    points = [m[:3, 3] for m in placements.values()]
    return np.array([*points, robot.frame_position(q)])


def plane_axes(points: NDArray[np.float64]) -> NDArray[np.float64] | None:
    """Screen axes (right, up) of the points' plane seen from its −y side, or None if not planar.

    "Up" is world z projected into the plane (when the plane is not horizontal), as in the
    paper's Fig. 2 of the vertical two-link arm.
    """
    centred = points - points.mean(axis=0)
    _, sv, vt = np.linalg.svd(centred, full_matrices=False)
    if sv[-1] >= 1e-6 * max(sv[0], 1e-12):
        return None
    normal = vt[2] if vt[2] @ [0.0, -1.0, 0.0] >= 0 else -vt[2]  # towards the viewer
    up = np.array([0.0, 0.0, 1.0]) - normal[2] * normal
    up = up / np.linalg.norm(up) if np.linalg.norm(up) > 0.1 else vt[1]
    return np.array([np.cross(up, normal), up])


def tip_path(robot: Robot, trajectory: Trajectory, points: int = 300) -> NDArray[np.float64]:
    """The tip's position [m] at ``points`` evenly spaced times of the motion, shape (points, 3)."""
    return robot.frame_position(trajectory(np.linspace(0, trajectory.duration, points), 0))
