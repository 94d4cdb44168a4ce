"""Goals given as tool poses: a placement of a robot frame, reached by inverse kinematics inside
the joint limits.

The target is a position p* [m] and optionally an orientation (unit quaternion qx, qy, qz, qw, in
the base frame). :func:`inverse_kinematics` runs damped least squares (Levenberg-Marquardt) on the
placement error e = log₆(M(θ)⁻¹ M*) (or p* − p(θ) for a position only) with Pinocchio's frame
Jacobian, θ projected onto the position limits after every step, from the seed and then from
seeded random configurations, until |e| ≤ 1e-10 (m and rad).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin

from ..errors import ConfigurationError, UnreachablePoseError
from .dynamics import check_robot

if TYPE_CHECKING:
    from numpy.typing import ArrayLike, NDArray

    from .dynamics import Robot

__all__ = ["ToolPose", "inverse_kinematics", "nearest_turn", "pose_error", "task_jacobian"]


@dataclass(frozen=True)
class ToolPose:
    """A target placement of a frame of the robot.

    Attributes
    ----------
    position
        The frame's origin in the base frame [m], shape (3,).
    quaternion
        Its orientation (qx, qy, qz, qw), normalised on construction; None: position only.
    frame
        The frame (a link or any frame of the URDF); None: the robot's tip.
    """

    position: tuple[float, float, float]
    quaternion: tuple[float, float, float, float] | None = None
    frame: str | None = None

    def __post_init__(self) -> None:
        p = _floats(self.position, 3, "a tool position is 3 finite numbers [m]")
        object.__setattr__(self, "position", tuple(float(x) for x in p))
        if self.quaternion is not None:
            message = (
                "a tool orientation is a non-zero quaternion of 4 finite numbers (qx, qy, qz, qw)"
            )
            q = _floats(self.quaternion, 4, message)
            q = q / np.max(np.abs(q)) if np.any(q != 0.0) else q  # no overflow in the norm
            if np.linalg.norm(q) < 1e-9:
                raise ConfigurationError(f"{message}, got {self.quaternion!r}")
            object.__setattr__(self, "quaternion", tuple(float(x) for x in q / np.linalg.norm(q)))
        if self.frame is not None and (not isinstance(self.frame, str) or not self.frame):
            raise ConfigurationError(f"a frame is given by its name, got {self.frame!r}")

    def placement(self) -> pin.SE3:
        """The target as a Pinocchio placement (identity rotation for a position only)."""
        rotation = np.eye(3)
        if self.quaternion is not None:
            qx, qy, qz, qw = self.quaternion
            rotation = pin.Quaternion(qw, qx, qy, qz).toRotationMatrix()
        return pin.SE3(rotation, np.asarray(self.position))


def _floats(value: object, size: int, message: str) -> NDArray[np.float64]:
    """``value`` as ``size`` finite floats, or a ConfigurationError with ``message``."""
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        a = np.zeros(0)
    if isinstance(value, str | bytes) or a.shape != (size,) or not np.all(np.isfinite(a)):
        raise ConfigurationError(f"{message}, got {value!r}")
    return a


def pose_error(robot: Robot, q: ArrayLike, pose: ToolPose) -> tuple[float, float]:
    """Distance [m] and angle [rad] between the frame at θ and the target (angle 0 for a
    position-only target)."""
    placement = robot.frame_placement(q, pose.frame)
    target = pose.placement()
    distance = float(np.linalg.norm(placement.translation - target.translation))
    if pose.quaternion is None:
        return distance, 0.0
    angle = float(np.linalg.norm(pin.log3(placement.rotation.T @ target.rotation)))
    return distance, angle


def task_jacobian(robot: Robot, pose: ToolPose, q: ArrayLike) -> NDArray[np.float64]:
    """The pose's frame Jacobian at θ: 6 × n in the frame (a full pose), 3 × n with world axes
    (a position); a step Δθ in its null space keeps the frame at the pose to first order."""
    model, data = robot.model, robot.new_data()
    fid = robot.frame_id(pose.frame)
    pin.computeJointJacobians(model, data, robot.check_configuration(q))
    pin.updateFramePlacements(model, data)
    if pose.quaternion is None:
        return _frame_jacobian(model, data, fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)[:3]
    return _frame_jacobian(model, data, fid, pin.ReferenceFrame.LOCAL)


def _frame_jacobian(
    model: pin.Model, data: pin.Data, fid: int, frame: pin.ReferenceFrame
) -> NDArray[np.float64]:
    """Pinocchio's frame Jacobian as 6 × n (of a one-joint arm it returns a vector)."""
    return np.asarray(pin.getFrameJacobian(model, data, fid, frame)).reshape(6, model.nv)


