"""Pick and place on the panda in a cell: a task of four tool poses, planned as one motion.

The task (scripts/tasks/pick_and_place.toml) approaches the part, picks it (the arm stops),
lifts it and places it beyond a wall (stops); the cell (scripts/tasks/pick_and_place_cell.toml)
is a table under the arm and the wall. Every target is a pose of the gripper's frame, reached by
inverse kinematics; each goal configuration moves along its pose with the path to lower J; the
links keep 1 cm from the cell and from each other along the whole motion (certified). Prints the
targets and the segments, verifies the motion independently (limits, targets, rest at the stops,
clearance, J, forward simulation) and writes the figures, the animation (HTML), JSON and CSV into
out/pick_and_place/.

    python scripts/02_pick_and_place.py [--out DIR] [--time-limit SECONDS]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import nearopt
from nearopt.export import write_csv, write_json
from nearopt.viz.figures import save_figures
from nearopt.viz.viewer import export_html

HERE = Path(__file__).resolve().parent


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("out/pick_and_place"))
    parser.add_argument("--time-limit", type=float, default=120.0)
    args = parser.parse_args()
    robot = nearopt.Robot.from_name("panda")
    task = nearopt.Task.from_file(HERE / "tasks" / "pick_and_place.toml")
    cell = nearopt.Scene.from_file(HERE / "tasks" / "pick_and_place_cell.toml")
    cost = nearopt.TorqueCost(0.001)
    print(
        f"panda, f0 = {cost.describe()}, cell: "
        f"{', '.join(o.name for o in cell.obstacles)} (margin {cell.margin * 1e3:.0f} mm)"
    )

    result = nearopt.plan_task(
        robot,
        task.start,
        task,
        cost,
        nearopt.PlanSettings(scene=cell, time_limit=args.time_limit),
    )
    print(f"\n{'target':>9} {'stop':>5} {'t [s]':>7}   x, y, z [m]")
    for target, t in zip(result.targets, result.target_times, strict=True):
        position = ", ".join(f"{x:.3f}" for x in target.goal.position)
        print(f"{target.name:>9} {'yes' if target.stop else 'no':>5} {t:7.4f}   {position}")
    print(
        f"\n{'segment':>8} {'from [s]':>9} {'to [s]':>8} {'J first':>9} {'J':>9} "
        f"{'iterations':>10} {'wall [s]':>9}  status"
    )
    for k, (t0, seg) in enumerate(zip(result.trajectory.starts, result.segments, strict=True)):
        print(
            f"{k + 1:>8} {t0:9.4f} {t0 + seg.duration:8.4f} {seg.initial.J:9.5f} "
            f"{seg.J:9.5f} {len(seg.history) - 1:10d} {seg.wall_time:9.2f}  {seg.status}"
        )
    c = result.clearance
    print(
        f"\ntask: J = {result.J:.6f} (first paths {result.initial_J:.6f}), te = "
        f"{result.duration:.4f} s, {result.wall_time:.1f} s; closest: {c.closest.pair} "
        f"{c.closest.distance * 1e3:.1f} mm"
    )

    report = nearopt.verify(
        result.trajectory,
        robot,
        q0=task.start,
        goal_pose=result.goal,
        waypoints=result.waypoints,
        cost=cost,
        J=result.J,
        collisions=result.collisions,
    )
    print(f"\n{report}")
    report.raise_if_failed()
    speeds = np.abs(result.trajectory(result.target_times, 1)).max(axis=1)
    print(
        "joint speed at the targets [rad/s, max over joints]: "
        + ", ".join(f"{t.name} {v:.3g}" for t, v in zip(result.targets, speeds, strict=True))
    )

    args.out.mkdir(parents=True, exist_ok=True)
    written = [
        *save_figures(result, args.out),
        write_json(result, args.out / "pick_and_place.json"),
        write_csv(result, args.out / "pick_and_place.csv"),
        export_html(result, args.out / "pick_and_place.html"),
    ]
    print("\nwrote " + ", ".join(str(p) for p in written))


if __name__ == "__main__":
    main()
