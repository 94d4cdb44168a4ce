"""The checks every returned motion must pass, made by :func:`nearopt.verify`.

``verify`` recomputes torques with Pinocchio's RNEA (+ D θ̇) from the sampled motion, checks the
limits, the end states and J, and forward-simulates the torques with ABA; ``tests/test_verify.py``
shows that it catches each kind of fault. The tests use it as their one oracle (plus truly
independent references: closed forms, IPOPT, TOPP-RA).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

import nearopt
from nearopt.trajectory import Trajectory

RATE = 2000.0  # [Hz] the checks' controller rate


def torques_from_samples(
    robot: nearopt.Robot, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray
) -> np.ndarray:
    """u = RNEA(θ, θ̇, θ̈) + D θ̇ at every sample (of a file written by the CLI, say)."""
    data = robot.model.createData()
    return np.array(
        [
            pin.rnea(robot.model, data, qk, vk, ak) + robot.damping * vk
            for qk, vk, ak in zip(q, qd, qdd, strict=True)
        ]
    )


def worst_torque_excess(robot: nearopt.Robot, u: np.ndarray) -> float:
    """max over samples and joints of the excess beyond the limits, relative to the limit."""
    lim = robot.limits
    span = np.maximum(np.abs(lim.effort_upper), np.abs(lim.effort_lower))
    return float(np.max(np.maximum(u - lim.effort_upper, lim.effort_lower - u) / span))


def assert_independent_checks(
    robot: nearopt.Robot,
    traj: Trajectory,
    cost: nearopt.Cost,
    J: float,
    q0: np.ndarray,
    qe: np.ndarray,
    *,
    position_limits: bool = True,
) -> nearopt.VerificationReport:
    """Verify a motion at 2 kHz against the robot's limits, q0, qe and J (default tolerances)."""
    report = nearopt.verify(
        traj, robot, rate=RATE, q0=q0, qe=qe, cost=cost, J=J, position_limits=position_limits
    )
    assert report.passed, str(report)
    assert np.isclose(traj.sample(RATE).t[-1], traj.duration, rtol=1e-12)
    return report
