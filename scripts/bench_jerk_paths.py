"""Which path is better under a jerk limit (#26): the straight line, stage 2's iterates found
without the limit, or the line bent a little.

For ur5 and panda (a seeded pair of configurations each, time-optimal, URDF limits) and two jerk
limits, prints the jerk-limited duration (``time_with_jerk_limits``, grid 100) of

- the straight line (the plan's first path, a cubic B-spline with 16 interior control points),
- every third iterate of stage 2 run without the jerk limit, and its last,
- the line with its interior control points moved by smooth random bumps of 2 and 10 mrad
  (6 seeded bumps each; the ends fixed): the least and the largest duration.

    python scripts/bench_jerk_paths.py
"""

from __future__ import annotations

import numpy as np

import nearopt
from nearopt.planning.records import SCPOptions
from nearopt.planning.scp import knot_breaks
from nearopt.timing import load_kernel, time_with_jerk_limits

CASES = [
    ("ur5", [0.0, -1.5, 1.5, 0.0, 0.0, 0.0], [1.5, -1.0, 1.0, 0.5, 0.5, 0.5], (30.0, 300.0)),
    (
        "panda",
        [0.0, -0.5, 0.0, -2.0, 0.0, 1.5, 0.5],
        [1.2, 0.3, -0.5, -1.2, 0.6, 2.0, -0.3],
        (50.0, 500.0),
    ),
]
GRID = 100


def bent(line: nearopt.BSplinePath, amplitude: float, rng: np.random.Generator):
    """The line with each joint's interior control points moved by amplitude·N(0,1)·sin(kπx)."""
    points = line.control_points.copy()
    x = np.linspace(0.0, 1.0, points.shape[0])
    for joint in range(points.shape[1]):
        points[1:-1, joint] += (
            amplitude * rng.normal() * np.sin(np.pi * x[1:-1] * rng.integers(1, 3))
        )
    return nearopt.BSplinePath(points, line.knots[4:-4])


def main() -> None:
    load_kernel()
    options = SCPOptions()
    for name, q0, qe, limits in CASES:
        q0, qe = np.array(q0), np.array(qe)
        free = nearopt.plan(nearopt.Robot.from_name(name), q0, qe, nearopt.TimeCost(), grid=GRID)
        line = nearopt.BSplinePath.line(
            q0, qe, options.control_points, knot_breaks(options, options.control_points)
        )
        for jerk in limits:
            robot = nearopt.Robot.from_name(name).with_limits(jerk=jerk)

            def timed(path: nearopt.Path, robot: nearopt.Robot = robot) -> float:
                return time_with_jerk_limits(robot, path, nearopt.TimeCost(), grid=GRID).J

            print(f"{name}, |jerk| <= {jerk:g} rad/s³: jerk-limited t_e [s]")
            print(f"  straight line             {timed(line):8.4f}")
            picks = list(free.history[1::3]) + [free.history[-1]]
            for entry in dict.fromkeys(picks):
                print(
                    f"  stage-2 iterate {entry.index:2d}        {timed(entry.path):8.4f}"
                    f"   (without the jerk limit {entry.duration:.4f})"
                )
            rng = np.random.default_rng(0)
            for amplitude in (0.002, 0.01):
                times = [timed(bent(line, amplitude, rng)) for _ in range(6)]
                print(
                    f"  line bent by {amplitude * 1e3:4.0f} mrad      "
                    f"{min(times):8.4f} … {max(times):.4f}"
                )


if __name__ == "__main__":
    main()
