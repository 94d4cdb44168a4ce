"""A planned motion in ROS 2's terms: ``trajectory_msgs/JointTrajectory``, the YAML of a
``control_msgs/action/FollowJointTrajectory`` goal, and a rosbag2 (MCAP storage) with the
trajectory, the joint states and the tool frame — written without a ROS installation (``mcap`` and
``mcap-ros2-support``).

Two ways to put a motion into points (:func:`joint_trajectory`):

- at a controller ``rate`` [Hz]: t = 0, 1/rate, …, t_e (the last step shorter), as the JSON;
- at its own knots (``rate=None``): the times where its acceleration may jump, with intervals
  halved until the interpolation ``joint_trajectory_controller`` applies between points given
  with positions, velocities and accelerations — a quintic polynomial per joint matching all
  three at both ends (its ``splines`` interpolation) — stays within ``tolerance`` [rad or m] of
  the motion at 16 points inside every interval (:func:`interpolate` is that polynomial). A
  stage-1 motion's acceleration jumps at its knots: the points gather around them.

Every point carries positions, velocities, accelerations and the torques as ``effort`` (a
feed-forward for controllers that take one), and ``time_from_start`` to the nanosecond.
"""

from __future__ import annotations

import io
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml
from numpy.typing import NDArray

from .errors import ConfigurationError
from .export import check_record, check_sampling
from .outputs import write_atomically
from .planning import Plan
from .validate import check_rate, is_number

__all__ = [
    "JointTrajectory",
    "joint_trajectory",
    "interpolate",
    "goal_yaml",
    "write_ros_bag",
    "bag_files",
    "check_bag_folder",
    "replace_folder",
    "BagContents",
]

SHORTEST = 1e-6
"""Intervals this short [s] are not halved further (the points' times are whole nanoseconds)."""

MAX_POINTS = 1_000_000
"""The most points :func:`joint_trajectory` makes at the motion's knots (each refinement halves
the intervals that need it)."""


@dataclass(frozen=True)
class JointTrajectory:
    """A ``trajectory_msgs/msg/JointTrajectory``: P points of n joints.

    Attributes
    ----------
    joint_names
        The URDF's joint names, in the order of every vector.
    time_from_start
        Each point's time [ns], shape (P,), from 0 to t_e.
    positions, velocities, accelerations, effort
        θ [rad or m], θ̇, θ̈ and u [N·m or N] at the points, shape (P, n).
    """

    joint_names: tuple[str, ...]
    time_from_start: NDArray[np.int64]
    positions: NDArray[np.float64]
    velocities: NDArray[np.float64]
    accelerations: NDArray[np.float64]
    effort: NDArray[np.float64]

    @property
    def seconds(self) -> NDArray[np.float64]:
        """time_from_start [s]."""
        return self.time_from_start * 1e-9

    def message(self, stamp_ns: int = 0, frame_id: str = "") -> dict[str, object]:
        """The message as mcap-ros2-support and ``ros2 topic pub`` take it (header stamp 0: the
        controller starts it on receipt)."""
        return {
            "header": {"stamp": _time(stamp_ns), "frame_id": frame_id},
            "joint_names": list(self.joint_names),
            "points": [
                {
                    "positions": self.positions[k].tolist(),
                    "velocities": self.velocities[k].tolist(),
                    "accelerations": self.accelerations[k].tolist(),
                    "effort": self.effort[k].tolist(),
                    "time_from_start": _time(int(self.time_from_start[k])),
                }
                for k in range(self.time_from_start.size)
            ],
        }


def _time(ns: int) -> dict[str, int]:
    """builtin_interfaces Time/Duration of ``ns`` ≥ 0 nanoseconds."""
    sec, nanosec = divmod(int(ns), 1_000_000_000)
    return {"sec": sec, "nanosec": nanosec}


def joint_trajectory(
    result: Plan, rate: float | None = None, tolerance: float = 1e-6
) -> JointTrajectory:
    """The plan's motion as a JointTrajectory: at ``rate`` [Hz], or (None) at its own knots,
    refined until the quintic interpolation between points is within ``tolerance`` of the
    motion (see the module docstring).

    Raises
    ------
    ConfigurationError
        A rate that is not a number of Hz in (0, 1e6], a tolerance that is not a positive
        number, or more than :data:`MAX_POINTS` points.
    """
    motion = result.trajectory
    if rate is not None:
        check_record(result, rate)
        samples = motion.sample(rate)  # (check_record checked the rate)
        t, q, qd, qdd, u = samples.t, samples.q, samples.qd, samples.qdd, samples.tau
    else:
        if not (is_number(tolerance) and np.isfinite(tolerance) and tolerance > 0):
            raise ConfigurationError(f"tolerance must be a positive number, got {tolerance!r}")
        t = _refined(motion, tolerance)
        q, qd, qdd = motion.states(t)
        u = motion.torque(t)
    names = tuple(result.robot.joint_names)
    ns = np.rint(np.asarray(t) * 1e9).astype(np.int64)
    return JointTrajectory(names, ns, q, qd, qdd, u)


