"""The ``nearopt`` command line: plan a motion for a named or URDF arm and write it as JSON.

    nearopt plan --robot two_link --q0 45 -90 --qe -90 0 --deg --beta 0.03 --json plan.json
    nearopt robots

Every failure the user can cause (a bad argument, a bad URDF, an infeasible request) ends with one
line on stderr, ``nearopt: error: …``, and exit code 2; no output file is written then.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn

import numpy as np

from .catalog import available_robots
from .cost import Cost, TimeCost, TorqueCost
from .errors import ConfigurationError, NearoptError
from .path import StraightPath
from .planner import METHODS, plan
from .robot import Robot
from .timing import optimal_timing

if TYPE_CHECKING:
    from collections.abc import Sequence

__all__ = ["main"]


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line (no usage dump) with exit code 2."""

    def error(self, message: str) -> NoReturn:
        _fail(message)


def _fail(message: str) -> NoReturn:
    print(f"nearopt: error: {' '.join(str(message).split())}", file=sys.stderr)
    raise SystemExit(2)


def _parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="nearopt", description="Near-optimum trajectory planning for URDF arms.")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    sub.add_parser("robots", help="list the arms known by name")
    p = sub.add_parser("plan", help="plan a motion from rest at q0 to rest at qe")
    which = p.add_mutually_exclusive_group(required=True)
    which.add_argument("--robot", metavar="NAME", help="a known arm (see `nearopt robots`)")
    which.add_argument("--urdf", metavar="PATH", help="a URDF file")
    p.add_argument("--lock", nargs="+", default=[], metavar="JOINT",
                   help="joints of the URDF to hold fixed (e.g. gripper fingers)")
    p.add_argument("--q0", nargs="+", type=float, required=True, metavar="V", help="start")
    p.add_argument("--qe", nargs="+", type=float, required=True, metavar="V", help="goal")
    p.add_argument("--deg", action="store_true", help="q0 and qe are in degrees (default rad)")
    cost = p.add_mutually_exclusive_group()
    cost.add_argument("--beta", type=float, help="f0 = 1 + β Σ u² (the paper's eq. 32)")
    cost.add_argument("--weights", nargs="+", type=float, metavar="W",
                      help="f0 = 1 + Σ w_i u_i², one weight per joint")
    cost.add_argument("--time-optimal", action="store_true", help="f0 = 1 (the default)")
    p.add_argument("--stage1-only", action="store_true",
                   help="only time the straight joint line optimally (stage 1)")
    p.add_argument("--method", choices=METHODS, default="quasi-newton", help="path update")
    p.add_argument("--grid", type=int, default=200, help="stage-1 grid segments (200)")
    p.add_argument("--max-iterations", type=int, default=200, help="iteration budget (200)")
    p.add_argument("--time-limit", type=float, default=300.0, help="wall-time budget [s] (300)")
    p.add_argument("--no-velocity-limits", action="store_true", help="ignore joint speed limits")
    p.add_argument("--no-position-limits", action="store_true",
                   help="ignore joint position limits")
    p.add_argument("--json", metavar="FILE", help="write the planned motion as JSON")
    p.add_argument("--rate", type=float, default=1000.0, help="JSON sampling rate [Hz] (1000)")
    p.add_argument("--quiet", action="store_true", help="no per-iteration output")
    return parser


def _cost(args: argparse.Namespace) -> Cost:
    if args.beta is not None:
        return TorqueCost(args.beta)
    if args.weights is not None:
        return TorqueCost(weights=args.weights)
    return TimeCost()


def _check_writable(target: str) -> Path:
    path = Path(target).expanduser()
    folder = path.parent if str(path.parent) else Path(".")
    if path.is_dir():
        raise ConfigurationError(f"cannot write {target}: it is a directory")
    if not folder.is_dir():
        raise ConfigurationError(f"cannot write {target}: folder {folder} does not exist")
    if not os.access(folder, os.W_OK) or (path.exists() and not os.access(path, os.W_OK)):
        raise ConfigurationError(f"cannot write {target}: permission denied")
    return path


def _write_atomically(path: Path, text: str) -> None:
    """Write via a temporary file in the same folder, so a failure leaves no partial file."""
    fd, tmp = tempfile.mkstemp(dir=path.parent if str(path.parent) else ".", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as handle:
            handle.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _plan_command(args: argparse.Namespace) -> None:
    if not (np.isfinite(args.rate) and args.rate > 0):
        raise ConfigurationError(f"--rate must be a positive number of Hz, got {args.rate}")
    target = _check_writable(args.json) if args.json else None
    robot = (
        Robot.from_name(args.robot)
        if args.robot
        else Robot.from_urdf(args.urdf, locked_joints=tuple(args.lock))
    )
    q0, qe = (np.deg2rad(v) if args.deg else np.asarray(v) for v in (args.q0, args.qe))
    cost = _cost(args)
    velocity = not args.no_velocity_limits
    if args.stage1_only:
        q0 = robot.check_configuration(q0, "q0")
        qe = robot.check_configuration(qe, "qe")
        timing = optimal_timing(
            robot, StraightPath(q0, qe), cost, grid=args.grid, velocity_limits=velocity
        )
        trajectory, J, duration = timing.trajectory, timing.J, timing.duration
        history = [{"J": timing.objective, "alpha": None}]
        print(f"stage 1 on the straight line: J = {J:.6f}, te = {duration:.4f} s "
              f"({timing.solver}, {timing.wall_time:.2f} s)")
    else:
        result = plan(
            robot, q0, qe, cost,
            method=args.method,
            grid=args.grid,
            max_iterations=args.max_iterations,
            time_limit=args.time_limit,
            velocity_limits=velocity,
            position_limits=not args.no_position_limits,
            verbose=not args.quiet,
        )
        trajectory, J, duration = result.trajectory, result.J, result.duration
        history = [{"J": it.J, "alpha": it.alpha} for it in result.history]
        print(f"{result.status}: J = {J:.6f} (straight line {result.initial.J:.6f}), "
              f"te = {duration:.4f} s, {len(result.history) - 1} iterations, "
              f"{result.wall_time:.2f} s ({result.message})")
    if target is not None:
        samples = trajectory.sample(args.rate)
        document = {
            "robot": robot.name,
            "joint_names": list(robot.joint_names),
            "cost": cost.describe(),
            "J": J,
            "duration": duration,
            **{key: samples[key].tolist() for key in ("t", "q", "qd", "qdd", "tau")},
            "history": history,
        }
        _write_atomically(target, json.dumps(document))
        print(f"wrote {target} ({samples['t'].size} samples at {args.rate:g} Hz)")


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``nearopt`` console script; returns the exit code."""
    args = _parser().parse_args(argv)
    try:
        if args.command == "robots":
            print("\n".join(available_robots()))
        else:
            _plan_command(args)
    except NearoptError as exc:
        _fail(str(exc))
    except OSError as exc:
        _fail(f"{exc.strerror or exc}: {exc.filename or ''}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
