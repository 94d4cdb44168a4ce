"""Per-call cost of the robot layer (eq. 1 and its derivatives) against bare Pinocchio.

Prints, for each arm, the median time of one call of H(θ), g(θ), inverse dynamics and the ABA
derivatives (A, B) through nearopt.Robot, and of the same Pinocchio function called directly, with
the ratio (the wrapper's overhead: argument checks, damping, copies).

    python scripts/bench_dynamics.py [--robots panda ur5 ...] [--repeat 2000]
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np
import pinocchio as pin

import nearopt


def median_us(fn: Callable[[], object], repeat: int) -> float:
    """Median wall time of one call [µs], over ``repeat`` calls after a warm-up."""
    for _ in range(20):
        fn()
    times = np.empty(repeat)
    for k in range(repeat):
        t0 = time.perf_counter()
        fn()
        times[k] = time.perf_counter() - t0
    return float(np.median(times) * 1e6)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", nargs="+", default=["two_link", "ur5", "panda", "xarm7"])
    parser.add_argument("--repeat", type=int, default=2000)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    print(f"{'robot':<10}{'call':<22}{'nearopt [µs]':>14}{'pinocchio [µs]':>16}{'ratio':>8}")
    for name in args.robots:
        robot = nearopt.Robot.from_name(name)
        model, data = robot.model, robot.model.createData()
        lo = np.maximum(robot.limits.position_lower, -np.pi)
        hi = np.minimum(robot.limits.position_upper, np.pi)
        q, v, a = rng.uniform(lo, hi), rng.normal(size=robot.n), rng.normal(size=robot.n)
        u = robot.inverse_dynamics(q, v, a)
        rows = [
            ("H(θ) crba", lambda: robot.mass_matrix(q), lambda: pin.crba(model, data, q)),
            (
                "g(θ)",
                lambda: robot.gravity_torque(q),
                lambda: pin.computeGeneralizedGravity(model, data, q),
            ),
            (
                "inverse dynamics",
                lambda: robot.inverse_dynamics(q, v, a),
                lambda: pin.rnea(model, data, q, v, a),
            ),
            (
                "ABA derivatives A, B",
                lambda: robot.dynamics_jacobians(q, v, u),
                lambda: pin.computeABADerivatives(model, data, q, v, u),
            ),
        ]
        for label, ours, theirs in rows:
            t_ours, t_pin = median_us(ours, args.repeat), median_us(theirs, args.repeat)
            print(f"{name:<10}{label:<22}{t_ours:>14.2f}{t_pin:>16.2f}{t_ours / t_pin:>8.2f}")


if __name__ == "__main__":
    main()
