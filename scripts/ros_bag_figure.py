"""A plan's rosbag2 read back by an independent reader and plotted (#27): the README's figure.

Plans the ur5 example (time-optimal, URDF limits), writes its bag (``nearopt.ros.write_ros_bag``:
MCAP storage, 500 Hz), reads it back with the ``rosbags`` library and plots, against the bag's
own stamps, the joint positions of ``/joint_states`` with the points of the
``/joint_trajectory`` message on them, and the tool frame's position from ``/tf``.

    python scripts/ros_bag_figure.py [--out scripts/figures/ros_bag.png]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from rosbags.highlevel import AnyReader  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402

import nearopt  # noqa: E402
from nearopt.ros import write_ros_bag  # noqa: E402

START = 1_767_225_600_000_000_000  # 2026-01-01 00:00 UTC [ns]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="scripts/figures/ros_bag.png")
    args = parser.parse_args()
    robot = nearopt.Robot.from_name("ur5")
    q0, qe = np.array([0, -1.5, 1.5, 0, 0, 0.0]), np.array([1.5, -1.0, 1.0, 0.5, 0.5, 0.5])
    result = nearopt.plan(robot, q0, qe, nearopt.TimeCost())
    with tempfile.TemporaryDirectory() as folder:
        bag = Path(folder) / "ur5_plan"
        write_ros_bag(result, bag, rate=500.0, start_ns=START)
        states, tool, points = [], [], None
        with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
            for connection, stamp, raw in reader.messages():
                msg = reader.deserialize(raw, connection.msgtype)
                t = (stamp - START) * 1e-9
                if connection.topic == "/joint_states":
                    states.append((t, msg.position))
                elif connection.topic == "/tf":
                    moved = msg.transforms[0].transform.translation
                    tool.append((t, (moved.x, moved.y, moved.z)))
                else:
                    points = msg
    t = np.array([s[0] for s in states])
    q = np.array([s[1] for s in states])
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4), layout="constrained")
    times = np.array(
        [p.time_from_start.sec + 1e-9 * p.time_from_start.nanosec for p in points.points]
    )
    at = np.array([p.positions for p in points.points])
    for j, name in enumerate(points.joint_names):
        (line,) = left.plot(t, q[:, j], label=name)
        left.plot(times, at[:, j], ".", color=line.get_color(), markersize=3)
    left.set(
        xlabel="t [s] (the bag's stamps)",
        ylabel="θ [rad]",
        title=f"/joint_states at 500 Hz, /joint_trajectory's {len(times)} points (dots)",
    )
    left.legend(fontsize=7)
    xyz = np.array([p[1] for p in tool])
    for k, axis in enumerate("xyz"):
        right.plot([p[0] for p in tool], xyz[:, k], label=axis)
    right.set(xlabel="t [s]", ylabel="[m]", title=f"/tf: {robot.tip} in the base frame")
    right.legend()
    fig.suptitle("ur5 plan written as a rosbag2 (MCAP) by nearopt, read back with rosbags")
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}: {len(states)} joint states, {len(times)} trajectory points")


if __name__ == "__main__":
    main()