def inverse_kinematics(
    robot: Robot,
    pose: ToolPose,
    *,
    seed: ArrayLike | None = None,
    attempts: int = 30,
    iterations: int = 200,
    tolerance: float = 1e-10,
) -> NDArray[np.float64]:
    """A configuration θ within the position limits that puts ``pose.frame`` at the target.

    Parameters
    ----------
    robot
        The arm.
    pose
        The target.
    seed
        First guess [rad or m], shape (n,) (e.g. the motion's start); later attempts start from
        configurations drawn uniformly within the limits (seeded: the result is reproducible).
        The solution's revolute joints are then turned by whole turns to lie nearest the seed
        (:func:`nearest_turn`).
    attempts
        Starts tried.
    iterations
        Damped least-squares steps per start.
    tolerance
        Accepted |e| [m and rad] (the target is met to it).

    Raises
    ------
    UnreachablePoseError
        When no start converges: the message gives how far the best placement found is from the
        target, in metres and radians.
    ConfigurationError
        An unknown frame (the message lists the frames).
    """
    check_robot(robot)
    for name, value in (("attempts", attempts), ("iterations", iterations)):
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ConfigurationError(f"{name} must be a positive integer, got {value!r}")
    if not isinstance(pose, ToolPose):
        raise ConfigurationError(
            f"pose must be a nearopt.ToolPose (position [m], optional quaternion, frame), got "
            f"{type(pose).__name__} {pose!r:.60}"
        )
    model, data = robot.model, robot.new_data()
    fid = robot.frame_id(pose.frame)
    lim = robot.limits
    lower, upper = lim.sampling_box()
    rng = np.random.default_rng(20261123)
    target = pose.placement()
    full = pose.quaternion is not None
    starts = [] if seed is None else [robot.check_configuration(seed, "seed")]
    best: tuple[float, NDArray[np.float64]] | None = None
    for k in range(attempts):
        q = np.clip(
            starts[k] if k < len(starts) else rng.uniform(lower, upper),
            lim.position_lower,
            lim.position_upper,
        )
        damping = 1e-3
        for _ in range(iterations):
            err, jac = _error(model, data, fid, q, target, full)
            norm = float(np.linalg.norm(err))
            if best is None or norm < best[0]:
                best = (norm, q.copy())
            if norm <= tolerance:
                return q if not starts else nearest_turn(robot, q, starts[0])
            step = np.linalg.solve(jac.T @ jac + damping * np.eye(robot.n), jac.T @ err)
            trial = np.clip(q + step, lim.position_lower, lim.position_upper)
            if np.linalg.norm(_error(model, data, fid, trial, target, full)[0]) < norm:
                q, damping = trial, max(damping / 3.0, 1e-9)
            else:
                damping *= 10.0
                if damping > 1e6:
                    break
    assert best is not None
    distance, angle = pose_error(robot, best[1], pose)
    where = f"{pose.frame or robot.tip!r}"
    raise UnreachablePoseError(
        f"{robot.name} cannot put {where} at {list(pose.position)}"
        + (f" with orientation {list(pose.quaternion)}" if full else "")
        + f" within its joint limits: the closest placement found is {distance:.4g} m"
        + (f" and {angle:.4g} rad" if full else "")
        + " away",
        distance=distance,
        angle=angle,
    )


def nearest_turn(
    robot: Robot, q: NDArray[np.float64], reference: NDArray[np.float64]
) -> NDArray[np.float64]:
    """``q`` with each revolute joint turned by whole turns (2π rad) to lie nearest its value
    in ``reference`` within the position limits: every link where ``q`` puts it. A pose goal
    solved from θ0 came out with ur5 joints a turn away from θ0 (J 2.2 times the motion to the
    nearer turn: stage 2 cannot leave the turn it starts in)."""
    lim = robot.limits
    out = q.copy()
    turn = 2.0 * np.pi
    for i in np.flatnonzero(~robot.prismatic):
        k = np.round((reference[i] - q[i]) / turn)
        shifted = q[i] + np.array([0.0, k - 1.0, k, k + 1.0]) * turn
        inside = shifted[(shifted >= lim.position_lower[i]) & (shifted <= lim.position_upper[i])]
        out[i] = inside[np.argmin(np.abs(inside - reference[i]))]
    return out


def _error(
    model: pin.Model,
    data: pin.Data,
    fid: int,
    q: NDArray[np.float64],
    target: pin.SE3,
    full: bool,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The placement error e and de/dθ (so that θ + Δθ with J Δθ = e reduces it)."""
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    current = data.oMf[fid]
    if not full:
        jac = _frame_jacobian(model, data, fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)[:3]
        return target.translation - current.translation, jac
    error = current.actInv(target)  # M⁻¹ M*
    jac = _frame_jacobian(model, data, fid, pin.ReferenceFrame.LOCAL)
    return pin.log6(error).vector, pin.Jlog6(error.inverse()) @ jac
