"""Plans under jerk limits (#26): stage 2 under the limits against the better of the two paths
timed under them.

For seeded rest-to-rest motions (configurations within 40 % of each joint's range around its
middle, URDF limits, f0 = 1 + 1e-3 Σ u²) and two jerk limits per arm, prints the J under the
jerk limit (``time_with_jerk_limits`` on the plan's grid, 200) of

- the straight line (the plan's first path),
- the path stage 2 finds without the jerk limit,
- the plan with the limit (``nearopt.plan``: the better of those two, then stage 2 under the
  limits from it, :func:`nearopt.planning.smooth_iterations`),

the plan's gain over the better of the first two, its iterations under the limits, its wall
time, and whether ``verify_plan`` passes (the jerk at every 1 kHz sample, the torques by
forward simulation).

    python scripts/bench_jerk_plans.py [--arms ur5 panda two_link] [--seeds 2]
"""

from __future__ import annotations

import argparse
import re
import time

import numpy as np
from bench_duration import motion

import nearopt
from nearopt.timing import load_kernel, time_with_jerk_limits

WEIGHT = 1e-3
JERKS = {"ur5": (30.0, 300.0), "panda": (50.0, 500.0), "two_link": (300.0, 3000.0)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--arms", nargs="+", default=list(JERKS))
    parser.add_argument("--seeds", type=int, default=2)
    args = parser.parse_args()
    load_kernel()
    cost = nearopt.TorqueCost(WEIGHT)
    print(
        "| arm | seed | jerk [rad/s³] | line | found without | plan | gain | its | wall "
        "| verified |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    gains = []
    for name in args.arms:
        free_robot = nearopt.Robot.from_name(name)
        for seed in range(args.seeds):
            q0, qe = motion(free_robot, seed)
            free = nearopt.plan(free_robot, q0, qe, cost)
            for jerk in JERKS[name]:
                robot = free_robot.with_limits(jerk=jerk)
                line = nearopt.plan(robot, q0, qe, cost, max_iterations=0).J
                found = time_with_jerk_limits(robot, free.trajectory.path, cost).J
                start = time.perf_counter()
                result = nearopt.plan(robot, q0, qe, cost)
                wall = time.perf_counter() - start
                before = min(line, found)
                gains.append(result.J / before - 1.0)
                found_its = re.search(r"from there: .* in (\d+) iteration", result.message)
                smooth = int(found_its.group(1)) if found_its else 0
                ok = nearopt.verify_plan(result).passed
                print(
                    f"| {name} | {seed} | {jerk:g} | {line:.6g} | {found:.6g} | {result.J:.6g} | "
                    f"{100 * gains[-1]:+.2f} % | {smooth} | {wall:.1f} s | "
                    f"{'yes' if ok else 'NO'} |",
                    flush=True,
                )
    print(
        f"plan / better of line and found: median {100 * np.median(gains):+.2f} %, "
        f"best {100 * np.min(gains):+.2f} %, worst {100 * np.max(gains):+.2f} %"
    )


if __name__ == "__main__":
    main()
