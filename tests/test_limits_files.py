"""Limits from the robot's own files: URDF 1.2's <limit acceleration deceleration jerk> and
MoveIt's joint_limits.yaml (Robot.with_joint_limits, --joint-limits); jerk limits are read and
said, not yet held."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest
from console import run_cli
from urdfs import write_urdf

import nearopt
from nearopt.api import PlanRequest, run

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


def test_urdf_rate_limits_are_read_and_the_acceleration_is_held(tmp_path: Path) -> None:
    """The smaller of acceleration and deceleration is the joint's |θ̈| limit, and a time-optimal
    plan keeps it at every sample while reaching it (it binds: it is not ignored)."""
    robot = nearopt.Robot.from_urdf(_rate_urdf(tmp_path))
    np.testing.assert_array_equal(robot.limits.acceleration, [6.0, 10.0])
    np.testing.assert_array_equal(robot.limits.jerk, [40.0, np.inf])
    assert "|jerk|" in robot.summary()
    with pytest.warns(nearopt.LimitWarning, match=r"jerk limits \(j1 40"):
        result = nearopt.plan(robot, Q0, QE, nearopt.TimeCost(), max_iterations=2)
    samples = result.trajectory.sample(2000.0)
    peak = np.max(np.abs(samples.qdd), axis=0)
    assert np.all(peak <= robot.limits.acceleration * (1 + 1e-6))
    assert np.max(peak / robot.limits.acceleration) > 0.98
    free = robot.with_limits(acceleration=np.inf, jerk=np.inf)
    unlimited = nearopt.plan(free, Q0, QE, nearopt.TimeCost(), max_iterations=2)
    assert unlimited.duration < result.duration  # the limit made the motion slower


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


def test_the_command_reads_joint_limits_and_says_the_jerk_is_not_held(tmp_path: Path) -> None:
    """--joint-limits: the plan keeps the file's speed limit (checked in the written samples),
    the jerk limit is one warning line (not a Python warning's traceback-like text), and the
    file is an input that no output may overwrite."""
    path = tmp_path / "joint_limits.yaml"
    path.write_text(LIMITS_YAML)
    out = tmp_path / "plan.json"
    options = [
        "plan", "--robot", "panda", "--q0", "0", "0", "0", "-1.5", "0", "1.5", "0",
        "--qe", "1.2", "0.3", "0", "-1.2", "0", "1.6", "0.4", "--time-optimal", "--quiet",
        "--max-iterations", "2", "--joint-limits", str(path),
    ]  # fmt: skip
    done = run_cli(*options, "--json", str(out))
    assert done.returncode == 0, done.stderr
    assert done.stderr.count("warning:") == 1 and "panda_joint1 500" in done.stderr
    assert "LimitWarning" not in done.stderr
    qd = np.array(json.loads(out.read_text())["qd"])
    assert np.max(np.abs(qd[:, 0])) <= 1.5 * (1 + 1e-6)
    assert np.max(np.abs(qd[:, 0])) > 1.4  # the file's limit binds on this motion
    again = run_cli(*options, "--json", str(path))
    assert again.returncode != 0 and "joint limits file" in again.stderr
    assert path.read_text() == LIMITS_YAML


def test_run_notes_the_unheld_jerk_once(tmp_path: Path) -> None:
    """The request model's run() says it in its notes, and plan() itself does not warn twice."""
    path = tmp_path / "joint_limits.yaml"
    path.write_text(LIMITS_YAML)
    request = PlanRequest(
        robot="panda", q0=(0, 0, 0, -1.5, 0, 1.5, 0), qe=(0.3, 0.3, 0, -1.2, 0, 1.6, 0.4),
        joint_limits=str(path), max_iterations=1, time_optimal=True,
    )  # fmt: skip
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        outcome = run(request)
    assert [w for w in caught if issubclass(w.category, nearopt.LimitWarning)] == []
    assert sum("jerk limits" in note for note in outcome.warnings) == 1
