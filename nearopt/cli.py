"""The ``nearopt`` command line: plan a motion for a named or URDF arm; write, plot or play it.

    nearopt plan --robot two_link --q0 45 -90 --qe -90 0 --deg --beta 0.03 --json plan.json \
        --csv plan.csv --plots figures/ --html plan.html [--show]
    nearopt robots

Every failure the user can cause (a bad argument, a bad URDF, an infeasible request) ends with one
line on stderr, ``nearopt: error: …``, and exit code 2; no output file is written then. Every plan
is verified (:func:`nearopt.verify`, at ``--rate``) before anything is written; a motion that fails
verification ends the same way with exit code 1.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn

import numpy as np

from .catalog import available_robots
from .cost import Cost, TimeCost, TorqueCost
from .errors import ConfigurationError, NearoptError, SamplingWarning
from .export import check_writable, csv_text, json_text, write_all
from .planning import METHODS, plan
from .robot import Robot
from .verify import VerificationError, verify

if TYPE_CHECKING:
    from collections.abc import Sequence

__all__ = ["main"]


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line (no usage dump) with exit code 2."""

    def error(self, message: str) -> NoReturn:
        _fail(message)


def _fail(message: str, code: int = 2) -> NoReturn:
    print(f"nearopt: error: {' '.join(str(message).split())}", file=sys.stderr)
    raise SystemExit(code)


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
    p.add_argument("--tip", metavar="LINK",
                   help="plan for the chain of joints of the URDF that ends at this link (every "
                        "other joint held fixed at 0 within its limits)")
    p.add_argument("--base", metavar="LINK", help="the link that chain starts from (--tip)")
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
    p.add_argument("--method", choices=METHODS, default="scp", help="path update (scp)")
    p.add_argument("--grid", type=int, default=200, help="stage-1 grid segments (200)")
    p.add_argument("--max-iterations", type=int, default=200, help="iteration budget (200)")
    p.add_argument("--time-limit", type=float, default=300.0, help="wall-time budget [s] (300)")
    p.add_argument("--no-velocity-limits", action="store_true", help="ignore joint speed limits")
    p.add_argument("--acceleration-limit", nargs="+", type=float, metavar="A",
                   help="joint acceleration limits |qdd| <= A [rad/s²]: one value for every joint "
                        "or one per joint (default: none)")
    p.add_argument("--no-position-limits", action="store_true",
                   help="ignore joint position limits")
    p.add_argument("--json", metavar="FILE", help="write the planned motion as JSON")
    p.add_argument("--csv", metavar="FILE", help="write the same samples as CSV")
    p.add_argument("--rate", type=float, default=1000.0, help="JSON/CSV sampling rate [Hz] (1000)")
    p.add_argument("--plots", metavar="DIR", help="write torques.png, workspace.png, history.png")
    p.add_argument("--html", metavar="FILE", help="write the animation as a standalone HTML file")
    p.add_argument("--verify", action="store_true",
                   help="print the verification report (every plan is verified before output)")
    p.add_argument("--show", action="store_true",
                   help="play it in the browser (meshcat server on 127.0.0.1) until Ctrl+C")
    p.add_argument("--quiet", action="store_true", help="no per-iteration output")
    return parser


def _per_joint(values: list[float], robot: Robot, option: str) -> float | list[float]:
    """One value for every joint, or one per joint."""
    if len(values) == 1:
        return values[0]
    if len(values) != robot.n:
        raise ConfigurationError(
            f"{option} takes one value or one per joint of {robot.name} ({robot.n}: "
            f"{', '.join(robot.joint_names)}), got {len(values)}"
        )
    return values


def _cost(args: argparse.Namespace) -> Cost:
    if args.beta is not None:
        return TorqueCost(args.beta)
    if args.weights is not None:
        return TorqueCost(weights=args.weights)
    return TimeCost()


MAX_SAMPLES = 10_000_000  # rate × te: beyond this a file would take gigabytes


def _check_folder(target: str) -> Path:
    folder = Path(target).expanduser()
    if folder.exists() and not folder.is_dir():
        raise ConfigurationError(f"cannot write figures into {target}: it is not a folder")
    if folder.exists():
        check_writable(folder / "torques.png")
    else:
        check_writable(folder)  # its parent must exist and be writable
    return folder