def _refined(motion, tolerance: float) -> NDArray[np.float64]:  # noqa: ANN001 - a Motion
    """Times from the motion's knots (and 0, t_e) with every interval halved until the quintic
    through its ends is within ``tolerance`` at 16 points inside it (or it is
    :data:`SHORTEST`)."""
    duration = motion.duration
    t = np.unique(np.concatenate([[0.0], np.asarray(motion.t, dtype=float), [duration]]))
    t = t[(t >= 0.0) & (t <= duration)]
    inside = np.linspace(0.0, 1.0, 18)[1:-1]
    while True:
        q, qd, qdd = motion.states(t)
        left, right = t[:-1], t[1:]
        at = (left[:, None] + inside[None, :] * (right - left)[:, None]).ravel()
        ends = (q[:-1], qd[:-1], qdd[:-1], q[1:], qd[1:], qdd[1:])
        guess = interpolate(left, right, *ends, at.reshape(-1, inside.size))
        error = np.abs(guess - motion.states(at)[0].reshape(guess.shape))
        bad = (np.max(error, axis=(1, 2)) > tolerance) & (right - left > SHORTEST)
        if not np.any(bad):
            return t
        if t.size + np.count_nonzero(bad) > MAX_POINTS:
            raise ConfigurationError(
                f"the motion needs more than {MAX_POINTS} points for the interpolation to be "
                f"within {tolerance:g} of it: give a rate or a larger tolerance"
            )
        t = np.sort(np.concatenate([t, 0.5 * (left[bad] + right[bad])]))


def interpolate(
    t0: NDArray,
    t1: NDArray,
    p0,
    v0,
    a0,
    p1,
    v1,
    a1,
    t: NDArray,  # noqa: ANN001
) -> NDArray[np.float64]:
    """The quintic polynomial matching position, velocity and acceleration at both ends of each
    interval [t0_k, t1_k] (shapes (K,), the states (K, n)) at times t (K, M): shape (K, M, n) —
    what joint_trajectory_controller's spline interpolation does between two points that give
    all three."""
    h = (t1 - t0)[:, None, None]
    x = ((t - t0[:, None]) / (t1 - t0)[:, None])[..., None]
    p0, v0, a0, p1, v1, a1 = (np.asarray(v)[:, None, :] for v in (p0, v0, a0, p1, v1, a1))
    v0, v1, a0, a1 = v0 * h, v1 * h, a0 * h**2, a1 * h**2  # in x ∈ [0, 1]
    c3 = 10 * (p1 - p0) - 6 * v0 - 4 * v1 - 1.5 * a0 + 0.5 * a1
    c4 = -15 * (p1 - p0) + 8 * v0 + 7 * v1 + 1.5 * a0 - a1
    c5 = 6 * (p1 - p0) - 3 * v0 - 3 * v1 - 0.5 * a0 + 0.5 * a1
    return p0 + x * (v0 + x * (0.5 * a0 + x * (c3 + x * (c4 + x * c5))))


def goal_yaml(trajectory: JointTrajectory) -> str:
    """The YAML of a ``control_msgs/action/FollowJointTrajectory`` goal holding the trajectory,
    as ``ros2 action send_goal <controller>/follow_joint_trajectory
    control_msgs/action/FollowJointTrajectory "$(cat FILE)"`` takes it (the value of
    ``trajectory`` is the JointTrajectory ``ros2 topic pub <controller>/joint_trajectory
    trajectory_msgs/msg/JointTrajectory`` takes)."""
    message = trajectory.message()
    return yaml.safe_dump({"trajectory": message}, sort_keys=False, default_flow_style=None)


@dataclass(frozen=True)
class BagContents:
    """A bag's files (name → content) and its messages per topic."""

    name: str
    files: dict[str, bytes | str]
    messages: dict[str, int]


