"""Torque-rate limits |u̇_i| ≤ r_i against copp-py's TOPP3-LP with the same rows (#26), on the
seeded panda splines of ``bench_jerk.py``: N = 200 segments (copp's stations are nearopt's
knots), |θ⃛| ≤ 50 rad/s³, |θ̈| ≤ 10 rad/s², the URDF's speed limits, no torque limits, no joint
damping (copp's third-order rows have no damping term), and r_i = ``--fraction`` times the
largest |u̇_i| of nearopt's timing under the jerk limit alone (so that it binds).

copp gets the torque rate as raw third-order rows at its stations,
√b (c' b + (m' + 2c) a + m a' + g') ≤ r and its negation, with the coefficients of
``nearopt.timing.rates`` (the same problem; checked to give ``add_jerk_limits``' profile to the
last digit when fed the jerk's own rows). Printed per path: the duration under the jerk limit
alone, then under both limits nearopt's duration, programs and wall time, copp's duration and
wall time, their ratios, and each one's largest |u̇| over the limit at 10 kHz in time (nearopt:
central differences of the torques of its states; copp: differences of the torques of θ(s(t))
from its own s(t) at 10 kHz, θ̇ and θ̈ by differences too).

    python scripts/bench_torque_rate.py [--paths 5] [--grid 200] [--fraction 0.5]
"""

from __future__ import annotations

import argparse
import time

import copp_py as copp
import numpy as np
from bench_jerk import ACCELERATION, JERK, copp_topp3, summary
from bench_timing import spline

import nearopt
from nearopt.timing import jerk_limited_timing, load_kernel
from nearopt.timing.jerk import SmoothTrajectory
from nearopt.timing.rates import torque_rate_coefficients

RATE = 10_000.0


def copp_torque_rate(
    robot: nearopt.Robot, path: nearopt.Path, sigma: np.ndarray, rate: np.ndarray
) -> tuple[float, float, np.ndarray]:
    """copp-py's TOPP3-LP with jerk, acceleration, speed and torque-rate rows
    (``bench_jerk.copp_topp3`` with the torque-rate rows added): (duration, wall time, s at
    10 kHz)."""

    def rows(crobot) -> None:
        q1, q2, q3 = path(sigma, 1), path(sigma, 2), np.asarray(path(sigma, 3))
        coef = torque_rate_coefficients(robot, path(sigma, 0), q1, q2, q3, path.s_end)
        limit = np.broadcast_to(rate, q1.shape).copy()
        for sign in (1.0, -1.0):
            crobot.constraints.add_constraint_3rd(
                sign * coef.dc, sign * (coef.dm + 2 * coef.c), sign * coef.m, sign * coef.dg,
                limit, 0,
            )  # fmt: skip

    return copp_topp3(robot, path, sigma, rows)


def copp_excess(robot: nearopt.Robot, path: nearopt.Path, s_t: np.ndarray, rate: np.ndarray):
    """copp's largest |u̇| over the limit: θ(s(t)) at 10 kHz, θ̇, θ̈ and u̇ by differences."""
    theta = path(np.clip(s_t, 0.0, path.s_end), 0)
    dt = 1.0 / RATE
    qd = (theta[2:] - theta[:-2]) / (2 * dt)
    qdd = (theta[2:] - 2 * theta[1:-1] + theta[:-2]) / dt**2
    u = robot.inverse_dynamics_batch(theta[1:-1], qd, qdd)
    return float(np.max(np.abs(np.diff(u, axis=0)) / dt / rate))


def nearopt_rates(robot: nearopt.Robot, motion: SmoothTrajectory) -> np.ndarray:
    """|u̇| at 10 kHz in time by central differences (±1e-6 s) of the motion's torques."""
    t = np.arange(0.0, motion.duration, 1.0 / RATE)
    torque = [robot.inverse_dynamics_batch(*motion.states(t + h)) for h in (1e-6, -1e-6)]
    return np.abs(torque[0] - torque[1]) / 2e-6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--paths", type=int, default=5)
    parser.add_argument("--grid", type=int, default=200)
    parser.add_argument("--fraction", type=float, default=0.5)
    args = parser.parse_args()
    robot = nearopt.Robot.from_name("panda").with_limits(
        damping=0.0, acceleration=ACCELERATION, effort=1e300
    )
    print(
        f"panda, N = {args.grid}, |jerk| <= {JERK:g} rad/s³, |qdd| <= {ACCELERATION:g} rad/s², "
        f"URDF speeds, |du/dt| <= {args.fraction:g} x its peak under the jerk limit alone; "
        f"copp-py {copp.version()}"
    )
    print(
        f"{'path':>4}{'jerk only [s]':>14}{'nearopt [s]':>13}{'its':>5}{'wall':>7}"
        f"{'copp [s]':>11}{'wall':>7}{'ratio':>8}{'wall':>7}{'rate/lim nearopt':>18}{'copp':>7}"
    )
    load_kernel()
    ratios, walls = [], []
    for seed in range(args.paths):
        path = spline(robot, seed)
        free = jerk_limited_timing(robot, path, JERK, grid=args.grid, torque=False)
        before = SmoothTrajectory(path, free, robot.inverse_dynamics_batch)
        rate = args.fraction * np.max(nearopt_rates(robot, before), axis=0)
        start = time.perf_counter()
        timing = jerk_limited_timing(
            robot, path, JERK, grid=args.grid, torque=False, torque_rate=rate
        )
        wall = time.perf_counter() - start
        motion = SmoothTrajectory(path, timing, robot.inverse_dynamics_batch)
        theirs, their_wall, s_t = copp_torque_rate(robot, path, timing.s, rate)
        ratios.append(timing.duration / theirs)
        walls.append(wall / their_wall)
        ours = float(np.max(nearopt_rates(robot, motion) / rate))
        print(
            f"{seed:>4}{free.duration:>14.4f}{timing.duration:>13.4f}{timing.iterations:>5}"
            f"{wall:>7.2f}{theirs:>11.4f}{their_wall:>7.2f}{ratios[-1]:>8.4f}{walls[-1]:>7.2f}"
            f"{ours:>18.4f}{copp_excess(robot, path, s_t, rate):>7.3f}",
            flush=True,
        )
    summary(ratios, walls)


if __name__ == "__main__":
    main()
