"""Stage-1 benchmark: nearopt's optimal timing against copp-py's TOPP2-RA / COPP2-SOCP and TOPP-RA,
measured in one process on the same paths and knots.

Cases (the issue's): cubic splines through 6 seeded waypoints of each arm (damping 0: the peers'
torque rows cannot hold D θ' √b), rest at both ends, the same N + 1 knots for every solver:

* ``speed+acc``: joint speed limits and |θ̈_i| ≤ 10 rad/s² (no torque limits), time-optimal;
* ``torque``: torque (RNEA; the peers through a Python ``pin.rnea`` callback, included in their
  time) and speed limits, time-optimal;
* ``energy``: J = ∫(1 + 1e-3 Σ u_i²) dt under torque and speed limits (copp's COPP2-SOCP, with
  the sign of gravity in its cost corrected, see ``peers.py``).

For each: the median wall time of ``nearopt.optimal_timing`` (sampling the path with Pinocchio,
the solve, and the check of the limits between the samples), of its solve alone
(``solve_timing`` on the built problem), and of the peers; the durations (nearopt's own holds
the limits between the knots too, so it is a little longer; "knots" is nearopt at the knots
only, the peers' problem) and the discretised J of the solve against Clarabel's SOCP on the same
rows (``--reference``; inf where Clarabel fails).
Then the growth of the stage-1 time with N, and (``--sweep``) a robustness sweep over seeded
paths × grids × limit scales on three arms.

    python scripts/bench_timing.py [--robots panda ur5] [--grids 200 1000] [--paths 5]
                                   [--repeat 3] [--sweep] [--reference]
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np
import peers
from benchlib import median_time

import nearopt
from nearopt.cost import TimeCost, TorqueCost
from nearopt.timing import TimingMethod, build_timing_problem, solve_timing
from nearopt.trajectory import segment_times

ENERGY = TorqueCost(1e-3)
ACCELERATION = 10.0  # rad/s²


def spline(robot: nearopt.Robot, seed: int) -> nearopt.SplinePath:
    """A cubic spline through 6 waypoints drawn within the position limits (±π at most)."""
    rng = np.random.default_rng(seed)
    lo = np.maximum(robot.limits.position_lower, -np.pi)
    hi = np.minimum(robot.limits.position_upper, np.pi)
    return nearopt.SplinePath(np.linspace(0.0, 1.0, 6), rng.uniform(lo, hi, size=(6, robot.n)))


def arm(name: str, case: str) -> nearopt.Robot:
    robot = nearopt.Robot.from_name(name).with_limits(damping=0.0)
    if case == "speed+acc":
        return robot.with_limits(acceleration=ACCELERATION, effort=1e300)
    return robot


def knots_only(problem: nearopt.timing.TimingProblem) -> nearopt.timing.TimingProblem:
    """The peers' problem: limits at the knots only."""
    return dataclasses.replace(problem, interior_speed=None, interior=None)


def peer(
    case: str, robot: nearopt.Robot, path: nearopt.Path, sigma: np.ndarray, which: str
) -> peers.PeerResult:
    acc = np.full(robot.n, ACCELERATION) if case == "speed+acc" else None
    torque = case != "speed+acc"
    if case == "energy":
        if which != "copp":
            raise ValueError(which)
        return peers.copp_copp2_socp_energy(robot, path, sigma, ENERGY.torque_weights(robot.n))
    solve = peers.copp_topp2_ra if which == "copp" else peers.toppra_duration
    return solve(robot, path, sigma, torque=torque, acceleration=acc)


