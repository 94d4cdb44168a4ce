"""Benchmark: tool-pose goals on a redundant arm — J with the goal configuration optimised along
the pose against J with inverse kinematics' configuration fixed (#12).

Seeded panda motions from a random configuration to the tool pose of another, f0 = 1 + 0.001 Σu²;
every plan is verified (limits, J, the pose at t = te to 1e-8).

    python scripts/bench_goals.py [--cases 6]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import pinocchio as pin

import nearopt
from nearopt import ToolPose


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=6)
    parser.add_argument("--robot", default="panda")
    args = parser.parse_args()
    robot = nearopt.Robot.from_name(args.robot)
    rng = np.random.default_rng(7)
    lo = np.maximum(robot.limits.position_lower, -np.pi)
    hi = np.minimum(robot.limits.position_upper, np.pi)
    cost = nearopt.TorqueCost(0.001)
    print(f"{args.robot}: tool-pose goals, f0 = 1 + 0.001 Σu²")
    print(
        f"{'case':>4} {'J fixed θe':>11} {'J optimised':>12} {'ratio':>7} {'wall fixed':>11} "
        f"{'wall optimised':>15} {'verified':>9}"
    )
    ratios = []
    for k in range(args.cases):
        q0, qt = rng.uniform(lo, hi), rng.uniform(lo, hi)
        m = robot.frame_placement(qt)
        quat = pin.Quaternion(m.rotation)
        goal = ToolPose(m.translation, (quat.x, quat.y, quat.z, quat.w))
        t0 = time.perf_counter()
        fixed = nearopt.plan(robot, q0, goal, cost, optimise_goal=False)
        t1 = time.perf_counter()
        moved = nearopt.plan(robot, q0, goal, cost)
        t2 = time.perf_counter()
        ok = all(
            nearopt.verify(
                r.trajectory, robot, goal_pose=goal, cost=r.cost, J=r.J, simulate=False
            ).passed
            for r in (fixed, moved)
        )
        ratios.append(moved.J / fixed.J)
        print(
            f"{k:4d} {fixed.J:11.5f} {moved.J:12.5f} {moved.J / fixed.J:7.4f} "
            f"{t1 - t0:10.2f}s {t2 - t1:14.2f}s {str(ok):>9}",
            flush=True,
        )
    print(f"median ratio {np.median(ratios):.4f}, best {min(ratios):.4f}, worst {max(ratios):.4f}")


if __name__ == "__main__":
    main()
