"""Geometry of a motion shared by the figures and the viewer: the tip's path, the links' centre
lines, the plane of a planar arm (numpy only)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from ..robot import Robot
    from ..trajectory import Trajectory

__all__ = ["plane_axes", "tip_path", "chain_points"]


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