def comparison(args: argparse.Namespace) -> None:
    print("\nnearopt against its peers (median of repeats; times in ms; durations in s)")
    head = (
        f"{'robot':<7}{'case':<10}{'N':>5}{'path':>5}{'ours':>8}{'solve':>7}{'copp':>7}"
        f"{'toppra':>8}{'ours/copp':>10}{'te ours':>12}{'te knots':>12}{'te copp':>12}"
        f"{'knots/copp-1':>13}{'J ours':>11}{'J/ref-1':>9}"
    )
    print(head)
    ratios: dict[tuple[str, str, int], list[float]] = {}
    topp2: dict[tuple[str, int, int], float] = {}  # copp TOPP2-RA's time, torque case
    for name in args.robots:
        for case in ("speed+acc", "torque", "energy"):
            robot = arm(name, case)
            cost = ENERGY if case == "energy" else TimeCost()
            for grid in args.grids:
                for seed in range(args.paths):
                    path = spline(robot, seed)
                    t_ours, ours = median_time(
                        lambda: nearopt.optimal_timing(robot, path, cost, grid=grid), args.repeat
                    )
                    problem = build_timing_problem(robot, path, grid=grid)
                    t_solve, solved = median_time(lambda: solve_timing(problem, cost), args.repeat)
                    knots = solve_timing(knots_only(problem), cost)
                    te_knots = segment_times(problem.sigma, knots.b).sum()
                    try:
                        t_copp, copp = median_time(
                            lambda: peer(case, robot, path, problem.sigma, "copp"), args.repeat
                        )
                        te_copp = copp.duration
                    except RuntimeError as exc:  # the peer failed: say so, keep going
                        print(f"  copp failed on {name} {case} N = {grid} path {seed}: {exc}")
                        t_copp = te_copp = np.nan
                    t_topp = np.nan
                    if case != "energy":
                        t_topp, _ = median_time(
                            lambda: peer(case, robot, path, problem.sigma, "toppra"), args.repeat
                        )
                    rel = np.nan
                    if args.reference:
                        try:
                            ref = solve_timing(problem, cost, method=TimingMethod.SOCP)
                            rel = solved.objective / ref.objective - 1.0
                        except nearopt.SolverError:
                            rel = np.inf  # Clarabel did not solve it
                    ratio = t_ours / t_copp
                    ratios.setdefault((name, case, grid), []).append(ratio)
                    if case == "torque":
                        topp2[(name, grid, seed)] = t_copp
                    if case == "energy":  # the yardstick: copp's time-optimal TOPP2-RA
                        ratios.setdefault((name, "energy/RA", grid), []).append(
                            t_ours / topp2.get((name, grid, seed), np.nan)
                        )
                    print(
                        f"{name:<7}{case:<10}{grid:>5}{seed:>5}{1e3 * t_ours:>8.1f}"
                        f"{1e3 * t_solve:>7.1f}{1e3 * t_copp:>7.1f}{1e3 * t_topp:>8.1f}"
                        f"{ratio:>10.1f}{ours.duration:>12.6f}{te_knots:>12.6f}"
                        f"{te_copp:>12.6f}{te_knots / te_copp - 1:>13.1e}"
                        f"{ours.J:>11.6f}{rel:>9.1e}",
                        flush=True,
                    )
    print(
        "\nmedian ratio of wall times, nearopt optimal_timing / copp (its Pinocchio callbacks "
        "included; energy: against COPP2-SOCP, energy/RA: against TOPP2-RA's time-optimal "
        "solve of the same path)"
    )
    for (name, case, grid), values in ratios.items():
        print(f"  {name:<7}{case:<10}N = {grid:<6}{np.nanmedian(values):6.1f}×")


def growth(args: argparse.Namespace) -> None:
    """Stage-1 time against N (torque + speed, time-optimal), and its exponent."""
    print("\nstage-1 time against N (panda, torque + speed, time-optimal; median ms)")
    robot = arm("panda", "torque")
    path = spline(robot, 0)
    grids = [100, 200, 500, 1000, 2000, 5000]
    totals, solves = [], []
    for grid in grids:
        t_all, res = median_time(
            lambda: nearopt.optimal_timing(robot, path, grid=grid), args.repeat
        )
        problem = build_timing_problem(robot, path, grid=grid)
        t_solve, sol = median_time(lambda: solve_timing(problem, TimeCost()), args.repeat)
        totals.append(t_all)
        solves.append(t_solve)
        print(
            f"  N = {grid:>5}: optimal_timing {1e3 * t_all:8.1f}, solve {1e3 * t_solve:7.1f} "
            f"({sol.iterations} iterations), te {res.duration:.6f} s",
            flush=True,
        )
    for label, values in (("optimal_timing", totals), ("solve", solves)):
        slope = np.polyfit(np.log(grids), np.log(values), 1)[0]
        print(f"  {label}: time ∝ N^{slope:.2f} from N = {grids[0]} to {grids[-1]}")


