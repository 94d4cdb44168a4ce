"""MoveIt's ``joint_limits.yaml``: the limits a MoveIt configuration (or ros2_control) declares per
joint, over the URDF's.

The file is a mapping with ``joint_limits:``, and under it one mapping per joint::

    joint_limits:
      panda_joint1:
        has_velocity_limits: true
        max_velocity: 2.175          # rad/s (m/s for a prismatic joint)
        has_acceleration_limits: true
        max_acceleration: 3.75       # rad/s²
        has_deceleration_limits: true
        max_deceleration: 5.0        # rad/s² (its magnitude; ros2_control writes it negative)
        has_jerk_limits: true
        max_jerk: 500.0              # rad/s³
        has_effort_limits: true
        max_effort: 87.0             # N·m
        has_position_limits: true
        min_position: -2.9
        max_position: 2.9

A value counts where its ``has_…`` is true (MoveIt's rule); it replaces the URDF's. Joints the
robot locks (a gripper's) are skipped; a joint the URDF does not have is an error (a misspelt
name would otherwise be ignored). MoveIt's ``default_velocity_scaling_factor`` and
``default_acceleration_scaling_factor`` scale MoveIt's own plans and are not read: nearopt plans
at the limits (``--velocity-scale`` scales its speed limits).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from ..errors import ConfigurationError

__all__ = ["FileLimits", "read_joint_limits"]

_KINDS = ("velocity", "acceleration", "deceleration", "jerk", "effort")
_KEYS = {
    *(f"has_{kind}_limits" for kind in _KINDS),
    *(f"max_{kind}" for kind in _KINDS),
    "has_position_limits",
    "min_position",
    "max_position",
    "has_soft_limits",
}


@dataclass(frozen=True)
class FileLimits:
    """One joint's limits from a ``joint_limits.yaml`` (None: not declared there).

    Attributes
    ----------
    velocity, acceleration, deceleration, jerk, effort
        Magnitudes [rad/s, rad/s², rad/s², rad/s³, N·m; or m/… and N for a prismatic joint].
    position
        (lower, upper) [rad or m].
    """

    velocity: float | None = None
    acceleration: float | None = None
    deceleration: float | None = None
    jerk: float | None = None
    effort: float | None = None
    position: tuple[float, float] | None = None


def read_joint_limits(path: str | Path) -> dict[str, FileLimits]:
    """The limits of every joint a ``joint_limits.yaml`` names (see the module docstring).

    Raises
    ------
    ConfigurationError
        A missing or unreadable file, YAML that is not a mapping with ``joint_limits``, or a
        value that is not a positive number (a position range with min > max); the message
        names the file, the joint and the key.
    """
    import yaml

    path = Path(path).expanduser()
    try:
        data = yaml.safe_load(path.read_text())
    except OSError as exc:
        raise ConfigurationError(
            f"cannot read the joint limits file {path}: {exc.strerror}"
        ) from None
    except UnicodeDecodeError:
        raise ConfigurationError(f"{path} is not a text file (YAML)") from None
    except yaml.YAMLError as exc:
        raise ConfigurationError(f"{path} is not YAML: {exc}") from None
    if not isinstance(data, dict) or not isinstance(data.get("joint_limits"), dict):
        raise ConfigurationError(
            f"{path} has no 'joint_limits:' mapping (MoveIt's joint_limits.yaml: joint_limits: "
            "{joint: {has_velocity_limits: true, max_velocity: ...}})"
        )
    return {
        str(joint): _joint(path, str(joint), entry) for joint, entry in data["joint_limits"].items()
    }


def _joint(path: Path, joint: str, entry: object) -> FileLimits:
    where = f"{path}: joint {joint!r}"
    if entry is None:
        return FileLimits()
    if not isinstance(entry, dict):
        raise ConfigurationError(f"{where}: expected a mapping of its limits, got {entry!r:.60}")
    values: dict[str, object] = {}
    for key in entry:  # a misspelt key would leave its limit out without a word
        if str(key).startswith(("has_", "max_", "min_")) and key not in _KEYS:
            raise ConfigurationError(
                f"{where}: unknown key {key!r} (known: {', '.join(sorted(_KEYS))})"
            )
    for kind in _KINDS:
        if _has(where, entry, f"has_{kind}_limits"):
            value = _number(where, entry, f"max_{kind}")
            if kind == "deceleration":  # ros2_control writes it negative: its magnitude
                value = abs(value)
            if not value > 0.0:
                raise ConfigurationError(f"{where}: max_{kind} is {value:g}: a limit must be > 0")
            values[kind] = value
    if _has(where, entry, "has_position_limits"):
        low, high = _number(where, entry, "min_position"), _number(where, entry, "max_position")
        if low > high:
            raise ConfigurationError(
                f"{where}: min_position {low:g} is above max_position {high:g}"
            )
        values["position"] = (low, high)
    return FileLimits(**values)  # type: ignore[arg-type]


def _has(where: str, entry: dict, key: str) -> bool:
    value = entry.get(key, False)
    if not isinstance(value, bool):
        raise ConfigurationError(f"{where}: {key} must be true or false, got {value!r:.40}")
    return value


def _number(where: str, entry: dict, key: str) -> float:
    value = entry.get(key)
    if isinstance(value, str):  # YAML 1.1 reads 1e3 (no dot) as text; MoveIt as a number
        try:
            value = float(value)
        except ValueError:
            pass
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        said = "is missing" if value is None else f"must be a finite number, got {value!r:.40}"
        raise ConfigurationError(f"{where}: {key} {said}")
    return float(value)
