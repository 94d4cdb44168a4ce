"""Re-planning a moving arm: a plan interrupted half-way, re-planned to a new goal from its state.

The ur5 is on its way from q0 to q1 (a near-optimum plan, f0 = 1 + 0.001 Σ u²) when, at half of
its duration, the goal changes to q2. nearopt plans from the arm's state there — θ(t) and θ̇(t),
``plan(…, qd0=θ̇(t))`` — to q2, and the motion that ran is joined with the new plan
(``ChainedTrajectory([first.trajectory.until(t), second.trajectory])``). The script prints both
plans and, for comparison, the straight line from the same state with the same start velocity
(stage 1 alone); checks that the joined motion is C¹ at the join (θ and θ̇ equal on both sides);
verifies it as one motion (limits at 1 kHz, start at rest at q0, end at rest at q2, J, forward
simulation of its torques); and writes the animation (the first plan's tip trail in grey) and the
joined motion's JSON into out/replanning/.

    python scripts/03_replanning.py [--out DIR] [--arm ur5] [--time-limit SECONDS]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

import nearopt
from nearopt.outputs import write_atomically
from nearopt.trajectory import ChainedTrajectory
from nearopt.viz.viewer import scene_html

GOALS = {  # q0, q1 (the first goal) and q2 (the new one) [rad]
    "ur5": ([0.3, -1.2, 1.4, -1.6, -1.4, 0.2], [1.9, -0.6, 0.5, -1.0, -1.9, 1.1],
            [0.6, -1.8, 2.0, -0.6, -0.9, -0.8]),
    "panda": ([0.2, -0.4, 0.1, -2.0, 0.0, 1.6, 0.6], [1.4, 0.3, -0.4, -1.3, 0.5, 2.0, -0.2],
              [-0.6, 0.5, 0.4, -1.0, -0.4, 1.2, 1.4]),
}  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("out/replanning"))
    parser.add_argument("--arm", choices=sorted(GOALS), default="ur5")
    parser.add_argument("--time-limit", type=float, default=60.0)
    args = parser.parse_args()
    robot = nearopt.Robot.from_name(args.arm)
    q0, q1, q2 = (np.array(q) for q in GOALS[args.arm])
    cost = nearopt.TorqueCost(0.001)

    first = nearopt.plan(robot, q0, q1, cost, time_limit=args.time_limit)
    cut = 0.5 * first.duration
    q, qd = (x[0] for x in first.trajectory.states(np.array([cut]))[:2])
    second = nearopt.plan(robot, q, q2, cost, qd0=qd, time_limit=args.time_limit)
    line = nearopt.plan(robot, q, q2, cost, qd0=qd, max_iterations=0)
    ran = first.trajectory.until(cut)
    joined = ChainedTrajectory([ran, second.trajectory])

    print(f"{args.arm}, f0 = {cost.describe()}")
    print(f"{'motion':<34} {'t_e [s]':>8} {'J':>9} {'iterations':>10}")
    print(f"{'first plan q0 → q1':<34} {first.duration:8.4f} {first.J:9.5f} {first.iterations:10d}")
    print(f"{'  interrupted at t = t_e/2':<34} {cut:8.4f} {ran.integrate(cost):9.5f}")
    print(f"{'re-plan from there → q2':<34} {second.duration:8.4f} {second.J:9.5f} "
          f"{second.iterations:10d}")  # fmt: skip
    print(f"{'  the straight line, same θ̇(0)':<34} {line.duration:8.4f} {line.J:9.5f} {0:10d}")
    print(f"{'joined motion':<34} {joined.duration:8.4f} {joined.integrate(cost):9.5f}")
    print(f"  θ̇ at the cut [rad/s]: {np.array2string(qd, precision=3)}")

    before = ran.states(np.array([cut]))[:2]
    after = second.trajectory.states(np.array([0.0]))[:2]
    jumps = [float(np.max(np.abs(a[0] - b[0]))) for a, b in zip(before, after, strict=True)]
    print(f"  at the join: |Δθ| = {jumps[0]:.1e} rad, |Δθ̇| = {jumps[1]:.1e} rad/s (C¹)")
    report = nearopt.verify(
        joined,
        robot,
        rate=1000.0,
        q0=q0,
        qe=q2,
        cost=cost,
        J=ran.integrate(cost) + second.J,
    )
    print("\nthe joined motion, verified as one:")
    print(report)
    if max(jumps) > 1e-9 or not report.passed:
        raise SystemExit("the joined motion is not C¹ or fails its verification")

    args.out.mkdir(parents=True, exist_ok=True)
    page = scene_html(robot, joined, initial=first.trajectory)
    written = [write_atomically(args.out / "replanning.html", page)]
    samples = joined.sample(1000.0)
    document = {
        "robot": robot.name,
        "joint_names": list(robot.joint_names),
        "t_cut": cut,
        **{key: getattr(samples, key).tolist() for key in ("t", "q", "qd", "qdd", "tau")},
    }
    written.append(write_atomically(args.out / "replanning.json", json.dumps(document)))
    print("\nwritten: " + ", ".join(str(p) for p in written))


if __name__ == "__main__":
    main()
