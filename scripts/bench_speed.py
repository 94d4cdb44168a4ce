"""Whole plans against an earlier commit, side by side in one run (#24), and the paper's example
against CasADi + IPOPT.

The earlier commit (``--baseline``, default 5c1e9b0: where the speed issue started) is unpacked
with ``git archive`` into a temporary folder; the same cases are planned by it and by this
checkout, each in a child process of its own (the same interpreter and packages, a first plan
to load what it needs), one after the other. Cases: the paper's example, and seeded free-space
motions of ur5 and panda (the planner's defaults, URDF limits) for f0 = 1 + 0.001 Σ u² and
time-optimal. Printed per case: J of both and their relative difference, wall times and the
speed-up; the median speed-up per cost. Then the paper's example against its direct
transcription by CasADi + IPOPT (K = 100, built and solved, ``bench_planner.ipopt_two_link``) in
this process: the ratio of the wall times.

    python scripts/bench_speed.py [--baseline 5c1e9b0] [--seeds 4] [--repeat 1]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from benchlib import ROOT, head, run_with, unpack

COSTS = {"energy": 0.001, "time": 0.0}


def cases(seeds: int) -> list[tuple[str, str, int]]:
    """(arm, cost, seed) of every case; the paper's example first."""
    out = [("two_link", "paper", 0)]
    for arm in ("ur5", "panda"):
        for cost in COSTS:
            out += [(arm, cost, seed) for seed in range(1, seeds + 1)]
    return out


def worker(seeds: int, repeat: int) -> None:
    """Plan every case with the nearopt on the path; one JSON line per case."""
    import nearopt
    from nearopt.paper_example import COST, THETA_0, THETA_E

    robots = {name: nearopt.Robot.from_name(name) for name in ("two_link", "ur5", "panda")}
    nearopt.plan(robots["two_link"], THETA_0, THETA_E, COST)  # loads what a process needs
    for arm, cost, seed in cases(seeds):
        robot = robots[arm]
        if cost == "paper":
            q0, qe, f0 = THETA_0, THETA_E, COST
        else:
            rng = np.random.default_rng(seed)
            lo = np.maximum(robot.limits.position_lower, -np.pi)
            hi = np.minimum(robot.limits.position_upper, np.pi)
            mid, half = 0.5 * (lo + hi), 0.3 * (hi - lo)
            q0, qe = rng.uniform(mid - half, mid + half, (2, robot.n))
            f0 = nearopt.TorqueCost(COSTS[cost])
        walls = []
        for _ in range(repeat):
            start = time.perf_counter()
            result = nearopt.plan(robot, q0, qe, f0)
            walls.append(time.perf_counter() - start)
        line = {"case": [arm, cost, seed], "J": result.J, "wall": float(np.median(walls))}
        print(json.dumps(line), flush=True)


def measure(path: Path, seeds: int, repeat: int) -> dict[tuple, dict]:
    """Run the worker with ``path`` first on PYTHONPATH; its lines by case."""
    out = run_with(path, __file__, "--worker", "--seeds", str(seeds), "--repeat", str(repeat))
    lines = [json.loads(line) for line in out.splitlines() if line.startswith("{")]
    return {tuple(line["case"]): line for line in lines}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", default="5c1e9b0")
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        worker(args.seeds, args.repeat)
        return
    with tempfile.TemporaryDirectory() as tmp:
        old = measure(unpack(args.baseline, Path(tmp)), args.seeds, args.repeat)
    new = measure(ROOT, args.seeds, args.repeat)
    print(f"whole plans: {args.baseline} against this checkout ({head()}), median of {args.repeat}")
    print(
        f"{'arm':<10}{'cost':<8}{'seed':>5}{'J before':>12}{'J now':>12}{'ΔJ/J':>10}"
        f"{'before [s]':>12}{'now [s]':>9}{'speed-up':>10}"
    )
    ups: dict[str, list[float]] = {}
    for key in old:
        a, b = old[key], new[key]
        up = a["wall"] / b["wall"]
        ups.setdefault(key[1], []).append(up)
        print(
            f"{key[0]:<10}{key[1]:<8}{key[2]:>5}{a['J']:>12.6f}{b['J']:>12.6f}"
            f"{b['J'] / a['J'] - 1:>+10.1e}{a['wall']:>12.2f}{b['wall']:>9.2f}{up:>9.1f}×"
        )
    for cost, values in ups.items():
        print(f"median speed-up, {cost}: {np.median(values):.2f}× ({len(values)} plans)")
    paper_against_ipopt(new[("two_link", "paper", 0)]["wall"], args.repeat)


def paper_against_ipopt(plan_wall: float, repeat: int) -> None:
    """The paper's example: this checkout's plan time against IPOPT's in this process."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_planner import ipopt_two_link
    from benchlib import median_time

    ipopt_two_link(100)  # CasADi's first build loads its plugins
    wall, (j, te, iterations) = median_time(lambda: ipopt_two_link(100), max(repeat, 3))
    print(
        f"paper's example: plan {plan_wall:.3f} s, CasADi + IPOPT (K = 100, built and solved) "
        f"{wall:.3f} s (J = {j:.6f}, {iterations} iterations): plan / IPOPT = "
        f"{plan_wall / wall:.2f}"
    )


if __name__ == "__main__":
    main()
