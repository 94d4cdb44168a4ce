"""Stage 1 benchmark: nearopt's optimal timing against TOPP-RA on straight lines, same grid.

For two_link (the paper's line), ur5 and panda (a seeded random line), prints N, the median solve
time of repeats, J for the paper's cost and, for the time-optimal case, TOPP-RA's duration and
time on the same grid with the ratios; then the same with joint acceleration limits (``--accel``
rad/s² on every joint; TOPP-RA's ``JointAccelerationConstraint``).

    python scripts/bench_timing.py [--grids 100 200 400] [--repeat 5] [--accel 10]
"""

from __future__ import annotations

import argparse

import numpy as np
import pinocchio as pin
import toppra as ta
from benchlib import median_time

import nearopt
import nearopt.timing
from nearopt.paper_example import COST, THETA_0, THETA_E


def line(robot: nearopt.Robot) -> nearopt.StraightPath:
    if robot.name == "two_link":
        return nearopt.StraightPath(THETA_0, THETA_E)
    rng = np.random.default_rng(11)
    lo = np.maximum(robot.limits.position_lower, -np.pi)
    hi = np.minimum(robot.limits.position_upper, np.pi)
    return nearopt.StraightPath(rng.uniform(lo, hi), rng.uniform(lo, hi))


def toppra_duration(robot: nearopt.Robot, path: nearopt.StraightPath, grid: int) -> float:
    """TOPP-RA's time-optimal duration [s] with the same limits, on nearopt's knots."""
    data = robot.model.createData()
    lim = robot.limits
    spline = ta.SplineInterpolator([0.0, 1.0], np.vstack([path(0.0)[0], path(1.0)[0]]))
    constraints = [
        ta.constraint.JointVelocityConstraint(np.column_stack([-lim.velocity, lim.velocity])),
        ta.constraint.JointTorqueConstraint(
            lambda q, qd, qdd: pin.rnea(robot.model, data, q, qd, qdd) + robot.damping * qd,
            np.column_stack([lim.effort_lower, lim.effort_upper]),
            np.zeros(robot.n),
            discretization_scheme=ta.constraint.DiscretizationType.Interpolation,
        ),
    ]
    if np.any(np.isfinite(lim.acceleration)):
        constraints.append(ta.constraint.JointAccelerationConstraint(
            np.column_stack([-lim.acceleration, lim.acceleration]),
            discretization_scheme=ta.constraint.DiscretizationType.Interpolation,
        ))
    # the same knots as nearopt's stage 1 (clustered at the rest ends)
    knots = nearopt.timing.build_timing_problem(robot, path, grid=grid).sigma
    algo = ta.algorithm.TOPPRA(constraints, spline, gridpoints=knots)
    return algo.compute_trajectory(0, 0).duration


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", nargs="+", default=["two_link", "ur5", "panda"])
    parser.add_argument("--grids", nargs="+", type=int, default=[100, 200, 400])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--accel", type=float, default=10.0,
                        help="joint acceleration limit of the second table [rad/s²]")
    args = parser.parse_args()
    for accel in (np.inf, args.accel):
        table(args, accel)


def table(args: argparse.Namespace, accel: float) -> None:
    """One table: every robot and grid, with the acceleration limit ``accel`` on every joint."""
    print(f"\njoint acceleration limits: {accel:g} rad/s²")
    print(f"{'robot':<10}{'N':>5}{'J(β=0.03)':>12}{'t [ms]':>9}{'te ours':>10}{'t [ms]':>9}"
          f"{'te TOPP-RA':>12}{'t [ms]':>9}{'te ratio':>10}{'time ratio':>11}")
    for name in args.robots:
        robot = nearopt.Robot.from_name(name).with_limits(acceleration=accel)
        path = line(robot)
        for grid in args.grids:
            t_j, res_j = median_time(
                lambda: nearopt.optimal_timing(robot, path, COST, grid=grid),
                args.repeat,
            )
            t_o, res_o = median_time(
                lambda: nearopt.optimal_timing(robot, path, nearopt.TimeCost(), grid=grid),
                args.repeat,
            )
            t_t, te_t = median_time(lambda: toppra_duration(robot, path, grid), args.repeat)
            print(f"{name:<10}{grid:>5}{res_j.J:>12.6f}{1e3 * t_j:>9.1f}{res_o.duration:>10.5f}"
                  f"{1e3 * t_o:>9.1f}{te_t:>12.5f}{1e3 * t_t:>9.1f}"
                  f"{res_o.duration / te_t:>10.4f}{t_o / t_t:>11.2f}")


if __name__ == "__main__":
    main()
