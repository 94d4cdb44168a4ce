"""Independent checks of a returned trajectory, computed with Pinocchio directly.

They do not reuse the planner's bookkeeping: torques come from ``pinocchio.rnea`` (+ D θ̇) on
sampled (θ, θ̇, θ̈), the end state from integrating ``pinocchio.aba`` (− D θ̇) forward under the
returned torques u(t), and J from the trapezoidal rule over the samples.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from scipy.integrate import solve_ivp

import nearopt
from nearopt.trajectory import Trajectory


def torques_from_samples(robot: nearopt.Robot, samples: dict[str, np.ndarray]) -> np.ndarray:
    """u = RNEA(θ, θ̇, θ̈) + D θ̇ at every sample, with Pinocchio called here."""
    data = robot.model.createData()
    return np.array(
        [
            pin.rnea(robot.model, data, q, qd, qdd) + robot.damping * qd
            for q, qd, qdd in zip(samples["q"], samples["qd"], samples["qdd"], strict=True)
        ]
    )


def worst_torque_excess(robot: nearopt.Robot, u: np.ndarray) -> float:
    """max over samples and joints of the excess beyond the limits, relative to the limit."""
    lim = robot.limits
    span = np.maximum(np.abs(lim.effort_upper), np.abs(lim.effort_lower))
    return float(np.max(np.maximum(u - lim.effort_upper, lim.effort_lower - u) / span))


def simulate(
    robot: nearopt.Robot, traj: Trajectory, window: float = 0.25
) -> tuple[np.ndarray, float]:
    """Integrate ẍ = ABA(θ, θ̇, u(t) − D θ̇) under the trajectory's torques u(t).

    Open-loop integration amplifies any error at the rate of the arm's unstable (gravity) modes,
    e^{σt} with σ of several 1/s, so over a multi-second motion it measures that instability, not
    the plan. The motion is therefore shot in windows of ``window`` seconds, each started from the
    trajectory's own state (a single window when the motion is shorter): the returned end state is
    where the torques of the last window take the arm, and the defect is the largest mismatch
    between a window's simulated end state and the trajectory's state there. The torque jumps at
    knots (the path acceleration is piecewise constant), so integration also restarts at every knot.

    Returns
    -------
    (x_end, defect)
        The simulated end state (θ, θ̇), shape (2n,), and the largest window defect.
    """
    model, data, n = robot.model, robot.model.createData(), robot.n

    def rhs(t: float, x: np.ndarray) -> np.ndarray:
        u = traj.torque(np.array([t]))[0]
        qdd = pin.aba(model, data, x[:n], x[n:], u - robot.damping * x[n:])
        return np.concatenate([x[n:], qdd])

    def state(t: float) -> np.ndarray:
        return np.concatenate([traj(t, 0)[0], traj(t, 1)[0]])

    te = traj.duration
    starts = np.arange(0.0, te, window)
    defect = 0.0
    for w0 in starts:
        w1 = min(w0 + window, te)
        x = state(w0)
        cuts = np.concatenate([[w0], traj.t[(traj.t > w0) & (traj.t < w1)], [w1]])
        for t0, t1 in zip(cuts[:-1], cuts[1:], strict=True):
            # the torque of the segment [t0, t1): stop just short of the jump at t1
            sol = solve_ivp(rhs, (t0, t1 - 1e-12 * max(1.0, t1)), x, method="DOP853",
                            rtol=1e-10, atol=1e-12)
            x = sol.y[:, -1]
        if w1 < te:
            defect = max(defect, float(np.max(np.abs(x - state(w1)))))
    return x, defect


def assert_independent_checks(
    robot: nearopt.Robot,
    traj: Trajectory,
    cost: object,
    J: float,
    q0: np.ndarray,
    qe: np.ndarray,
    *,
    position_limits: bool = True,
) -> None:
    """The checks every returned motion must pass, computed with Pinocchio directly.

    Torques by RNEA (+ D θ̇) on 2 kHz samples within the limits (1e-6 relative); joint speeds (and
    positions) within the limits; at rest at θ0 and θe; J recomputed from 20 kHz samples
    (trapezoid, 1e-4 relative: its error on torques that jump at the knots and switch within
    milliseconds near the rest ends, measured 3e-5 on the paper's example); forward
    simulation of u(t) with ABA reaching θe at rest (windows of 0.25 s, see :func:`simulate`:
    integration error ~1e-10 amplified by the arm's open-loop instability within a window).
    """
    samples = traj.sample(2000.0)
    u = torques_from_samples(robot, samples)
    assert worst_torque_excess(robot, u) <= 1e-6
    assert np.all(np.abs(samples["qd"]) <= robot.limits.velocity * (1 + 1e-9))
    if position_limits:
        assert np.all(samples["q"] >= robot.limits.position_lower - 1e-12)
        assert np.all(samples["q"] <= robot.limits.position_upper + 1e-12)
    np.testing.assert_allclose(samples["q"][0], q0, atol=1e-12)
    np.testing.assert_allclose(samples["q"][-1], qe, atol=1e-8)
    np.testing.assert_allclose(samples["qd"][[0, -1]], 0.0, atol=1e-12)
    fine = traj.sample(20000.0)
    j_samples = np.trapezoid(
        cost(fine["q"], fine["qd"], torques_from_samples(robot, fine)), fine["t"]
    )
    np.testing.assert_allclose(j_samples, J, rtol=1e-4)
    np.testing.assert_allclose(samples["t"][-1], traj.duration, rtol=1e-12)
    x_end, defect = simulate(robot, traj)
    np.testing.assert_allclose(x_end[: robot.n], qe, atol=1e-5)
    np.testing.assert_allclose(x_end[robot.n :], 0.0, atol=1e-4)
    assert defect < 1e-5
