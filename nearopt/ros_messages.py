"""The ROS 2 message definitions a nearopt bag uses (``ros2msg`` schemas, each followed by the
definitions it depends on, as rosbag2 writes them into MCAP), from the interfaces of
builtin_interfaces, std_msgs, trajectory_msgs, sensor_msgs, geometry_msgs and tf2_msgs."""

from __future__ import annotations

__all__ = ["DEFINITIONS"]

_SEPARATOR = "=" * 80 + "\n"

_PLAIN = {
    "builtin_interfaces/Time": "int32 sec\nuint32 nanosec\n",
    "builtin_interfaces/Duration": "int32 sec\nuint32 nanosec\n",
    "std_msgs/Header": "builtin_interfaces/Time stamp\nstring frame_id\n",
    "trajectory_msgs/JointTrajectoryPoint": (
        "float64[] positions\nfloat64[] velocities\nfloat64[] accelerations\n"
        "float64[] effort\nbuiltin_interfaces/Duration time_from_start\n"
    ),
    "trajectory_msgs/JointTrajectory": (
        "std_msgs/Header header\nstring[] joint_names\nJointTrajectoryPoint[] points\n"
    ),
    "sensor_msgs/JointState": (
        "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\n"
        "float64[] effort\n"
    ),
    "geometry_msgs/Vector3": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/Quaternion": "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    "geometry_msgs/Transform": "Vector3 translation\nQuaternion rotation\n",
    "geometry_msgs/TransformStamped": (
        "std_msgs/Header header\nstring child_frame_id\nTransform transform\n"
    ),
    "tf2_msgs/TFMessage": "geometry_msgs/TransformStamped[] transforms\n",
}

_DEPENDS = {
    "trajectory_msgs/JointTrajectory": [
        "std_msgs/Header",
        "builtin_interfaces/Time",
        "trajectory_msgs/JointTrajectoryPoint",
        "builtin_interfaces/Duration",
    ],
    "sensor_msgs/JointState": ["std_msgs/Header", "builtin_interfaces/Time"],
    "tf2_msgs/TFMessage": [
        "geometry_msgs/TransformStamped",
        "std_msgs/Header",
        "builtin_interfaces/Time",
        "geometry_msgs/Transform",
        "geometry_msgs/Vector3",
        "geometry_msgs/Quaternion",
    ],
}


def _definition(kind: str) -> str:
    return _PLAIN[kind] + "".join(
        f"{_SEPARATOR}MSG: {dependency}\n{_PLAIN[dependency]}" for dependency in _DEPENDS[kind]
    )


DEFINITIONS = {
    f"{package}/msg/{name}": _definition(f"{package}/{name}")
    for package, name in (k.split("/") for k in _DEPENDS)
}
"""Schema name (``pkg/msg/Type``) → its definition text."""