BAG_SUFFIXES = (".mcap", ".db3", ".zstd")
"""The storage files a rosbag2 folder holds beside its ``metadata.yaml`` (MCAP, SQLite 3, and
either compressed)."""


def check_bag_folder(folder: str | Path) -> Path:
    """``folder`` as a place for a bag: refused if it exists and is neither empty nor a rosbag2
    folder — its ``metadata.yaml`` and storage files (:data:`BAG_SUFFIXES`) and nothing else —
    (what it holds would be replaced, and lost), or if this process runs in it (the current
    folder, or one inside it: it cannot be replaced).

    Raises
    ------
    ConfigurationError
        Naming the folder (and what else it holds).
    """
    folder = Path(folder)
    if str(folder) in ("", "-"):
        raise ConfigurationError(f"a bag is a folder: give its path, got {str(folder)!r}")
    here = Path.cwd().resolve()
    if folder.exists() and (folder.resolve() == here or folder.resolve() in here.parents):
        raise ConfigurationError(
            f"{folder} is the folder this command runs in (or holds it): a bag replaces its "
            "folder whole; give a folder of its own"
        )
    if folder.exists() and not folder.is_dir():
        raise ConfigurationError(f"{folder} exists and is not a folder: a bag is a folder")
    if folder.exists() and any(folder.iterdir()):
        if not (folder / "metadata.yaml").is_file():
            raise ConfigurationError(
                f"{folder} exists and is not a rosbag2 folder: it would be replaced; give another"
            )
        other = sorted(
            p.name
            for p in folder.iterdir()
            if p.name != "metadata.yaml" and not (p.is_file() and p.suffix in BAG_SUFFIXES)
        )
        if other:
            raise ConfigurationError(
                f"{folder} holds {other[0]!r}"
                + (f" and {len(other) - 1} more" if len(other) > 1 else "")
                + " besides a bag: the bag replaces the folder whole; give another"
            )
    return folder


def bag_files(
    result: Plan,
    name: str,
    rate: float = 1000.0,
    start_ns: int | None = None,
    trajectory: JointTrajectory | None = None,
) -> BagContents:
    """The files of the bag :func:`write_ros_bag` writes, not yet written (``name``: the folder's
    name, which the MCAP file takes)."""
    from mcap_ros2.writer import Writer

    from .ros_messages import DEFINITIONS

    check_record(result, rate)
    rate = check_rate(rate)
    check_sampling(result, rate)
    robot = result.robot
    if trajectory is None:
        trajectory = joint_trajectory(result)
    samples = result.trajectory.sample(rate)
    start = time.time_ns() if start_ns is None else int(start_ns)
    stamps = start + np.rint(samples.t * 1e9).astype(np.int64)
    base = next(iter(robot.link_placements(samples.q[0])))
    buffer = io.BytesIO()
    writer = Writer(buffer)
    schemas = {kind: writer.register_msgdef(kind, text) for kind, text in DEFINITIONS.items()}
    counts = {"/joint_trajectory": 1, "/joint_states": stamps.size, "/tf": stamps.size}
    writer.write_message(
        "/joint_trajectory",
        schemas[TYPES["/joint_trajectory"]],
        trajectory.message(),
        log_time=start,
        publish_time=start,
    )
    names = list(robot.joint_names)
    for k, stamp in enumerate(stamps.tolist()):
        writer.write_message(
            "/joint_states",
            schemas[TYPES["/joint_states"]],
            {
                "header": {"stamp": _time(stamp), "frame_id": ""},
                "name": names,
                "position": samples.q[k].tolist(),
                "velocity": samples.qd[k].tolist(),
                "effort": samples.tau[k].tolist(),
            },
            log_time=stamp,
            publish_time=stamp,
            sequence=k,
        )
        writer.write_message(
            "/tf",
            schemas[TYPES["/tf"]],
            {"transforms": [_tool_transform(robot, samples.q[k], stamp, base)]},
            log_time=stamp,
            publish_time=stamp,
            sequence=k,
        )
    writer.finish()
    files = {
        f"{name}_0.mcap": buffer.getvalue(),
        "metadata.yaml": _metadata(name, start, int(stamps[-1]), counts),
    }
    return BagContents(name, files, counts)


