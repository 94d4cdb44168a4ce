"""The robot layer against closed forms, finite differences and a second URDF parser."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import yourdfpy
from conftest import load, random_configuration

import nearopt
from nearopt.paper_example import eq31


# ---------------------------------------------------------------- the paper's arm, eq. (31)
def test_two_link_matches_eq31(rng: np.random.Generator) -> None:
    robot = load("two_link")
    for _ in range(20):
        q, qd = rng.uniform(-np.pi, np.pi, 2), rng.normal(0, 5, 2)
        hmat, h, g = (np.array(part) for part in eq31(q, qd))
        np.testing.assert_allclose(robot.mass_matrix(q), hmat, rtol=0, atol=1e-9)
        np.testing.assert_allclose(robot.coriolis(q, qd), h, rtol=0, atol=1e-9)
        np.testing.assert_allclose(robot.gravity_torque(q), g, rtol=0, atol=1e-9)


def test_two_link_declares_the_papers_limits() -> None:
    robot = load("two_link")
    np.testing.assert_array_equal(robot.limits.effort_upper, [10.0, 5.0])
    np.testing.assert_array_equal(robot.limits.effort_lower, [-10.0, -5.0])
    np.testing.assert_array_equal(robot.damping, [0.0, 0.0])
    # the arm points straight up at θ = 0: θ is measured from the upward vertical
    np.testing.assert_allclose(robot.frame_position(np.zeros(2)), [0, 0, 0.4], atol=1e-12)


# ---------------------------------------------------------------- derivatives (eqs. 24-26)
def _finite_difference_jacobians(
    robot: nearopt.Robot, x: np.ndarray, u: np.ndarray, eps: float = 1e-6
) -> tuple[np.ndarray, np.ndarray]:
    n = robot.n
    a = np.empty((2 * n, 2 * n))
    b = np.empty((2 * n, n))
    for j in range(2 * n):
        dx = np.zeros(2 * n)
        dx[j] = eps
        a[:, j] = (robot.state_derivative(x + dx, u) - robot.state_derivative(x - dx, u)) / 2 / eps
    for j in range(n):
        du = np.zeros(n)
        du[j] = eps
        b[:, j] = (robot.state_derivative(x, u + du) - robot.state_derivative(x, u - du)) / 2 / eps
    return a, b


@pytest.mark.parametrize("damped", [False, True], ids=["urdf_damping", "random_damping"])
def test_jacobians_match_finite_differences(
    robot: nearopt.Robot, rng: np.random.Generator, damped: bool
) -> None:
    if damped:
        robot = robot.with_limits(damping=rng.uniform(0.5, 3.0, robot.n))
        assert np.all(robot.damping > 0)
    for _ in range(3):
        q = random_configuration(robot, rng)
        x = np.concatenate([q, rng.normal(0, 1, robot.n)])
        u = rng.uniform(robot.limits.effort_lower, robot.limits.effort_upper)
        a, b = robot.dynamics_jacobians(x[: robot.n], x[robot.n :], u)
        a_fd, b_fd = _finite_difference_jacobians(robot, x, u)
        scale_a = max(1.0, np.abs(a_fd).max())
        scale_b = max(1.0, np.abs(b_fd).max())
        np.testing.assert_allclose(a, a_fd, rtol=0, atol=1e-6 * scale_a)
        np.testing.assert_allclose(b, b_fd, rtol=0, atol=1e-6 * scale_b)


def test_forward_dynamics_inverts_inverse_dynamics(
    robot: nearopt.Robot, rng: np.random.Generator
) -> None:
    robot = robot.with_limits(damping=rng.uniform(0.0, 2.0, robot.n))
    q = random_configuration(robot, rng)
    qd, qdd = rng.normal(0, 1, robot.n), rng.normal(0, 3, robot.n)
    u = robot.inverse_dynamics(q, qd, qdd)
    np.testing.assert_allclose(robot.forward_dynamics(q, qd, u), qdd, atol=1e-8)
    # damping enters as D θ̇, on top of what Pinocchio's RNEA knows
    plain = pin.rnea(robot.model, robot.model.createData(), q, qd, qdd)
    np.testing.assert_allclose(u - plain, robot.damping * qd, atol=1e-10)


# ---------------------------------------------------------------- eq. (10)
def _smooth_path(
    q0: np.ndarray, rng: np.random.Generator, count: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """θ(s) = q0 + Σ a_k sin(ω_k s + φ_k) on s ∈ [0, 1], with exact θ' and θ''."""
    s = np.linspace(0.0, 1.0, count)[:, None]
    amp = rng.normal(0, 0.5, (3, q0.size))
    omega = rng.uniform(1, 4, (3, 1))
    phase = rng.uniform(0, np.pi, (3, 1))
    theta, dtheta, ddtheta = np.repeat(q0[None], count, 0), 0 * s, 0 * s
    for k in range(3):
        arg = omega[k] * s + phase[k]
        theta = theta + amp[k] * np.sin(arg)
        dtheta = dtheta + amp[k] * omega[k] * np.cos(arg)
        ddtheta = ddtheta - amp[k] * omega[k] ** 2 * np.sin(arg)
    return s[:, 0], theta, dtheta, ddtheta


