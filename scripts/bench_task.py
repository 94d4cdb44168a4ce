"""Benchmark: 4-target tasks on the panda (#12) — wall time, and J with every goal configuration
optimised along its pose against J with inverse kinematics' configurations fixed.

Cases: the pick-and-place task of scripts/02_pick_and_place.py in its cell (table and wall,
margin 1 cm), and seeded tasks of four tool poses (each the pose of a random configuration,
reached from the previous one; the 2nd and 4th stopped at, the others passed through) without
obstacles. f0 = 1 + 0.001 Σu². Every plan is verified (limits, targets, rest at the stops, the
clearance, J, forward simulation).

    python scripts/bench_task.py [--random 3]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import pinocchio as pin

import nearopt
from nearopt import Target, ToolPose

HERE = Path(__file__).resolve().parent


def random_task(robot: nearopt.Robot, rng: np.random.Generator) -> tuple[np.ndarray, list]:
    """A start and four tool-pose targets of random configurations (passes, stops, passes,
    stops)."""
    lo = np.maximum(robot.limits.position_lower, -np.pi)
    hi = np.minimum(robot.limits.position_upper, np.pi)
    mid, half = 0.5 * (lo + hi), 0.4 * (hi - lo)
    q0 = rng.uniform(mid - half, mid + half)
    targets = []
    for k in range(4):
        m = robot.frame_placement(rng.uniform(mid - half, mid + half))
        quat = pin.Quaternion(m.rotation)
        targets.append(
            Target(
                ToolPose(m.translation, (quat.x, quat.y, quat.z, quat.w)),
                stop=k % 2 == 1,
                name=f"p{k + 1}",
            )
        )
    return q0, targets


def run(
    robot: nearopt.Robot,
    q0: np.ndarray,
    targets: list,
    cost: nearopt.Cost,
    scene: nearopt.Scene | None,
    optimise: bool,
) -> tuple[nearopt.TaskResult, float, bool]:
    t0 = time.perf_counter()
    result = nearopt.plan_task(
        robot, q0, targets, cost, nearopt.PlanSettings(scene=scene, optimise_goal=optimise)
    )
    wall = time.perf_counter() - t0
    report = nearopt.verify(
        result.trajectory,
        robot,
        q0=q0,
        goal_pose=result.goal,
        waypoints=result.waypoints,
        cost=cost,
        J=result.J,
        collisions=result.collisions,
    )
    return result, wall, report.passed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--random", type=int, default=3, help="seeded random tasks")
    args = parser.parse_args()
    robot = nearopt.Robot.from_name("panda")
    cost = nearopt.TorqueCost(0.001)
    task = nearopt.Task.from_file(HERE / "tasks" / "pick_and_place.toml")
    cell = nearopt.Scene.from_file(HERE / "tasks" / "pick_and_place_cell.toml")
    cases = [("pick-and-place, cell", np.asarray(task.start), list(task.targets), cell)]
    rng = np.random.default_rng(12)
    for k in range(args.random):
        q0, targets = random_task(robot, rng)
        cases.append((f"random {k + 1}, free", q0, targets, None))
    print(f"panda, 4 tool-pose targets per task, f0 = {cost.describe()}")
    print(
        f"{'task':22} {'segments':>8} {'J fixed θe':>11} {'J optimised':>12} {'ratio':>7} "
        f"{'te [s]':>7} {'wall fixed':>11} {'wall optimised':>15} {'verified':>9}"
    )
    ratios, walls = [], []
    for name, q0, targets, scene in cases:
        try:
            fixed, wall_fixed, ok_fixed = run(robot, q0, targets, cost, scene, False)
            moved, wall_moved, ok_moved = run(robot, q0, targets, cost, scene, True)
        except nearopt.NearoptError as exc:
            print(f"{name:22} failed: {type(exc).__name__}: {exc}")
            continue
        ratios.append(moved.J / fixed.J)
        walls.append(wall_moved)
        print(
            f"{name:22} {len(moved.segments):8d} {fixed.J:11.5f} {moved.J:12.5f} "
            f"{moved.J / fixed.J:7.4f} {moved.duration:7.3f} {wall_fixed:10.1f}s "
            f"{wall_moved:14.1f}s {str(ok_fixed and ok_moved):>9}",
            flush=True,
        )
    if ratios:
        print(
            f"J optimised / J fixed: median {np.median(ratios):.4f} (best {min(ratios):.4f}, "
            f"worst {max(ratios):.4f}); wall time (optimised) median {np.median(walls):.1f} s, "
            f"max {max(walls):.1f} s"
        )


if __name__ == "__main__":
    main()
