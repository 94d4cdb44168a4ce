"""Plans under a set duration: a sweep of T against the free plan, the straight line and IPOPT.

For seeded rest-to-rest motions of ur5 and panda (f0 = 1 + 1e-3 Σ u², URDF limits), T runs from
near the time-optimal plan's t_e to 1.5 times the free plan's. For each T: nearopt's plan with
``duration=T`` (t_e, J, wall time), the straight line timed to T (stage 1 alone), and the
independent reference — a direct transcription with CasADi + IPOPT (``scripts/ipopt_reference.py``,
K = 60 intervals of piecewise-constant torque, te fixed to T, two starts, validated by
re-simulation). J should not increase with T up to the free plan's t_e, and rise after it.

    python scripts/bench_duration.py [--arms ur5 panda] [--seeds 2]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

import nearopt

sys.path.insert(0, str(Path(__file__).resolve().parent))
import ipopt_reference as ref  # noqa: E402

WEIGHT = 1e-3
FRACTIONS = (0.25, 0.5, 0.75, 1.0)  # of the way from the time-optimal plan's t_e to the free one's
LONGER = (1.25, 1.5)  # times the free plan's t_e


def motion(robot: nearopt.Robot, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A start and goal within 40 % of each joint's range around its middle."""
    rng = np.random.default_rng(seed)
    lo = np.maximum(robot.limits.position_lower, -3.0)
    hi = np.minimum(robot.limits.position_upper, 3.0)
    mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    return mid + 0.4 * half * rng.uniform(-1, 1, robot.n), mid + 0.4 * half * rng.uniform(
        -1, 1, robot.n
    )


def row(robot: nearopt.Robot, q0: np.ndarray, qe: np.ndarray, duration: float) -> str:
    cost = nearopt.TorqueCost(WEIGHT)
    start = time.perf_counter()
    result = nearopt.plan(robot, q0, qe, cost, duration=duration, time_limit=120.0)
    wall = time.perf_counter() - start
    assert nearopt.verify_plan(result).passed
    try:
        line = f"{nearopt.plan(robot, q0, qe, cost, duration=duration, max_iterations=0).J:.6g}"
    except nearopt.InfeasiblePathError:
        line = "too slow"
    try:
        sol = ref.solve_reference(robot, q0, qe, WEIGHT, intervals=60, starts=2, duration=duration)
        ipopt = f"{sol.J:.6g} | {result.J / sol.J:.4f}"
    except RuntimeError:
        ipopt = "failed | –"
    return (
        f"| {duration:.4f} | {result.duration:.9f} | {result.J:.6g} | {line} | {ipopt} | "
        f"{wall:.2f} s |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--arms", nargs="+", default=["ur5", "panda"])
    parser.add_argument("--seeds", type=int, default=1)
    args = parser.parse_args()
    for name in args.arms:
        robot = nearopt.Robot.from_name(name)
        for seed in range(args.seeds):
            q0, qe = motion(robot, seed)
            free = nearopt.plan(robot, q0, qe, nearopt.TorqueCost(WEIGHT), time_limit=120.0)
            fastest = nearopt.plan(robot, q0, qe, time_limit=120.0).duration
            print(
                f"\n{name}, seed {seed}: time-optimal plan t_e {fastest:.4f} s; free plan "
                f"t_e {free.duration:.4f} s, J {free.J:.6g}\n"
            )
            print("| T [s] | nearopt t_e | nearopt J | line J | IPOPT J | nearopt/IPOPT | wall |")
            print("|---|---|---|---|---|---|---|")
            for duration in [fastest + f * (free.duration - fastest) for f in FRACTIONS] + [
                f * free.duration for f in LONGER
            ]:
                print(row(robot, q0, qe, duration), flush=True)


if __name__ == "__main__":
    main()