def test_eq10_matches_inverse_dynamics(robot: nearopt.Robot, rng: np.random.Generator) -> None:
    robot = robot.with_limits(damping=rng.uniform(0.1, 2.0, robot.n))
    s, theta, dtheta, ddtheta = _smooth_path(random_configuration(robot, rng), rng, 25)
    lam = 1.0 + 0.5 * np.sin(3 * s)  # λ(s) > 0
    dlam = 1.5 * np.cos(3 * s)
    u = robot.path_torque(theta, dtheta, ddtheta, lam, dlam)
    qd = lam[:, None] * dtheta  # eq. (8)
    qdd = lam[:, None] ** 2 * ddtheta + (lam * dlam)[:, None] * dtheta  # eq. (9)
    direct = np.array([robot.inverse_dynamics(*row) for row in zip(theta, qd, qdd, strict=True)])
    np.testing.assert_allclose(u, direct, rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(robot.inverse_dynamics_batch(theta, qd, qdd), direct, atol=1e-9)
    # the coefficient form u = m a + c b + d λ + g, with b = λ², a = λλ'
    coef = robot.path_coefficients(theta, dtheta, ddtheta)
    b, a = lam**2, lam * dlam
    rebuilt = coef.m * a[:, None] + coef.c * b[:, None] + coef.d * lam[:, None] + coef.g
    np.testing.assert_allclose(rebuilt, direct, rtol=1e-10, atol=1e-9)


# ---------------------------------------------------------------- a second parser: yourdfpy
def _yourdfpy(robot: nearopt.Robot) -> yourdfpy.URDF:
    return yourdfpy.URDF.load(
        str(robot.urdf_path),
        build_scene_graph=True,
        load_meshes=False,
        build_collision_scene_graph=False,
        load_collision_meshes=False,
    )


def test_yourdfpy_agrees_on_joints_and_limits(robot: nearopt.Robot) -> None:
    urdf = _yourdfpy(robot)
    moving = [j for j in urdf.actuated_joint_names if j not in robot.locked_joints]
    # the same joints (Pinocchio orders them along the tree, yourdfpy as in the file)
    assert sorted(robot.joint_names) == sorted(moving)
    lim = robot.limits
    for i, name in enumerate(robot.joint_names):
        joint = urdf.joint_map[name]
        assert lim.effort_upper[i] == joint.limit.effort
        assert lim.effort_lower[i] == -joint.limit.effort
        assert lim.velocity[i] == joint.limit.velocity
        if joint.type == "continuous":  # the URDF spec ignores their position limits
            assert (lim.position_lower[i], lim.position_upper[i]) == (-np.inf, np.inf)
        else:
            assert lim.position_lower[i] == joint.limit.lower
            assert lim.position_upper[i] == joint.limit.upper
        damping = joint.dynamics.damping if joint.dynamics is not None else 0.0
        assert robot.damping[i] == float(damping or 0.0)  # yourdfpy keeps it as text


def test_yourdfpy_agrees_on_forward_kinematics(
    robot: nearopt.Robot, rng: np.random.Generator
) -> None:
    urdf = _yourdfpy(robot)
    for _ in range(3):
        q = random_configuration(robot, rng)
        cfg = dict.fromkeys(urdf.actuated_joint_names, 0.0)  # locked joints at their reference
        cfg.update(zip(robot.joint_names, q, strict=True))
        urdf.update_cfg(cfg)
        placements = robot.link_placements(q)
        for link in urdf.link_map:
            expected = urdf.get_transform(frame_to=link, frame_from=urdf.base_link)
            np.testing.assert_allclose(placements[link], expected, atol=1e-9, err_msg=link)


def test_visual_meshes_are_resolved(robot: nearopt.Robot) -> None:
    geom = robot.visual_model()
    assert geom.ngeoms > 0
    meshes = [o.meshPath for o in geom.geometryObjects if Path(o.meshPath).suffix]
    primitives = [o for o in geom.geometryObjects if not Path(o.meshPath).suffix]
    assert meshes or primitives
    for mesh in meshes:  # package:// URIs became files that exist
        assert Path(mesh).is_absolute() and Path(mesh).is_file(), mesh


def test_continuous_joints_are_plain_angles() -> None:
    robot = load("kinova")
    assert robot.model.nq == robot.model.nv == robot.n == 6
    assert np.isinf(robot.limits.position_lower[0])
    # an angle beyond 2π is a valid, distinct configuration value
    q = np.array([7.0, 2.0, 2.0, 0.0, 2.0, 0.0])
    assert robot.mass_matrix(q).shape == (6, 6)


def test_joint_limits_validate_themselves_and_name_the_joint() -> None:
    robot = load("ur5")
    limits = robot.limits
    assert limits.names == tuple(robot.joint_names)
    assert not limits.velocity.flags.writeable
    inf = np.full(2, np.inf)
    with pytest.raises(nearopt.ConfigurationError, match="one shape"):
        nearopt.robot.JointLimits(-inf, inf, inf[:1], -inf, inf, inf)
    with pytest.raises(nearopt.ConfigurationError, match="joint 'b': lower 1 is above upper 0"):
        nearopt.robot.JointLimits(
            np.array([0.0, 1.0]), np.array([1.0, 0.0]), inf, -inf, inf, inf, names=("a", "b")
        )
    with pytest.raises(nearopt.ConfigurationError, match="velocity of joint 'a' is NaN"):
        nearopt.robot.JointLimits(
            -inf, inf, np.array([np.nan, 1.0]), -inf, inf, inf, names=("a", "b")
        )
    q = np.clip(np.zeros(robot.n), limits.position_lower, limits.position_upper)
    limits.check_within(q)
    q[2] = limits.position_upper[2] + 0.1
    with pytest.raises(nearopt.ConfigurationError, match="elbow_joint") as info:
        limits.check_within(q, "qe")
    assert info.value.joint == "elbow_joint" and "qe[2]" in str(info.value)
    lower, upper = nearopt.robot.JointLimits(
        -inf, np.array([np.inf, 2.0]), inf, -inf, inf, inf
    ).sampling_box()
    np.testing.assert_array_equal(lower, [-np.pi, -np.pi])
    np.testing.assert_array_equal(upper, [np.pi, 2.0])