def random_path(robot: nearopt.Robot, rng: np.random.Generator, kind: str) -> nearopt.Path:
    lo = np.maximum(robot.limits.position_lower, -np.pi)
    hi = np.minimum(robot.limits.position_upper, np.pi)
    q0, qe = rng.uniform(lo, hi), rng.uniform(lo, hi)
    if kind == "straight":
        return nearopt.StraightPath(q0, qe)
    count = int(rng.integers(3, 9))
    at = np.linspace(0.0, 1.0, count + 2)
    if kind == "bspline":
        at = nearopt.BSplinePath.greville(count + 2)
    points = q0 + np.outer(at, qe - q0)
    points[1:-1] += rng.normal(scale=0.25, size=(count, robot.n)) * np.abs(qe - q0)
    return nearopt.SplinePath(at, points) if kind == "spline" else nearopt.BSplinePath(points)


def sweep(args: argparse.Namespace) -> None:
    """Seeded paths × N × with and without acceleration limits × limit scales, three arms: every
    problem solved by the kernel (no fallback), compared with Clarabel where it solves (N ≤ 1000,
    one case in five)."""
    print("\nrobustness sweep (the kernel alone must solve every problem)")
    grids = [100, 200, 1000, 5000]
    scales = (1e-3, 1.0, 1e3, 1e12)
    solved = fallbacks = failures = compared = 0
    worst = -np.inf
    for name in ("two_link", "ur5", "panda"):
        base = nearopt.Robot.from_name(name)
        rng = np.random.default_rng(5)
        for k in range(args.sweep_paths):
            kind = ("straight", "spline", "bspline")[k % 3]
            path = random_path(base, rng, kind)
            scale = scales[(k // 3) % len(scales)]
            cost = (TimeCost(), ENERGY)[k % 2]
            for acc in (np.inf, ACCELERATION):
                robot = base.with_limits(
                    acceleration=acc * scale, velocity=np.asarray(base.limits.velocity) * scale
                )
                for grid in grids:
                    try:
                        problem = build_timing_problem(robot, path, grid=grid)
                        sol = solve_timing(problem, cost)
                    except nearopt.InfeasiblePathError:
                        continue
                    except nearopt.NearoptError as exc:
                        failures += 1
                        print(
                            f"  FAILED {name} path {k} ({kind}) N = {grid} scale {scale:g} "
                            f"acc {acc:g}: {exc}",
                            flush=True,
                        )
                        continue
                    solved += 1
                    if sol.solver != TimingMethod.INTERIOR:
                        fallbacks += 1
                        print(
                            f"  fallback {name} path {k} N = {grid} scale {scale:g}: {sol.message}",
                            flush=True,
                        )
                    if grid <= 1000 and k % 5 == 0:
                        try:
                            ref = solve_timing(problem, cost, method=TimingMethod.SOCP)
                        except nearopt.SolverError:
                            continue
                        compared += 1
                        worst = max(worst, sol.objective / ref.objective - 1.0)
    print(
        f"  {solved} problems solved, {fallbacks} by the fallback, {failures} failed; "
        f"against Clarabel ({compared} compared): J ours / J Clarabel − 1 ≤ {worst:.1e}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", nargs="+", default=["panda", "ur5"])
    parser.add_argument("--grids", nargs="+", type=int, default=[200, 1000])
    parser.add_argument("--paths", type=int, default=5, help="seeded splines per case")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument(
        "--reference", action="store_true", help="compare J with Clarabel's SOCP on the same rows"
    )
    parser.add_argument("--sweep", action="store_true", help="run the robustness sweep too")
    parser.add_argument("--sweep-paths", type=int, default=36)
    args = parser.parse_args()
    start = time.perf_counter()
    nearopt.optimal_timing(
        arm("two_link", "torque"), spline(arm("two_link", "torque"), 0)
    )  # numba's cold start
    print(
        f"first stage-1 call of the process (numba loads its compiled kernel): "
        f"{time.perf_counter() - start:.2f} s"
    )
    comparison(args)
    growth(args)
    if args.sweep:
        sweep(args)


if __name__ == "__main__":
    main()
