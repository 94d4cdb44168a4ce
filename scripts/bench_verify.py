"""Benchmark: the check ``nearopt plan`` makes before it writes a plan, against the plan's time.

For each arm, seeded free-space motions (f0 = 1 + 0.001 Σu², the arm's default limits, as
``bench_speed.py``) are planned and then verified as the command does it (``verify`` at 1 kHz
with the plan's cost and J, the forward simulation included). Printed per plan: the plan's wall
time, the check's, its share of the plan's, the joint damping's largest rate ρ = |eig H⁻¹D|
(the forward simulation is implicit where ρ · 10 ms > 3) and the simulated end position's error.
With ``--baseline REV`` the same motions are planned and verified by that commit's nearopt and
by this checkout, each in a child process of its own, one after the other (``git archive``, as
``bench_speed.py``), and printed side by side.

    python scripts/bench_verify.py [--arms ur5 panda xarm7 kinova z1] [--seeds 1 2 3]
                                   [--repeat 3] [--baseline REV]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np
from bench_plans import verify_as_the_command
from benchlib import ROOT, head, run_with, unpack

import nearopt


def motion(robot: nearopt.Robot, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A seeded start and goal within the middle 60 % of each joint's range (``bench_speed.py``)."""
    rng = np.random.default_rng(seed)
    lo = np.maximum(robot.limits.position_lower, -np.pi)
    hi = np.minimum(robot.limits.position_upper, np.pi)
    mid, half = 0.5 * (lo + hi), 0.3 * (hi - lo)
    q0, qe = rng.uniform(mid - half, mid + half, (2, robot.n))
    return q0, qe


def damping_rate(robot: nearopt.Robot, result: nearopt.PlanResult) -> float:
    """ρ = max |eig(H⁻¹D)| [1/s] at 9 configurations along the plan."""
    q = result.trajectory.states(np.linspace(0.0, result.duration, 9))[0]
    d = np.diag(robot.damping)
    return max(
        float(np.max(np.abs(np.linalg.eigvals(np.linalg.solve(robot.mass_matrix(x), d)))))
        for x in q
    )


def measure_here(args: argparse.Namespace) -> list[dict]:
    """Every arm's seeded plans, planned and verified by this process's nearopt."""
    lines = []
    for arm in args.arms:
        robot = nearopt.Robot.from_name(arm)
        cost = nearopt.TorqueCost(0.001)
        nearopt.plan(robot, *motion(robot, 0), cost)  # the first plan loads what it needs
        for seed in args.seeds:
            q0, qe = motion(robot, seed)
            start = time.perf_counter()
            result = nearopt.plan(robot, q0, qe, cost)
            wall = time.perf_counter() - start
            checks, report = [], None
            for _ in range(args.repeat):
                start = time.perf_counter()
                report = verify_as_the_command(result)
                checks.append(time.perf_counter() - start)
            assert report is not None
            end = next(c for c in report.checks if c.name == "simulated end position")
            line = {
                "arm": arm, "seed": seed, "J": result.J, "plan": wall,
                "verify": float(np.median(checks)), "passed": bool(report.passed),
                "rho": damping_rate(robot, result), "end": end.worst,
            }  # fmt: skip
            lines.append(line)
            if args.json:
                print(json.dumps(line), flush=True)
    return lines


def show(lines: list[dict]) -> None:
    print(
        f"{'arm':7}{'seed':>5}{'J':>10}{'ρ [1/s]':>9}{'plan [s]':>10}{'verify [s]':>11}"
        f"{'/ plan':>8}{'end [rad]':>11}  passed"
    )
    for x in lines:
        print(
            f"{x['arm']:7}{x['seed']:>5}{x['J']:>10.5f}{x['rho']:>9.0f}{x['plan']:>10.3f}"
            f"{x['verify']:>11.4f}{100 * x['verify'] / x['plan']:>7.1f}%{x['end']:>11.1e}  "
            f"{x['passed']}"
        )


def side_by_side(args: argparse.Namespace) -> None:
    """The motions planned and verified by ``args.baseline`` and by this checkout."""
    arguments = ["--json", "--arms", *args.arms, "--repeat", str(args.repeat), "--seeds"]
    arguments += [str(s) for s in args.seeds]
    with tempfile.TemporaryDirectory() as tmp:
        old_out = run_with(unpack(args.baseline, Path(tmp)), __file__, *arguments)
    new_out = run_with(ROOT, __file__, *arguments)
    old, new = (
        [json.loads(x) for x in out.splitlines() if x.startswith("{")] for out in (old_out, new_out)
    )
    print(f"verification at 1 kHz: {args.baseline} against this checkout ({head()})")
    print(
        f"{'arm':7}{'seed':>5}{'ρ [1/s]':>9}{'ΔJ/J':>10}{'verify before':>15}{'now [s]':>9}"
        f"{'speed-up':>10}{'/ plan before':>15}{'now':>7}{'end before':>12}{'now':>9}"
    )
    for a, b in zip(old, new, strict=True):
        print(
            f"{a['arm']:7}{a['seed']:>5}{b['rho']:>9.0f}{b['J'] / a['J'] - 1:>+10.1e}"
            f"{a['verify']:>15.4f}{b['verify']:>9.4f}{a['verify'] / b['verify']:>9.1f}×"
            f"{100 * a['verify'] / a['plan']:>14.1f}%{100 * b['verify'] / b['plan']:>6.1f}%"
            f"{a['end']:>12.1e}{b['end']:>9.1e}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--arms", nargs="+", default=["ur5", "panda", "xarm7", "kinova", "z1"])
    parser.add_argument("--seeds", nargs="+", type=int, default=[1, 2, 3])
    parser.add_argument("--repeat", type=int, default=3, help="checks per plan (the median)")
    parser.add_argument("--baseline", help="a commit to compare with, side by side")
    parser.add_argument("--json", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.baseline:
        side_by_side(args)
        return
    lines = measure_here(args)
    if not args.json:
        show(lines)


if __name__ == "__main__":
    main()
