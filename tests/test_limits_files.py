"""Limits from the robot's own files: URDF 1.2's <limit acceleration deceleration jerk> and
MoveIt's joint_limits.yaml (Robot.with_joint_limits, --joint-limits); jerk limits are read and
said, not yet held."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from console import run_cli
from urdfs import write_urdf

import nearopt

RATES = (
    '<limit effort="5" velocity="20" lower="-3" upper="3" acceleration="8" deceleration="6" '
    'jerk="40"/>',
    '<limit effort="5" velocity="20" lower="-3" upper="3" acceleration="10"/>',
)
Q0, QE = np.array([0.8, -0.6]), np.array([-0.4, 0.7])


def _rate_urdf(tmp_path: Path) -> Path:
    path = write_urdf(tmp_path, limits=RATES)
    path.write_text(
        path.read_text().replace('<robot name="chain">', '<robot name="chain" version="1.2">')
    )
    return path


def test_urdf_rate_limits_are_read_and_held(tmp_path: Path) -> None:
    """The smaller of acceleration and deceleration is the joint's |θ̈| limit and the jerk
    limit |θ⃛|: a time-optimal plan keeps both at 20 kHz while reaching them (they bind), and
    is slower than without them."""
    robot = nearopt.Robot.from_urdf(_rate_urdf(tmp_path))
    np.testing.assert_array_equal(robot.limits.acceleration, [6.0, 10.0])
    np.testing.assert_array_equal(robot.limits.jerk, [40.0, np.inf])
    assert "|jerk|" in robot.summary()
    result = nearopt.plan(robot, Q0, QE, nearopt.TimeCost(), max_iterations=2, grid=80)
    t = np.linspace(0.0, result.duration, 20001)
    peak = np.max(np.abs(result.trajectory(t, 2)), axis=0)
    assert np.all(peak <= robot.limits.acceleration * (1 + 1e-6))
    assert np.max(peak / robot.limits.acceleration) > 0.9
    jerk = np.max(np.abs(result.trajectory.jerk(t)), axis=0)
    assert jerk[0] <= 40.0 and jerk[0] > 0.9 * 40.0
    free = robot.with_limits(acceleration=np.inf, jerk=np.inf)
    unlimited = nearopt.plan(free, Q0, QE, nearopt.TimeCost(), max_iterations=2, grid=80)
    assert unlimited.duration < result.duration  # the limits made the motion slower
    report = nearopt.verify_plan(result)
    assert report.passed and "joint jerk limits" in {c.name for c in report.checks}


@pytest.mark.parametrize(
    ("attribute", "value"), [("acceleration", "0"), ("deceleration", "-2"), ("jerk", "nan")]
)
def test_a_bad_urdf_rate_limit_names_the_joint(tmp_path: Path, attribute: str, value: str) -> None:
    limit = f'<limit effort="5" velocity="2" lower="-3" upper="3" {attribute}="{value}"/>'
    path = write_urdf(tmp_path, limits=(RATES[1], limit))
    with pytest.raises(nearopt.URDFError, match=rf"j2.*{attribute}|{attribute}.*j2"):
        nearopt.Robot.from_urdf(path)


LIMITS_YAML = """
default_velocity_scaling_factor: 0.1
joint_limits:
  panda_joint1:
    has_velocity_limits: true
    max_velocity: 1.5
    has_acceleration_limits: true
    max_acceleration: 3.75
    has_deceleration_limits: true
    max_deceleration: -3.0
    has_jerk_limits: true
    max_jerk: 500
    has_effort_limits: true
    max_effort: 80
  panda_joint2:
    has_acceleration_limits: false
    max_acceleration: 0
    has_position_limits: true
    min_position: -1.5
    max_position: 1.5
  panda_finger_joint1:
    has_velocity_limits: true
    max_velocity: 0.1