def write_ros_bag(
    result: Plan,
    folder: str | Path,
    rate: float = 1000.0,
    start_ns: int | None = None,
    trajectory: JointTrajectory | None = None,
) -> BagContents:
    """A rosbag2 in MCAP storage (``folder``/metadata.yaml and ``folder``/<name>_0.mcap) with

    - ``/joint_trajectory`` (trajectory_msgs/msg/JointTrajectory): ``trajectory``, default the
      motion at its knots (:func:`joint_trajectory`), once at the start;
    - ``/joint_states`` (sensor_msgs/msg/JointState) at ``rate`` [Hz]: θ, θ̇ and u;
    - ``/tf`` (tf2_msgs/msg/TFMessage) at ``rate``: the tool frame (the robot's tip) in its
      root link's frame.

    Stamps from ``start_ns`` [ns since the epoch; default now]. The folder is replaced as a
    whole (written beside it, then renamed into place).

    Warns (:class:`~nearopt.SamplingWarning`) if the rate is too low to resolve the motion, as
    the JSON does.

    Raises
    ------
    ConfigurationError
        A rate that is not a number of Hz in (0, 1e6] or that gives more samples than a JSON
        record may hold (:func:`~nearopt.export.check_record`), or a folder that exists and is
        not a rosbag2 (it would be lost).
    """
    folder = check_bag_folder(folder)
    contents = bag_files(result, folder.resolve().name, rate, start_ns, trajectory)
    replace_folder(folder, contents.files)
    return contents


def _tool_transform(robot, q: NDArray, stamp: int, base: str) -> dict[str, object]:  # noqa: ANN001
    """geometry_msgs/TransformStamped: the tip in the root link's frame at θ = q."""
    pose = robot.frame_placement(q)
    x, y, z, w = _quaternion(np.asarray(pose.rotation))
    translation = np.asarray(pose.translation).tolist()
    return {
        "header": {"stamp": _time(stamp), "frame_id": base},
        "child_frame_id": robot.tip,
        "transform": {
            "translation": dict(zip("xyz", translation, strict=True)),
            "rotation": {"x": x, "y": y, "z": z, "w": w},
        },
    }


TYPES = {
    "/joint_trajectory": "trajectory_msgs/msg/JointTrajectory",
    "/joint_states": "sensor_msgs/msg/JointState",
    "/tf": "tf2_msgs/msg/TFMessage",
}


def _metadata(name: str, start: int, end: int, counts: dict[str, int]) -> str:
    """rosbag2's metadata.yaml (version 5: read by Humble and later, and by ``rosbags``)."""
    total = sum(counts.values())
    info = {
        "version": 5,
        "storage_identifier": "mcap",
        "duration": {"nanoseconds": end - start},
        "starting_time": {"nanoseconds_since_epoch": start},
        "message_count": total,
        "topics_with_message_count": [
            {
                "topic_metadata": {
                    "name": topic,
                    "type": TYPES[topic],
                    "serialization_format": "cdr",
                    "offered_qos_profiles": "",
                },
                "message_count": count,
            }
            for topic, count in counts.items()
        ],
        "compression_format": "",
        "compression_mode": "",
        "relative_file_paths": [f"{name}_0.mcap"],
        "files": [
            {
                "path": f"{name}_0.mcap",
                "starting_time": {"nanoseconds_since_epoch": start},
                "duration": {"nanoseconds": end - start},
                "message_count": total,
            }
        ],
    }
    return yaml.safe_dump({"rosbag2_bagfile_information": info}, sort_keys=False)


def replace_folder(folder: Path, files: dict[str, bytes | str]) -> None:
    """``folder`` with exactly ``files``: written into a new folder beside it, then swapped in
    (an old bag is removed only once the new one is complete)."""
    import secrets
    import shutil
    import tempfile

    parent = folder.resolve().parent
    parent.mkdir(parents=True, exist_ok=True)
    fresh = parent / f".{folder.name}.{secrets.token_hex(6)}"
    fresh.mkdir()  # (the user's umask, as the folder it replaces)
    try:
        for file, content in files.items():
            write_atomically(fresh / file, content)
        if folder.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{folder.name}.old.", dir=parent))
            old.rmdir()
            folder.rename(old)
            fresh.rename(folder)
            shutil.rmtree(old)
        else:
            fresh.rename(folder)
    except BaseException:
        shutil.rmtree(fresh, ignore_errors=True)
        raise


def _quaternion(rotation: NDArray[np.float64]) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation matrix (Pinocchio's conversion)."""
    import pinocchio as pin

    coeffs = pin.Quaternion(rotation).coeffs()  # x, y, z, w
    return float(coeffs[0]), float(coeffs[1]), float(coeffs[2]), float(coeffs[3])
