"""The paper's example (Section 7): the bundled two-link arm of eq. (31) and Table 1.

Loads the arm, prints its model summary and times the initial path of the paper, the straight
joint-space line θ0 → θe (eqs. 28-29), optimally for the paper's cost f0 = 1 + 0.03 Σ u² (eq. 32)
and for minimum time (stage 1). Stage 2 (improving the path itself) is the planner's next step.

    python scripts/01_paper_example.py
"""

from __future__ import annotations

import time

import numpy as np

import nearopt

THETA_0 = np.deg2rad([45.0, -90.0])  # Table 1
THETA_E = np.deg2rad([-90.0, 0.0])
PAPER_J0 = 0.95859  # the paper's stage-1 cost of the straight line (Table 2)


def main() -> None:
    robot = nearopt.Robot.from_name("two_link")
    print(robot.summary())
    path = nearopt.StraightPath(THETA_0, THETA_E)
    print(f"\nStage 1 on the straight line θ0 = {np.rad2deg(THETA_0).tolist()} deg → "
          f"θe = {np.rad2deg(THETA_E).tolist()} deg")
    print(f"{'cost':<22}{'N':>6}{'J':>12}{'te [s]':>10}{'solver':>16}{'time [s]':>10}")
    for cost in (nearopt.TorqueCost(0.03), nearopt.TimeCost()):
        for grid in (100, 200, 400):
            t0 = time.perf_counter()
            result = nearopt.optimal_timing(robot, path, cost, grid=grid)
            elapsed = time.perf_counter() - t0
            print(f"{cost.describe():<22}{grid:>6}{result.J:>12.6f}{result.duration:>10.4f}"
                  f"{result.solver:>16}{elapsed:>10.3f}")
    print(f"\nThe paper's stage 1 reports J0 = {PAPER_J0} for this path (its λ B-spline starts at "
          "λ = 0, so its times diverge at rest); the optimal timing above costs less.")


if __name__ == "__main__":
    main()
