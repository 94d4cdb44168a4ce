"""Jerk-limited timing against copp-py's TOPP3-LP (#26), on the stage-1 comparison's seeded panda
splines (cubic splines through 6 waypoints, ``bench_timing.spline``): N = 200 segments (nearopt's
grid with the spline's breakpoints; copp's stations are the same knots), |θ⃛| ≤ 50 rad/s³,
|θ̈| ≤ 10 rad/s², the URDF's speed limits, no torque limits, no joint damping.

Printed per path: the time-optimal duration without a jerk limit (nearopt's stage 1), nearopt's
jerk-limited duration, its convex programs and wall time (its banded kernel), the same with
Clarabel's SOCP for every program (``method=SOCP``, the solver it had before), copp's
TOPP3-LP duration (linearised at its TOPP2-RA profile, then twice at its own) and wall time,
the ratios of duration and wall time, and each one's largest
|θ⃛| over the limit *between* the stations, sampled at 10 kHz in time (nearopt: θ⃛ in closed form
at s(t); copp: third differences of θ(s(t)) from its own s(t) interpolation).

    python scripts/bench_jerk.py [--paths 5] [--grid 200]
"""

from __future__ import annotations

import argparse
import time

import copp_py as copp
import numpy as np
from bench_timing import spline

import nearopt
from nearopt.timing import TimingMethod, jerk_limited_timing, load_kernel, optimal_timing

JERK, ACCELERATION, RATE = 50.0, 10.0, 10_000.0


def copp_topp3(robot: nearopt.Robot, path: nearopt.Path, sigma: np.ndarray, rows=None):
    """copp-py's TOPP3-LP: (duration, wall time, s at 10 kHz); ``rows(crobot)`` adds more rows
    (its clock included)."""
    start = time.perf_counter()
    crobot = copp.Robot(robot.n, capacity=sigma.size)
    crobot.append_s(sigma)
    crobot.set_q(path(sigma, 0), path(sigma, 1), path(sigma, 2), 0, dddq=path(sigma, 3))
    v, a, j = robot.limits.velocity, np.full(robot.n, ACCELERATION), np.full(robot.n, JERK)
    crobot.add_velocity_limits(v, -v, start_idx_s=0, length=sigma.size)
    crobot.add_acceleration_limits(a, -a, start_idx_s=0, length=sigma.size)
    crobot.add_jerk_limits(j, -j, start_idx_s=0, length=sigma.size)
    if rows is not None:
        rows(crobot)
    ra = copp.solver.topp2_ra
    first = ra.Problem(
        crobot.constraints, idx_s_interval=(0, sigma.size - 1), a_boundary=(0.0, 0.0)
    )
    a_lin, b_lin = np.maximum(np.asarray(ra.solve(first, ra.Options())), 1e-6), None
    for _ in range(3):
        problem = copp.solver.topp3_lp.Problem(
            crobot.constraints, a_lin, b_linearization=b_lin, num_stationary_max=1
        )
        profile = copp.solver.topp3_lp.solve(problem)
        a_lin, b_lin = np.maximum(np.asarray(profile.a), 1e-10), np.asarray(profile.b)
    wall = time.perf_counter() - start
    duration, t_s = copp.interpolation.s_to_t_topp3(sigma, profile)
    s_t = copp.interpolation.t_to_s_topp3_uniform(sigma, profile, t_s, 1.0 / RATE)
    return duration, wall, np.asarray(s_t)


def copp_jerk(path: nearopt.Path, s_t: np.ndarray) -> float:
    """The largest |θ⃛| over the limit, by third differences of θ(s(t)) at 10 kHz."""
    theta = path(np.clip(s_t, 0.0, path.s_end), 0)
    third = np.diff(theta, 3, axis=0) * RATE**3
    return float(np.max(np.abs(third)) / JERK)


def nearopt_jerk(timing: nearopt.timing.JerkTiming, path: nearopt.Path) -> float:
    """The largest |θ⃛| over the limit at 10 kHz in time (θ⃛ in closed form at s(t))."""
    x = np.linspace(0.0, 1.0, 2001)
    s = np.unique((timing.s[:-1, None] + x[None, :] * np.diff(timing.s)[:, None]).ravel())
    t = timing.time_at(s)
    at = np.interp(np.arange(0.0, timing.duration, 1.0 / RATE), t, s)[1:]
    b, a, da = timing.evaluate(at)
    q1, q2, q3 = path(at, 1), path(at, 2), np.asarray(path(at, 3))
    jerk = np.sqrt(b)[:, None] * (q3 * b[:, None] + 3 * q2 * a[:, None] + q1 * da[:, None])
    return float(np.max(np.abs(jerk)) / JERK)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--paths", type=int, default=5)
    parser.add_argument("--grid", type=int, default=200)
    args = parser.parse_args()
    robot = nearopt.Robot.from_name("panda").with_limits(
        damping=0.0, acceleration=ACCELERATION, effort=1e300
    )
    print(
        f"panda, N = {args.grid}, |jerk| <= {JERK:g} rad/s³, |qdd| <= {ACCELERATION:g} rad/s², "
        f"URDF speeds; copp-py {copp.version()}"
    )
    print(
        f"{'path':>4}{'no jerk [s]':>12}{'nearopt [s]':>13}{'its':>5}{'wall':>7}"
        f"{'SOCP [s]':>10}{'wall':>7}"
        f"{'copp [s]':>11}{'wall':>7}{'ratio':>8}{'wall':>7}{'jerk/lim nearopt':>18}{'copp':>7}"
    )
    load_kernel()  # the compiled loops loaded before the clock starts
    ratios, walls = [], []
    for seed in range(args.paths):
        path = spline(robot, seed)
        free = optimal_timing(robot, path, grid=args.grid).duration
        start = time.perf_counter()
        timing = jerk_limited_timing(robot, path, JERK, grid=args.grid, torque=False)
        wall = time.perf_counter() - start
        start = time.perf_counter()
        clarabel = jerk_limited_timing(
            robot, path, JERK, grid=args.grid, torque=False, method=TimingMethod.SOCP
        ).duration
        socp = time.perf_counter() - start
        theirs, their_wall, s_t = copp_topp3(robot, path, timing.s)
        ratios.append(timing.duration / theirs)
        walls.append(wall / their_wall)
        print(
            f"{seed:>4}{free:>12.4f}{timing.duration:>13.4f}{timing.iterations:>5}{wall:>7.2f}"
            f"{clarabel:>10.4f}{socp:>7.2f}{theirs:>11.4f}{their_wall:>7.2f}{ratios[-1]:>8.4f}{walls[-1]:>7.2f}"
            f"{nearopt_jerk(timing, path):>18.4f}{copp_jerk(path, s_t):>7.3f}",
            flush=True,
        )
    summary(ratios, walls)


def summary(ratios: list[float], walls: list[float]) -> None:
    """The last line: nearopt / copp's durations and wall times, median and largest."""
    print(
        f"nearopt / copp TOPP3-LP: duration median {np.median(ratios):.4f}, max "
        f"{np.max(ratios):.4f}; wall time median {np.median(walls):.2f}, max {np.max(walls):.2f}"
    )


if __name__ == "__main__":
    main()
