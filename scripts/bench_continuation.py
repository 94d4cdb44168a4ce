"""Stage 2's second start (``SCPOptions.continuation``) against stage 2 alone and IPOPT.

Seeded rest-to-rest motions (start and goal within 40 % of each joint's range around its middle,
as ``bench_duration.py``), f0 = 1 + 1e-3 Σ u², the URDF limits. Per motion: J and wall time of
the plan with stage 2 from the straight line alone (``continuation=1``) and with the second
start (the default), and the independent reference of ``ipopt_reference.py`` (K = 60, t_e free,
two starts on the straight line, validated by re-simulation) — once from those starts alone and
once with nearopt's plan added as a third start. Every plan is verified (``verify_plan``).

    python scripts/bench_continuation.py [--arms ur5 panda] [--seeds 8] [--no-ipopt]
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
from bench_duration import motion  # noqa: E402

WEIGHT = 1e-3


def planned(robot: nearopt.Robot, q0, qe, options: nearopt.SCPOptions):
    start = time.perf_counter()
    result = nearopt.plan(robot, q0, qe, nearopt.TorqueCost(WEIGHT), options=options)
    wall = time.perf_counter() - start
    if not nearopt.verify_plan(result).passed:
        raise SystemExit(f"{robot.name}: a plan failed its verification")
    return result, wall


def reference(robot: nearopt.Robot, q0, qe, guesses=()) -> str:
    try:
        sol = ref.solve_reference(
            robot, q0, qe, WEIGHT, intervals=60, starts=2, guesses=list(guesses)
        )
    except RuntimeError:
        return "failed"
    return f"{sol.J:.5f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--arms", nargs="+", default=["ur5", "panda"])
    parser.add_argument("--seeds", type=int, default=8)
    parser.add_argument("--no-ipopt", action="store_true")
    args = parser.parse_args()
    alone = nearopt.SCPOptions(continuation=1.0)
    print(
        "| arm | seed | alone J | t_e | wall | with it J | t_e | wall | change "
        "| IPOPT (line) | IPOPT (+ plan) |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    changes, ratios = [], []
    for name in args.arms:
        robot = nearopt.Robot.from_name(name)
        for seed in range(args.seeds):
            q0, qe = motion(robot, seed)
            a, wa = planned(robot, q0, qe, alone)
            b, wb = planned(robot, q0, qe, nearopt.SCPOptions())
            changes.append(b.J / a.J - 1)
            ratios.append(wb / wa)
            line = plus = "–"
            if not args.no_ipopt:
                line = reference(robot, q0, qe)
                plus = reference(robot, q0, qe, [b.trajectory])
            print(
                f"| {name} | {seed} | {a.J:.5f} | {a.duration:.3f} | {wa:.2f} s | {b.J:.5f} "
                f"| {b.duration:.3f} | {wb:.2f} s | {b.J / a.J - 1:+.2%} | {line} | {plus} |",
                flush=True,
            )
    print(
        f"\nJ with the second start / alone − 1: median {np.median(changes):+.3%}, "
        f"lowest {min(changes):+.2%}, highest {max(changes):+.2%}; wall time ratio median "
        f"{np.median(ratios):.2f} (from {min(ratios):.2f} to {max(ratios):.2f})"
    )


if __name__ == "__main__":
    main()
