"""Plans that start (and end) moving: re-planning from a moving state, against IPOPT.

For seeded motions of ur5 and panda (f0 = 1 + 1e-3 Σ u², URDF limits): a rest-to-rest plan from
q0 to q1 is interrupted at half its duration; from its state there (θ, θ̇) nearopt plans to a new
goal q2 with ``qd0 = θ̇`` — ending at rest, and ending with ``qde`` = 0.3 θ̇ (a motion handed on
to the next one). For each: nearopt's J and t_e, the straight line with the same boundary
velocities (stage 1 alone, ``max_iterations=0``), and the independent reference — a direct
transcription with CasADi + IPOPT (``scripts/ipopt_reference.py``, K = 60 intervals of
piecewise-constant torque, the same boundary velocities, te free, two starts on the line and
one from nearopt's plan, validated by re-simulation). Every plan is verified (``verify_plan``:
θ̇(0), θ̇(t_e), limits at 1 kHz, forward simulation).

    python scripts/bench_moving_ends.py [--arms ur5 panda] [--seeds 3]
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


def goals(robot: nearopt.Robot, seed: int) -> tuple[np.ndarray, ...]:
    """Three configurations within 40 % of each joint's range around its middle."""
    rng = np.random.default_rng(seed)
    lo = np.maximum(robot.limits.position_lower, -3.0)
    hi = np.minimum(robot.limits.position_upper, 3.0)
    mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    return tuple(mid + 0.4 * half * rng.uniform(-1, 1, robot.n) for _ in range(3))


def row(robot: nearopt.Robot, q: np.ndarray, q2: np.ndarray, qd0: np.ndarray, qde) -> str:
    cost = nearopt.TorqueCost(WEIGHT)
    start = time.perf_counter()
    result = nearopt.plan(robot, q, q2, cost, qd0=qd0, qde=qde, time_limit=120.0)
    wall = time.perf_counter() - start
    report = nearopt.verify_plan(result)
    line = nearopt.plan(robot, q, q2, cost, qd0=qd0, qde=qde, max_iterations=0)
    try:
        sol = ref.solve_reference(
            robot, q, q2, WEIGHT, intervals=60, starts=2, qd0=qd0, qde=qde,
            guesses=[result.trajectory],
        )  # fmt: skip
        ipopt = f"{sol.J:.6g} | {result.J / sol.J:.4f}"
    except RuntimeError:
        ipopt = "failed | –"
    end = "rest" if qde is None else "0.3 θ̇"
    return (
        f"| {end} | {result.duration:.4f} | {result.J:.6g} | {line.J:.6g} | {ipopt} | "
        f"{'yes' if report.passed else 'NO'} | {wall:.2f} s |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--arms", nargs="+", default=["ur5", "panda"])
    parser.add_argument("--seeds", type=int, default=2)
    args = parser.parse_args()
    print("| arm | seed | qde | nearopt t_e | nearopt J | line J | IPOPT J | nearopt/IPOPT |"
          " verified | wall |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name in args.arms:
        robot = nearopt.Robot.from_name(name)
        for seed in range(args.seeds):
            q0, q1, q2 = goals(robot, seed)
            first = nearopt.plan(robot, q0, q1, nearopt.TorqueCost(WEIGHT), time_limit=120.0)
            half = 0.5 * first.duration
            q = first.trajectory(half, 0).ravel()
            qd = first.trajectory(half, 1).ravel()
            for qde in (None, 0.3 * qd):
                try:
                    text = row(robot, q, q2, qd, qde)
                except nearopt.NearoptError as exc:
                    text = f"| {'rest' if qde is None else '0.3 θ̇'} | refused: {exc} |"
                print(f"| {name} | {seed} " + text, flush=True)


if __name__ == "__main__":
    main()
