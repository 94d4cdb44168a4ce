"""The paper's example (Section 7): the bundled two-link arm of eq. (31) and Table 1.

For now this loads the arm, prints its model summary and checks it against eq. (31) at the start
configuration of Table 1; the planner's issues extend it to plan the example.

    python scripts/01_paper_example.py
"""

from __future__ import annotations

import time

import numpy as np

import nearopt

THETA_0 = np.deg2rad([45.0, -90.0])  # Table 1
THETA_E = np.deg2rad([-90.0, 0.0])


def main() -> None:
    t0 = time.perf_counter()
    robot = nearopt.Robot.from_name("two_link")
    print(robot.summary())
    for label, q in (("θ0", THETA_0), ("θe", THETA_E)):
        print(
            f"{label} = {np.rad2deg(q).tolist()} deg: g(θ) = {robot.gravity_torque(q).round(4)} N·m, "
            f"tip at {robot.frame_position(q).round(4).tolist()} m"
        )
    print(f"loaded and evaluated in {time.perf_counter() - t0:.3f} s")


if __name__ == "__main__":
    main()