def _check_request(args: argparse.Namespace) -> None:
    """What can be checked before loading the robot: numbers and optional packages."""
    if not (np.isfinite(args.rate) and args.rate > 0):
        raise ConfigurationError(f"--rate must be a positive number of Hz, got {args.rate}")
    for option in ("lock", "tip", "base"):
        if getattr(args, option) and not args.urdf:
            raise ConfigurationError(
                f"--{option} applies to --urdf (a named robot chooses its own joints)"
            )
    if args.base and not args.tip:
        raise ConfigurationError("--base needs --tip: the chain goes from the base to the tip")
    if args.plots:
        try:
            import matplotlib  # noqa: F401
        except ImportError:
            raise ConfigurationError(
                "--plots needs matplotlib: pip install 'nearopt[viz]'"
            ) from None


def _plan_command(args: argparse.Namespace) -> None:
    _check_request(args)
    # every output is checked before planning, so that a bad path costs no planning time
    targets = {key: check_writable(getattr(args, key)) for key in ("json", "csv", "html")
               if getattr(args, key)}
    plots = _check_folder(args.plots) if args.plots else None
    robot = (
        Robot.from_name(args.robot)
        if args.robot
        else Robot.from_urdf(args.urdf, locked_joints=tuple(args.lock), tip=args.tip,
                             base=args.base)
    )
    if args.acceleration_limit is not None:
        robot = robot.with_limits(acceleration=_per_joint(args.acceleration_limit, robot,
                                                          "--acceleration-limit"))
    if args.weights is not None and len(args.weights) != robot.n:
        raise ConfigurationError(
            f"--weights needs one weight per joint of {robot.name} ({robot.n}), "
            f"got {len(args.weights)}"
        )
    q0, qe = (np.deg2rad(v) if args.deg else np.asarray(v) for v in (args.q0, args.qe))
    result = plan(
        robot, q0, qe, _cost(args),
        method=args.method,
        grid=args.grid,
        max_iterations=0 if args.stage1_only else args.max_iterations,
        time_limit=args.time_limit,
        velocity_limits=not args.no_velocity_limits,
        position_limits=not args.no_position_limits,
        verbose=not args.quiet and not args.stage1_only,
    )
    print(f"{result.status}: J = {result.J:.6f} (straight line {result.initial.J:.6f}), "
          f"te = {result.duration:.4f} s, {len(result.history) - 1} iterations, "
          f"{result.wall_time:.2f} s ({result.message})")
    if args.rate * result.duration > MAX_SAMPLES:
        raise ConfigurationError(
            f"--rate {args.rate:g} Hz over te = {result.duration:.4g} s gives more than "
            f"{MAX_SAMPLES:.0e} samples"
        )
    # verified at the controller's rate, and never more coarsely than at 1 kHz
    report = verify(
        result.trajectory, robot, rate=max(args.rate, 1000.0), q0=q0, qe=qe, cost=result.cost,
        J=result.J, velocity_limits=not args.no_velocity_limits,
        position_limits=not args.no_position_limits,
    )
    if args.verify:
        print(report)
    report.raise_if_failed()  # nothing is written for a motion that fails
    # everything is produced first, then written: a failure leaves no file behind
    contents: dict[Path, str | bytes] = {}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", SamplingWarning)
        if "json" in targets:
            contents[targets["json"]] = json_text(result, args.rate)
        if "csv" in targets:
            contents[targets["csv"]] = csv_text(result, args.rate)
    for message in dict.fromkeys(str(w.message) for w in caught):
        print(f"nearopt: warning: {message}", file=sys.stderr)
    if "html" in targets:
        from .viewer import plan_html

        contents[targets["html"]] = plan_html(result)
    if plots is not None:
        from .figures import render_figures

        rendered = render_figures(result)
        plots.mkdir(exist_ok=True)
        contents.update({plots / name: png for name, png in rendered.items()})
    for path in write_all(contents):
        print(f"wrote {path}")
    if args.show:
        from .viewer import show

        with show(result) as viewer:
            print(f"playing at {viewer.url} (meshcat on 127.0.0.1 only); Ctrl+C stops it",
                  flush=True)
            try:
                while True:
                    time.sleep(1.0)
            except KeyboardInterrupt:
                pass


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``nearopt`` console script; returns the exit code."""
    args = _parser().parse_args(argv)
    try:
        if args.command == "robots":
            print("\n".join(available_robots()))
        else:
            _plan_command(args)
    except VerificationError as exc:
        _fail(str(exc), code=1)
    except NearoptError as exc:
        _fail(str(exc))
    except OSError as exc:
        _fail(f"cannot write {exc.filename or 'an output file'}: {exc.strerror or exc}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