"""


def test_moveit_joint_limits_replace_the_urdfs(tmp_path: Path) -> None:
    path = tmp_path / "joint_limits.yaml"
    path.write_text(LIMITS_YAML)
    panda = nearopt.Robot.from_name("panda")
    robot = panda.with_joint_limits(path)
    lim, urdf = robot.limits, panda.limits
    assert lim.velocity[0] == 1.5 and lim.velocity[1] == urdf.velocity[1]
    assert lim.acceleration[0] == 3.0  # the smaller of acceleration and |deceleration|
    assert lim.acceleration[1] == np.inf  # has_acceleration_limits: false
    assert lim.jerk[0] == 500.0 and np.all(np.isinf(lim.jerk[1:]))
    assert (lim.effort_lower[0], lim.effort_upper[0]) == (-80.0, 80.0)
    assert (lim.position_lower[1], lim.position_upper[1]) == (-1.5, 1.5)
    assert lim.velocity[2:].tolist() == urdf.velocity[2:].tolist()  # the fingers are locked


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("joint_limits:\n  panda_joint9:\n    has_velocity_limits: true\n    max_velocity: 1",
         "panda_joint9"),
        ("joint_limits:\n  panda_joint1:\n    has_velocity_limits: true\n    max_velocity: fast",
         r"panda_joint1.*max_velocity must be a finite number"),
        ("joint_limits:\n  panda_joint1:\n    has_jerk_limits: true", r"max_jerk is missing"),
        ("joint_limits:\n  panda_joint1:\n    has_velocity_limits: yes please\n",
         "has_velocity_limits must be true or false"),
        ("velocity: 3", "no 'joint_limits:' mapping"),
        ("joint_limits: [1, 2", "is not YAML"),
    ],
)  # fmt: skip
def test_a_bad_joint_limits_file_says_where(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "joint_limits.yaml"
    path.write_text(text)
    with pytest.raises(nearopt.ConfigurationError, match=message):
        nearopt.Robot.from_name("panda").with_joint_limits(path)


def test_the_command_reads_joint_limits_and_holds_them(tmp_path: Path) -> None:
    """--joint-limits: the plan keeps the file's speed limit and its jerk limit (checked in the
    written samples, and by the verification), and the file is an input that no output may
    overwrite."""
    path = tmp_path / "joint_limits.yaml"
    path.write_text(LIMITS_YAML)
    out = tmp_path / "plan.json"
    options = [
        "plan", "--robot", "panda", "--q0", "0", "0", "0", "-1.5", "0", "1.5", "0",
        "--qe", "1.2", "0.3", "0", "-1.2", "0", "1.6", "0.4", "--time-optimal", "--quiet",
        "--max-iterations", "2", "--grid", "80", "--joint-limits", str(path), "--verify",
    ]  # fmt: skip
    done = run_cli(*options, "--json", str(out))
    assert done.returncode == 0, done.stderr
    assert "warning" not in done.stderr
    assert re.search(r"ok +joint jerk limits", done.stdout)
    record = json.loads(out.read_text())
    qd, qdd, t = np.array(record["qd"]), np.array(record["qdd"]), np.array(record["t"])
    assert np.max(np.abs(qd[:, 0])) <= 1.5 * (1 + 1e-6)
    jerk = np.diff(qdd[:, 0]) / np.diff(t)  # a mean over each step: at most the limit
    assert np.max(np.abs(jerk)) <= 500.0 * (1 + 1e-6)
    again = run_cli(*options, "--json", str(path))
    assert again.returncode != 0 and "joint limits file" in again.stderr
    assert path.read_text() == LIMITS_YAML


def test_a_motion_with_jumps_fails_a_jerk_limited_check() -> None:
    """verify with jerk limits and a stage-1 motion (θ̈ jumps at its knots): the jerk check
    fails (its jerk is unbounded) rather than being left out."""
    robot = nearopt.Robot.from_name("two_link")
    result = nearopt.plan(robot, Q0, QE, max_iterations=0, grid=40)
    report = nearopt.verify(result.trajectory, robot.with_limits(jerk=100.0))
    failed = {c.name for c in report.checks if not c.passed}
    assert "joint jerk limits" in failed


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("joint_limits:\n  panda_joint1:\n    has_jerk_limit: true\n    max_jerk: 5",
         "unknown key 'has_jerk_limit'"),
        ("joint_limits:\n  panda_joint1:\n    has_velocity_limits: true\n    max_velocity: -2",
         r"max_velocity is -2: a limit must be > 0"),
    ],
)  # fmt: skip
def test_a_misspelt_key_or_a_negative_limit_is_refused(
    tmp_path: Path, text: str, message: str
) -> None:
    path = tmp_path / "joint_limits.yaml"
    path.write_text(text)
    with pytest.raises(nearopt.ConfigurationError, match=message):
        nearopt.Robot.from_name("panda").with_joint_limits(path)


def test_yaml_numbers_without_a_dot_and_binary_files(tmp_path: Path) -> None:
    """PyYAML reads 1e3 as text (YAML 1.1); MoveIt reads a number: so does nearopt. A file that
    is not text is refused in one line."""
    path = tmp_path / "joint_limits.yaml"
    path.write_text(
        "joint_limits:\n  panda_joint1:\n    has_jerk_limits: true\n    max_jerk: 1e3\n"
    )
    assert nearopt.Robot.from_name("panda").with_joint_limits(path).limits.jerk[0] == 1000.0
    path.write_bytes(b"\xff\xfe\x00binary")
    with pytest.raises(nearopt.ConfigurationError, match="not a text file"):
        nearopt.Robot.from_name("panda").with_joint_limits(path)


def test_an_empty_urdf_rate_limit_names_the_joint(tmp_path: Path) -> None:
    limit = '<limit effort="5" velocity="2" lower="-3" upper="3" jerk=""/>'
    path = write_urdf(tmp_path, limits=(RATES[1], limit))
    with pytest.raises(nearopt.URDFError, match="<limit jerk> of joint 'j2' is '', not a number"):
        nearopt.Robot.from_urdf(path)
