"""Bad input to the robot layer: each answered by a specific nearopt exception."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from conftest import load
from urdfs import LIMIT, write_urdf

import nearopt
from nearopt import ConfigurationError, NearoptError, RobotNotFoundError, URDFError


def test_the_generated_chain_loads(tmp_path: Path) -> None:
    robot = nearopt.Robot.from_urdf(write_urdf(tmp_path))
    assert robot.n == 2 and robot.joint_names == ["j1", "j2"]


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(URDFError, match="not found.*nope.urdf"):
        nearopt.Robot.from_urdf(tmp_path / "nope.urdf")


def test_malformed_xml(tmp_path: Path) -> None:
    path = tmp_path / "bad.urdf"
    path.write_text('<robot name="x"><link name="a">')
    with pytest.raises(URDFError, match="malformed URDF"):
        nearopt.Robot.from_urdf(path)


def test_not_a_urdf(tmp_path: Path) -> None:
    path = tmp_path / "scene.xml"
    path.write_text("<mujoco/>")
    with pytest.raises(URDFError, match="root element is <mujoco>"):
        nearopt.Robot.from_urdf(path)


def test_unknown_robot_name_lists_the_known_ones() -> None:
    with pytest.raises(RobotNotFoundError) as info:
        nearopt.Robot.from_name("r2d2")
    message = str(info.value)
    assert "'r2d2'" in message
    for name in nearopt.available_robots():
        assert name in message


@pytest.mark.parametrize("jtype", ["floating", "planar"])
def test_floating_base_is_rejected(tmp_path: Path, jtype: str) -> None:
    path = write_urdf(tmp_path, types=(jtype, "revolute"))
    with pytest.raises(URDFError, match=f"joint 'j1'.*{jtype}.*moving base"):
        nearopt.Robot.from_urdf(path)


def test_mimic_joint_is_rejected_unless_locked(tmp_path: Path) -> None:
    path = write_urdf(tmp_path, extra=("", '<mimic joint="j1"/>'))
    with pytest.raises(URDFError, match="joint 'j2'.*mimics joint 'j1'"):
        nearopt.Robot.from_urdf(path)
    assert nearopt.Robot.from_urdf(path, locked_joints=["j2"]).joint_names == ["j1"]


def test_one_locked_joint_by_its_name_alone(tmp_path: Path) -> None:
    """``locked_joints="j2"`` locks j2 (it was split into its letters and refused)."""
    path = write_urdf(tmp_path, extra=("", '<mimic joint="j1"/>'))
    assert nearopt.Robot.from_urdf(path, locked_joints="j2").joint_names == ["j1"]


def test_a_locked_joint_may_have_no_room(tmp_path: Path) -> None:
    """lower = upper ≠ 0 is refused for a joint that would move; a locked one stays there."""
    path = write_urdf(
        tmp_path, limits=(LIMIT, LIMIT.replace('lower="-3" upper="3"', 'lower="0.5" upper="0.5"'))
    )
    with pytest.raises(URDFError, match="joint 'j2' has position limits lower = upper = 0.5"):
        nearopt.Robot.from_urdf(path)
    assert nearopt.Robot.from_urdf(path, locked_joints=["j2"], lock_at={"j2": 0.5}).n == 1


def test_unknown_locked_joint(tmp_path: Path) -> None:
    with pytest.raises(URDFError, match=re.escape("cannot lock joint(s) ['j9']")):
        nearopt.Robot.from_urdf(write_urdf(tmp_path), locked_joints=["j9"])


def test_missing_effort_limit_needs_an_override(tmp_path: Path) -> None:
    path = write_urdf(tmp_path, limits=(LIMIT, '<limit velocity="2" lower="-3" upper="3"/>'))
    with pytest.raises(URDFError, match="joint 'j2'.*declares no effort limit"):
        nearopt.Robot.from_urdf(path)
    robot = nearopt.Robot.from_urdf(path, effort_limit=[5.0, 4.0])
    np.testing.assert_array_equal(robot.limits.effort_upper, [5.0, 4.0])


def test_links_without_inertia(tmp_path: Path) -> None:
    with pytest.raises(URDFError, match="joint 'j1'.*moves no inertia.*<inertial>"):
        nearopt.Robot.from_urdf(write_urdf(tmp_path, inertial=False))


def test_unsupported_joint_type(tmp_path: Path) -> None:
    with pytest.raises(URDFError, match="unsupported type 'ball'"):
        nearopt.Robot.from_urdf(write_urdf(tmp_path, types=("ball", "revolute")))


def test_a_urdf_limit_beyond_no_limit_is_read_as_with_limits_reads_it(tmp_path: Path) -> None:
    """velocity 1e300 in a URDF is no limit (its square overflowed in stage 1), and an effort
    limit beyond NO_LIMIT is NO_LIMIT: as ``with_limits`` takes them."""
    big = '<limit effort="1e300" velocity="1e300" lower="-3" upper="3"/>'
    robot = nearopt.Robot.from_urdf(write_urdf(tmp_path, limits=(big, LIMIT)))
    assert robot.limits.velocity[0] == np.inf and robot.limits.velocity[1] == 2.0
    assert robot.limits.effort_upper[0] == nearopt.robot.NO_LIMIT
    assert robot.limits.effort_lower[0] == -nearopt.robot.NO_LIMIT
    same = robot.with_limits(effort=[1e300, 5.0], velocity=[1e300, 2.0])
    np.testing.assert_array_equal(same.limits.velocity, robot.limits.velocity)
    np.testing.assert_array_equal(same.limits.effort_upper, robot.limits.effort_upper)


def test_continuous_joint_becomes_an_unbounded_angle(tmp_path: Path) -> None:
    robot = nearopt.Robot.from_urdf(write_urdf(tmp_path, types=("continuous", "revolute")))
    assert robot.model.nq == robot.n == 2
    assert robot.limits.position_lower[0] == -np.inf
    assert robot.limits.position_upper[1] == 3.0


@pytest.mark.parametrize(
    ("q", "pattern"),
    [
        ([0.1], r"must have 2 values .*joint1, joint2.*shape \(1,\)"),
        ([0.1, 0.2, 0.3], r"must have 2 values"),
        ([0.1, np.nan], r"joint 'joint2' is nan"),
        ([np.inf, 0.0], r"joint 'joint1' is inf"),
        (["a", "b"], r"not numeric"),
    ],
    ids=["too_short", "too_long", "nan", "inf", "text"],
)
def test_bad_configuration(q: list[object], pattern: str) -> None:
    robot = load("two_link")
    with pytest.raises(ConfigurationError, match=pattern):
        robot.mass_matrix(q)
    with pytest.raises(NearoptError):
        robot.inverse_dynamics(q, [0, 0], [0, 0])


def test_bad_limit_overrides() -> None:
    robot = load("two_link")
    with pytest.raises(ConfigurationError, match="effort limits of joint 'joint2'.*lower 5"):
        robot.with_limits(effort=(np.array([-1.0, 5.0]), np.array([1.0, 5.0])))
    with pytest.raises(ConfigurationError, match="velocity limit of joint 'joint1' is -1"):
        robot.with_limits(velocity=[-1.0, 2.0])
    with pytest.raises(ConfigurationError, match="damping of joint 'joint2' is -0.5"):
        robot.with_limits(damping=[0.0, -0.5])
    relaxed = robot.with_limits(velocity=np.inf, effort=[20.0, 8.0])
    assert np.all(np.isinf(relaxed.limits.velocity))
    np.testing.assert_array_equal(relaxed.limits.effort_lower, [-20.0, -8.0])
    assert robot.limits.effort_upper[0] == 10.0  # the original is unchanged


def test_limits_are_read_only() -> None:
    robot = load("two_link")
    with pytest.raises(ValueError):
        robot.limits.effort_upper[0] = 100.0
