"""Benchmark: plans in a work cell (#11) — a table under the base, a post and a box.

For each arm, seeded start/goal pairs drawn within the joint limits, clear of the cell by the
margin, whose straight line collides (with the cell or the arm itself). Each pair is planned in
the cell (obstacles + self-collision, margin 1 cm) and without any collision checking. Printed:
success rate, J in the cell against J without obstacles, wall time (median, max) and the share
of it spent computing distances; every plan in the cell is re-checked at 1 kHz with coal by
``verify``.

    python scripts/bench_cell.py [--pairs 6] [--arms ur5 panda xarm7] [--time-limit 60]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import nearopt
from nearopt import CollisionError, NearoptError, TorqueCost
from nearopt.collision import Box, CollisionModel, Cylinder, Obstacle, Scene
from nearopt.path import StraightPath

CELL = Scene(
    (
        Obstacle("table", Box((1.6, 1.6, 0.04)), (0.0, 0.0, -0.03)),
        Obstacle("post", Cylinder(0.05, 1.0), (0.45, 0.0, 0.5)),
        Obstacle("box", Box((0.25, 0.25, 0.25)), (0.3, -0.45, 0.125)),
    ),
    margin=0.01,
)


def pairs_for(
    robot: nearopt.Robot, cm: CollisionModel, count: int, seed: int
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Start/goal pairs clear of the cell whose straight line is not (seeded)."""
    rng = np.random.default_rng(seed)
    lo = np.maximum(robot.limits.position_lower, -np.pi)
    hi = np.minimum(robot.limits.position_upper, np.pi)
    # stay within 80 % of each range: the extremes of a joint rarely make a work-cell motion
    mid, half = 0.5 * (lo + hi), 0.4 * (hi - lo)
    out: list[tuple[np.ndarray, np.ndarray]] = []
    while len(out) < count:
        q0, qe = rng.uniform(mid - half, mid + half, (2, robot.n))
        if min(cm.distances(q0).min(), cm.distances(qe).min()) < 2 * cm.margin:
            continue
        if cm.path_clearance(StraightPath(q0, qe)).certified:
            continue
        out.append((q0, qe))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=int, default=6)
    parser.add_argument("--arms", nargs="+", default=["ur5", "panda", "xarm7"])
    parser.add_argument("--time-limit", type=float, default=60.0)
    parser.add_argument("--seed", type=int, default=11)
    args = parser.parse_args()
    cost = TorqueCost(0.001)
    print(
        f"cell: {', '.join(o.name for o in CELL.obstacles)}, margin {CELL.margin} m; "
        f"f0 = 1 + 0.001 Σu²; {args.pairs} seeded pairs per arm whose straight line collides\n"
    )
    header = (
        f"{'arm':7} {'pair':>4} {'status':>10} {'J cell':>9} {'J free':>9} {'ratio':>6} "
        f"{'wall [s]':>8} {'dist [s]':>8} {'clear [mm]':>10}"
    )
    rows = []
    for name in args.arms:
        robot = nearopt.Robot.from_name(name)
        cm = CollisionModel(robot, CELL)
        print(f"{name}: {len(cm.pairs)} pairs checked")
        print(header)
        for k, (q0, qe) in enumerate(pairs_for(robot, cm, args.pairs, args.seed)):
            free = nearopt.plan(robot, q0, qe, cost, time_limit=args.time_limit)
            model = CollisionModel(robot, CELL)
            t0 = time.perf_counter()
            try:
                result = nearopt.plan(robot, q0, qe, cost, scene=model, time_limit=args.time_limit)
            except (CollisionError, NearoptError) as exc:
                wall = time.perf_counter() - t0
                rows.append((name, False, np.nan, wall, model.seconds))
                print(
                    f"{name:7} {k:4d} {'failed':>10} {'':>9} {free.J:9.5f} {'':>6} "
                    f"{wall:8.2f} {model.seconds:8.2f}   {type(exc).__name__}: {exc}"
                )
                continue
            wall = time.perf_counter() - t0
            report = nearopt.verify(
                result.trajectory,
                robot,
                rate=1000.0,
                q0=q0,
                qe=qe,
                collisions=CollisionModel(robot, CELL),
                simulate=False,
            )
            ok = report.passed
            clear = -next(c.worst for c in report.checks if c.name.startswith("clearance"))
            clear += CELL.margin
            rows.append((name, ok, result.J / free.J, wall, model.seconds))
            print(
                f"{name:7} {k:4d} {str(result.status) if ok else 'UNVERIFIED':>10} "
                f"{result.J:9.5f} {free.J:9.5f} {result.J / free.J:6.3f} {wall:8.2f} "
                f"{model.seconds:8.2f} {clear * 1e3:10.1f}",
                flush=True,
            )
        print()
    print("summary")
    print(
        f"{'arm':7} {'success':>8} {'J/J free (median)':>18} {'wall median':>12} "
        f"{'wall max':>9} {'distances':>10}"
    )
    for name in args.arms:
        mine = [r for r in rows if r[0] == name]
        ok = [r for r in mine if r[1]]
        walls = np.array([r[3] for r in mine])
        share = sum(r[4] for r in mine) / max(walls.sum(), 1e-9)
        print(
            f"{name:7} {len(ok):>4}/{len(mine):<3} "
            f"{np.median([r[2] for r in ok]) if ok else np.nan:18.3f} "
            f"{np.median(walls):11.2f}s {walls.max():8.2f}s {100 * share:9.0f}%"
        )


if __name__ == "__main__":
    main()
