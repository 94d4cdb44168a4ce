"""Benchmark: plans in a work cell (#11) — a table under the base, a post and a box.

For each arm, seeded start/goal pairs drawn within the joint limits, clear of the cell by the
margin, whose straight line collides (with the cell or the arm itself). Each pair is planned in
the cell (obstacles + self-collision, margin 1 cm) and without any collision checking. Printed:
success rate, J in the cell against J without obstacles, wall time (median, max) and the share
of it spent computing distances; every plan in the cell is re-checked at 1 kHz with coal by
``verify``. With ``--baseline REV``, the same pairs are planned by that commit's nearopt and by
this checkout, each in a child process of its own, one after the other (``git archive``, as
``bench_speed.py``), and printed side by side: J and wall time per pair, and per arm.

    python scripts/bench_cell.py [--pairs 6] [--arms ur5 panda xarm7] [--time-limit 60]
                                 [--seed 11] [--baseline REV]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np
from benchlib import ROOT, head, run_with, unpack

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
    parser.add_argument("--baseline", help="a commit to compare with, side by side")
    parser.add_argument("--json", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.baseline:
        side_by_side(args)
        return
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
                record(args, name, k, False, np.nan, free.J, wall)
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
            record(args, name, k, ok, result.J, free.J, wall)
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


def record(
    args: argparse.Namespace, arm: str, pair: int, ok: bool, j: float, j_free: float, wall: float
) -> None:
    """One pair as a JSON line (for :func:`side_by_side`), with ``--json``."""
    if args.json:
        line = {"arm": arm, "pair": pair, "ok": bool(ok), "J": j, "free": j_free, "wall": wall}
        print(json.dumps(line), flush=True)


def measure(path: Path, args: argparse.Namespace) -> dict[tuple[str, int], dict]:
    """This script's pairs planned with the nearopt in ``path``; its JSON lines by pair."""
    out = run_with(
        path, __file__, "--json", "--pairs", str(args.pairs), "--arms", *args.arms,
        "--time-limit", str(args.time_limit), "--seed", str(args.seed),
    )  # fmt: skip
    lines = [json.loads(line) for line in out.splitlines() if line.startswith("{")]
    return {(line["arm"], line["pair"]): line for line in lines}


def side_by_side(args: argparse.Namespace) -> None:
    """The pairs planned by ``args.baseline`` and by this checkout, printed side by side."""
    with tempfile.TemporaryDirectory() as tmp:
        old = measure(unpack(args.baseline, Path(tmp)), args)
    new = measure(ROOT, args)
    print(f"cell plans: {args.baseline} against this checkout ({head()}), seed {args.seed}")
    print(
        f"{'arm':7} {'pair':>4} {'J before':>9} {'J now':>9} {'ΔJ/J':>9} {'before [s]':>10} "
        f"{'now [s]':>8} {'speed-up':>8}"
    )
    for key, a in old.items():
        b = new[key]
        print(
            f"{key[0]:7} {key[1]:4d} {a['J']:9.5f} {b['J']:9.5f} {b['J'] / a['J'] - 1:+9.1e} "
            f"{a['wall']:10.2f} {b['wall']:8.2f} {a['wall'] / b['wall']:7.2f}×"
        )
    print(
        f"\n{'arm':7} {'success':>15} {'J/J free (median)':>21} {'wall median [s]':>16} "
        f"{'speed-up':>9}"
    )
    for arm in args.arms:
        a = [v for k, v in old.items() if k[0] == arm]
        b = [v for k, v in new.items() if k[0] == arm]

        def ratio(lines: list[dict]) -> float:
            return float(np.median([x["J"] / x["free"] for x in lines if x["ok"]] or [np.nan]))

        wa, wb = np.median([x["wall"] for x in a]), np.median([x["wall"] for x in b])
        print(
            f"{arm:7} {sum(x['ok'] for x in a):>5}/{len(a)} → {sum(x['ok'] for x in b)}/{len(b)} "
            f"{ratio(a):>10.3f} → {ratio(b):.3f} {wa:>9.2f} → {wb:.2f} {wa / wb:>8.2f}×"
        )


if __name__ == "__main__":
    main()
