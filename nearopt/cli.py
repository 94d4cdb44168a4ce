"""The ``nearopt`` command line: plan a motion for a named or URDF arm; write, plot or play it.

    nearopt plan --robot two_link --q0 45 -90 --qe -90 0 --deg --beta 0.03 --json plan.json \
        --csv plan.csv --plots figures/ --html plan.html [--show]
    nearopt plan --robot panda --task pick.toml --scene cell.toml --json task.json
    nearopt batch motions.jsonl --out table/ [--workers N | --scheduler tcp://HOST:8786]
    nearopt robots

Every failure the user can cause (a bad argument, a bad URDF, an infeasible request) ends with one
line on stderr, ``nearopt: error: …``, and exit code 2; no output file is written then. Every
output place is checked before planning (:mod:`nearopt.outputs`: files are replaced atomically,
links followed, devices and FIFOs written as streams, ``-`` is the standard output). Every plan is
verified (:func:`nearopt.verify`, at ``--rate``) before anything is written; a motion that fails
verification ends the same way with exit code 1. Ctrl-C ends planning with the best plan so far:
it is verified and written, and the exit code is 130; a second Ctrl-C aborts (at once, or at the
end of the output being made).
"""

from __future__ import annotations

import argparse
import contextlib
import math
import re
import signal
import sys
import time
import warnings
from dataclasses import fields
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn, TextIO

from .api import PlanRequest, check, prepare, solve
from .catalog import available_robots
from .errors import ConfigurationError, NearoptError, SamplingWarning
from .export import check_record, csv_text, json_text
from .outputs import (
    Output,
    ReaderTolerant,
    check_outputs,
    is_standard_output,
    quiet_standard_output,
    refuse_inputs,
    resolve_output,
    write_outputs,
)
from .path import StraightPath
from .planning import METHODS, Iteration, PlanResult, StopReason, TaskResult
from .ros import (
    BagContents,
    bag_files,
    check_bag_folder,
    goal_yaml,
    joint_trajectory,
    replace_folder,
)
from .validate import check_rate
from .verify import VerificationError

if TYPE_CHECKING:
    from collections.abc import Iterator, Sequence
    from types import FrameType

__all__ = ["main", "parse_plan", "plan_request"]

# a negative number in any float syntax (-1e-05, -.5, -inf) is a value, not an option
_NEGATIVE_NUMBER = re.compile(
    r"^-(?:(?:\d+(?:_\d+)*)?\.?\d+(?:_\d+)*\.?(?:[eE][-+]?\d+)?|inf(?:inity)?|nan)$",
    re.IGNORECASE,
)


class _Once(argparse._StoreAction):  # noqa: SLF001 - argparse's own store action
    """An option that may be given once: a second value is an error, not a silent override."""

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: object,
        option_string: str | None = None,
    ) -> None:
        given = namespace.__dict__.setdefault("_given", set())
        if self.dest in given:
            parser.error(
                f"{option_string} is given twice (options take one value list; --via repeats)"
            )
        given.add(self.dest)
        super().__call__(parser, namespace, values, option_string)


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are ConfigurationErrors (one line, exit code 2, no usage
    dump; a batch records them as the motion's error); an option given twice is an error; no
    abbreviations (``--bet`` is not ``--beta``: a batch's motions name options in full, and an
    abbreviation would change meaning as options are added)."""

    def __init__(self, *args: object, **kwargs: object) -> None:
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self.register("action", None, _Once)
        self.register("action", "store", _Once)
        self._negative_number_matcher = _NEGATIVE_NUMBER  # argparse's own reads -1e-05 as -1

    def error(self, message: str) -> NoReturn:
        raise ConfigurationError(message)


def _fail(message: str, code: int = 2) -> NoReturn:
    print(f"nearopt: error: {' '.join(str(message).split())}", file=sys.stderr)
    raise SystemExit(code)


def _parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="nearopt", description="Near-optimum trajectory planning for URDF arms.")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    sub.add_parser("robots", help="list the arms known by name")
    p = sub.add_parser("plan", help="plan a motion from rest at q0 to rest at qe")
    for options in (
        _arm_options,
        _motion_options,
        _planner_options,
        _scene_options,
        _output_options,
    ):
        options(p)
    _batch_parser(sub)
    return parser


def _arm_options(p: argparse.ArgumentParser) -> None:
    """Which arm, which of its joints, its limits (``nearopt plan``)."""
    which = p.add_mutually_exclusive_group(required=True)
    which.add_argument("--robot", metavar="NAME", help="a known arm (see `nearopt robots`)")
    which.add_argument("--urdf", metavar="PATH", help="a URDF file")
    p.add_argument(
        "--lock",
        nargs="+",
        default=[],
        metavar="JOINT",
        help="joints of the URDF to hold fixed (e.g. gripper fingers)",
    )
    p.add_argument(
        "--tip",
        metavar="LINK",
        help="plan for the chain of joints of the URDF that ends at this link (every "
        "other joint held fixed at 0 within its limits)",
    )
    p.add_argument("--base", metavar="LINK", help="the link that chain starts from (--tip)")
    p.add_argument(
        "--srdf",
        metavar="FILE",
        help="an SRDF of the URDF: its disabled collision pairs (and --group)",
    )
    p.add_argument(
        "--group",
        metavar="NAME",
        help="plan for the joints of this SRDF group (a chain or a list of joints)",
    )
    p.add_argument(
        "--lock-at",
        nargs="+",
        default=[],
        metavar="JOINT=VALUE",
        help="values [rad or m] at which locked joints are held (default 0 within their limits)",
    )
    p.add_argument(
        "--joint-order",
        nargs="+",
        default=[],
        metavar="JOINT",
        help="the order of the joint values given (--q0, --qe, --via, per-joint limits and "
        "weights), e.g. a controller's: every joint by name (default the URDF's)",
    )
    p.add_argument(
        "--effort-limit",
        nargs="+",
        type=float,
        metavar="U",
        help="actuator limits |u| <= U [N·m or N]: one value or one per joint "
        "(default: the URDF's)",
    )
    p.add_argument(
        "--velocity-limit",
        nargs="+",
        type=float,
        metavar="V",
        help="joint speed limits [rad/s or m/s]: one value or one per joint",
    )
    p.add_argument(
        "--velocity-scale", type=float, metavar="F", help="multiply every joint speed limit by F"
    )


def _motion_options(p: argparse.ArgumentParser) -> None:
    """Start, goal (joint values, a tool pose or a task), via-points."""
    p.add_argument(
        "--q0",
        nargs="+",
        type=float,
        metavar="V",
        help="start (required unless the --task file gives it; then this overrides it)",
    )
    p.add_argument("--qe", nargs="+", type=float, metavar="V", help="goal")
    p.add_argument(
        "--goal-pose",
        nargs="+",
        type=float,
        metavar="X",
        help="goal as a tool pose instead of --qe: x y z [m] (position only) or "
        "x y z qx qy qz qw (base frame), reached by inverse kinematics",
    )
    p.add_argument(
        "--frame", metavar="NAME", help="the frame --goal-pose places (default: the robot's tip)"
    )
    p.add_argument(
        "--via",
        nargs="+",
        type=float,
        action="append",
        default=[],
        metavar="V",
        help="a via-point passed through without stopping (joint values, like --q0); "
        "repeat for several, in order",
    )
    p.add_argument(
        "--task",
        metavar="FILE",
        help="a task (TOML): targets (joint values or tool poses) in order, each "
        "stopped at or passed through, planned as one motion (instead of --qe)",
    )
    p.add_argument(
        "--fixed-goal",
        action="store_true",
        help="keep inverse kinematics' goal configuration (by default it moves along "
        "the pose with the path, to lower J)",
    )
    p.add_argument(
        "--deg",
        action="store_true",
        help="q0, qe, --via are in degrees, --qd0, --qde in deg/s (default rad, rad/s); a "
        "prismatic joint's stay in m, m/s",
    )


def _planner_options(p: argparse.ArgumentParser) -> None:
    """The cost, the method, the grid, the budgets and the limits switched off."""
    cost = p.add_mutually_exclusive_group()
    cost.add_argument("--beta", type=float, help="f0 = 1 + β Σ u² (the paper's eq. 32)")
    cost.add_argument(
        "--weights",
        nargs="+",
        type=float,
        metavar="W",
        help="f0 = 1 + Σ w_i u_i², one weight per joint",
    )
    cost.add_argument("--time-optimal", action="store_true", help="f0 = 1 (the default)")
    p.add_argument(
        "--stage1-only",
        action="store_true",
        help="only time the straight joint line optimally (stage 1)",
    )
    p.add_argument("--method", choices=METHODS, default="scp", help="path update (scp)")
    p.add_argument("--grid", type=int, default=200, help="stage-1 grid segments (200)")
    p.add_argument("--max-iterations", type=int, default=200, help="iteration budget (200)")
    p.add_argument(
        "--time-limit",
        type=float,
        default=300.0,
        help="wall-time budget [s] (300; inf: none); the best plan so far is kept",
    )
    p.add_argument("--no-velocity-limits", action="store_true", help="ignore joint speed limits")
    when = p.add_mutually_exclusive_group()
    when.add_argument(
        "--duration",
        type=float,
        metavar="T",
        help="the motion takes exactly T seconds (J minimised under it; time or 1 + Σ w u²)",
    )
    when.add_argument(
        "--max-duration",
        type=float,
        metavar="T",
        help="the motion takes at most T seconds (J minimised under it; time or 1 + Σ w u²)",
    )
    p.add_argument(
        "--qd0",
        nargs="+",
        type=float,
        metavar="V",
        help="joint velocities at the start [rad/s; deg/s with --deg] (default: at rest); the "
        "path leaves q0 along them",
    )
    p.add_argument(
        "--qde",
        nargs="+",
        type=float,
        metavar="V",
        help="joint velocities at the goal [rad/s; deg/s with --deg] (default: at rest)",
    )
    p.add_argument(
        "--acceleration-limit",
        nargs="+",
        type=float,
        metavar="A",
        help="joint acceleration limits |qdd| <= A [rad/s²]: one value for every joint "
        "or one per joint (default: the URDF's, URDF 1.2 <limit acceleration=...>; else none)",
    )
    p.add_argument(
        "--jerk-limit",
        nargs="+",
        type=float,
        metavar="J",
        help="joint jerk limits |qddd| <= J [rad/s³], one value or one per joint (default: the "
        "URDF's or --joint-limits'; else none): the better of the first path and the path "
        "found, timed under them, is improved under them (C¹, qdd = 0 at rest)",
    )
    p.add_argument(
        "--torque-rate-limit",
        nargs="+",
        type=float,
        metavar="R",
        help="actuator torque-rate limits |du/dt| <= R [N·m/s], one value or one per joint "
        "(default: none): the better of the first path and the path found, timed under "
        "them, is improved under them (C¹, qdd = 0 at rest)",
    )
    p.add_argument(
        "--joint-limits",
        metavar="FILE",
        help="MoveIt's joint_limits.yaml: its declared speed, acceleration, jerk, effort and "
        "position limits replace the URDF's (the --*-limit options replace both)",
    )
    p.add_argument("--no-position-limits", action="store_true", help="ignore joint position limits")


def _scene_options(p: argparse.ArgumentParser) -> None:
    """Obstacles, the margin, self-collision."""
    p.add_argument(
        "--scene",
        metavar="FILE",
        help="obstacles (TOML): every link keeps the margin from them and from the "
        "other links along the whole motion",
    )
    p.add_argument(
        "--margin",
        type=float,
        metavar="M",
        help="clearance kept [m] (default: the scene's, else 0.01)",
    )
    selfc = p.add_mutually_exclusive_group()
    selfc.add_argument(
        "--self-collision",
        action="store_true",
        default=None,
        help="keep the links apart (the default with --scene)",
    )
    selfc.add_argument(
        "--no-self-collision",
        dest="self_collision",
        action="store_false",
        help="do not check the links against each other",
    )


def _output_options(p: argparse.ArgumentParser) -> None:
    """What is written, shown or printed."""
    p.add_argument(
        "--json",
        metavar="FILE",
        help="write the planned motion as JSON (- for the standard output)",
    )
    p.add_argument("--csv", metavar="FILE", help="write the same samples as CSV (- likewise)")
    p.add_argument("--rate", type=float, default=1000.0, help="JSON/CSV sampling rate [Hz] (1000)")
    p.add_argument(
        "--plots",
        metavar="DIR",
        help="write torques.png, speeds.png, workspace.png, history.png (and accelerations.png, "
        "jerks.png, torque_rates.png where the arm has such limits)",
    )
    p.add_argument("--html", metavar="FILE", help="write the animation as a standalone HTML file")
    p.add_argument(
        "--ros-yaml",
        metavar="FILE",
        help="write the control_msgs/action/FollowJointTrajectory goal as YAML (- likewise)",
    )
    p.add_argument(
        "--ros-bag",
        metavar="DIR",
        help="write a rosbag2 (MCAP): /joint_trajectory, /joint_states and /tf at --rate",
    )
    p.add_argument(
        "--ros-points",
        choices=("knots", "rate"),
        default="knots",
        help="the JointTrajectory's points: at the motion's knots, refined until the "
        "controller's quintic interpolation is within 1e-6 of it (default), or at --rate",
    )
    p.add_argument(
        "--verify",
        action="store_true",
        help="print the verification report (every plan is verified before output)",
    )
    p.add_argument(
        "--show",
        action="store_true",
        help="play it in the browser (meshcat server on 127.0.0.1) until Ctrl+C",
    )
    p.add_argument("--quiet", action="store_true", help="no per-iteration output")


def _batch_parser(sub: argparse._SubParsersAction) -> None:  # noqa: SLF001 - argparse's own
    """``nearopt batch``."""
    b = sub.add_parser(
        "batch", help="plan many motions (JSON Lines) on this machine's cores or on a Dask cluster"
    )
    b.add_argument(
        "tasks",
        metavar="TASKS",
        help="motions, one JSON object per line: id and the long options of "
        "`nearopt plan` without dashes ('-' as '_')",
    )
    b.add_argument(
        "--out",
        required=True,
        metavar="DIR",
        help="write DIR/<id>.json per motion (or DIR/shards/*.jsonl: --layout) and DIR/summary.csv",
    )
    where = b.add_mutually_exclusive_group()
    where.add_argument(
        "--workers",
        type=int,
        metavar="N",
        help="worker processes on this machine (default: one per core)",
    )
    where.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="a dask.distributed scheduler, e.g. tcp://10.0.0.5:8786",
    )
    b.add_argument(
        "--rate", type=float, default=1000.0, help="the JSON files' sampling rate [Hz] (1000)"
    )
    b.add_argument(
        "--ros-bag",
        action="store_true",
        help="also write DIR/bags/<id>/ per motion planned: a rosbag2 (MCAP) as nearopt plan "
        "--ros-bag writes",
    )
    b.add_argument(
        "--retry-failed",
        action="store_true",
        help="plan again the motions an earlier run recorded as failed",
    )
    b.add_argument(
        "--layout",
        choices=("auto", "files", "shards"),
        default="auto",
        help="files: DIR/<id>.json per motion; shards: DIR/shards/*.jsonl written by the "
        "workers a chunk at a time, DIR/summary.csv appended (for motion tables of any size); "
        "auto (default): the folder's own, else shards above 1000 motions",
    )
    b.add_argument("--quiet", action="store_true", help="no progress bar")


def parse_plan(argv: Sequence[str]) -> argparse.Namespace:
    """``nearopt plan`` arguments (``argv`` starts with ``"plan"``) as the command reads them.

    Raises
    ------
    ConfigurationError
        On an unknown option or a bad value.
    """
    args = _parser().parse_args(list(argv))
    if args.command != "plan":
        raise ConfigurationError(f"expected a plan request, got {args.command!r}")
    return args


def plan_request(args: argparse.Namespace) -> PlanRequest:
    """The request of parsed ``nearopt plan`` arguments: every field of
    :class:`~nearopt.api.PlanRequest` is the option of the same name (lists as tuples)."""
    values = {}
    for field in fields(PlanRequest):
        value = getattr(args, field.name)
        if isinstance(value, list):
            value = tuple(tuple(v) if isinstance(v, list) else v for v in value)
        values[field.name] = value
    return PlanRequest(**values)


def _plan_command(args: argparse.Namespace, interrupt: _Interrupt) -> int:
    request = plan_request(args)
    request.check()
    outputs, plots = _check_output_places(args)
    to_stdout = any(is_standard_output(o) for o in outputs.values())
    # the standard output may carry a file: then every line goes to stderr; a reader that goes
    # away (`| head -1`) costs the lines, not the plan or its files
    out = ReaderTolerant(sys.stderr if to_stdout else sys.stdout)
    prepared = prepare(request)
    refuse_inputs(outputs, prepared.input_files())
    if args.html or args.show:  # meshes that cannot be loaded are named before planning
        prepared.robot.visual_model()
    quiet = args.quiet or args.stage1_only

    def progress(entry: Iteration) -> None:
        print(_format(entry), file=out, flush=True)

    def segment_progress(k: int, entry: Iteration) -> None:
        print(f"segment {k + 1}  {_format(entry)}", file=out, flush=True)

    with interrupt.armed():
        result = solve(prepared, None if quiet else progress, None if quiet else segment_progress)
    _print_summary(result, out)
    if args.json or args.csv or args.ros_bag or (args.ros_yaml and args.ros_points == "rate"):
        check_record(result, args.rate)  # a record too long for its rate: before the check
    report = check(result, prepared)
    if args.verify:
        print(report, file=out)
    report.raise_if_failed()  # nothing is written for a motion that fails
    _write(result, args, outputs, plots, out, interrupt)
    if args.show:
        _show(result, out)
    return 130 if result.status == StopReason.INTERRUPTED else 0


def _check_output_places(args: argparse.Namespace) -> tuple[dict[str, Output], Path | None]:
    """Every output place, checked before planning (a bad path costs no planning time); the
    figures' folder."""
    for key in ("json", "csv", "html", "plots", "ros_yaml", "ros_bag"):  # an unset variable
        if getattr(args, key) == "":
            raise ConfigurationError(f"--{key.replace('_', '-')} is an empty path")
    if args.ros_bag:
        check_bag_folder(args.ros_bag)
    if args.plots:
        try:
            import matplotlib  # noqa: F401
        except ImportError:
            raise ConfigurationError(
                "--plots needs matplotlib: pip install 'nearopt[viz]'"
            ) from None
    roles = {
        f"--{key.replace('_', '-')}": getattr(args, key)
        for key in ("json", "csv", "html", "ros_yaml")
        if getattr(args, key)
    }
    plots = _plots_folder(args.plots) if args.plots else None
    if plots is not None and plots.is_dir():
        from .viz.figures import FIGURE_NAMES

        roles.update({f"--plots {name}": plots / name for name in FIGURE_NAMES})
    if args.ros_bag:  # the bag replaces its folder whole, with whatever was written into it
        _refuse_in_bag(Path(args.ros_bag), {**roles, **({"--plots": plots} if plots else {})})
    return check_outputs(roles), plots


def _refuse_in_bag(bag: Path, outputs: dict[str, str | Path]) -> None:
    """A ConfigurationError where an output is the ``--ros-bag`` folder or lies in it."""
    folder = bag.expanduser().resolve()
    for role, target in outputs.items():
        if str(target) == "-":
            continue
        place = Path(target).expanduser().resolve()
        if place == folder or folder in place.parents:
            raise ConfigurationError(
                f"{role} {target} is in the --ros-bag folder {bag}, which the bag replaces "
                "whole: give a place outside it"
            )


def _print_summary(result: PlanResult | TaskResult, out: TextIO) -> None:
    """The plan in a few lines: J, te, iterations (per segment for a task), the clearance."""
    if isinstance(result, TaskResult):
        print(
            f"{result.status}: J = {result.J:.6f} (first paths {result.initial_J:.6f}), "
            f"te = {result.duration:.4f} s, {len(result.segments)} "
            f"segment{'s' if len(result.segments) > 1 else ''}, "
            f"{result.wall_time:.2f} s",
            file=out,
        )
        for k, (t0, seg, reached) in enumerate(
            zip(result.trajectory.starts, result.segments, result.segment_targets, strict=True)
        ):
            to = ", ".join(t.name for t in reached)
            print(
                f"  segment {k + 1} (to {to}): t = {t0:.4f}-{t0 + seg.duration:.4f} s, "
                f"J = {seg.J:.6f}, {len(seg.history) - 1} iterations, {seg.status} "
                f"({seg.message})",
                file=out,
            )
    else:
        if isinstance(result.initial.trajectory.path, StraightPath):
            first = "straight line"
        elif result.via:  # the spline through them (around the obstacles where it collides)
            first = "first path, through the via-points"
        elif result.clearance is not None:  # around the obstacles
            first = "first path, from OMPL"
        else:
            first = "first path"
        if result.jerk_timing is not None:  # its J is stage 1's, without them
            first += " without the jerk or torque-rate limits"
        print(
            f"{result.status}: J = {result.J:.6f} ({first} {result.initial.J:.6f}), "
            f"te = {result.duration:.4f} s, {len(result.history) - 1} iterations, "
            f"{result.wall_time:.2f} s ({result.message})",
            file=out,
        )
    if result.clearance is not None and not math.isfinite(result.clearance.closest.distance):
        print("clearance: no pairs of bodies to check (the scene and the arm are apart)", file=out)
    elif result.clearance is not None:
        c = result.clearance
        print(
            f"clearance: closest {c.closest.pair} {c.closest.distance * 1e3:.1f} mm "
            f"(margin {c.level * 1e3:.1f} mm, certified along the whole path)",
            file=out,
        )


def _write(
    result: PlanResult | TaskResult,
    args: argparse.Namespace,
    outputs: dict[str, Output],
    plots: Path | None,
    out: TextIO,
    interrupt: _Interrupt,
) -> None:
    """Produce every output first, then write them all (a failure leaves no file behind); the
    sampling warnings after success only. A second Ctrl-C while they are produced aborts when
    the step under way ends (:meth:`_Interrupt.held`), and also where a library swallowed an
    exception (trimesh catches BaseException around its optional imports, which the viewer's
    page makes)."""
    contents: dict[Output, str | bytes] = {}
    with warnings.catch_warnings(record=True) as caught, interrupt.held():
        warnings.simplefilter("always", SamplingWarning)
        if args.json:
            contents[outputs["--json"]] = json_text(result, args.rate)
        if args.csv:
            contents[outputs["--csv"]] = csv_text(result, args.rate)
        bag = _ros_outputs(result, args, outputs, contents)
    if args.html:
        with interrupt.held():
            from .viz.viewer import plan_html

            contents[outputs["--html"]] = plan_html(result)
    if plots is not None:
        with interrupt.held():
            from .viz.figures import render_figures

            rendered = render_figures(result)
        plots.mkdir(exist_ok=True)
        contents.update(
            {
                outputs.get(f"--plots {name}") or resolve_output(plots / name): png
                for name, png in rendered.items()
            }
        )
    interrupt.abort_if_second()
    for name in write_outputs(contents):
        print(f"wrote {name}", file=out)
    if bag is not None:
        replace_folder(Path(args.ros_bag), bag.files)
        print(f"wrote {args.ros_bag} (rosbag2, MCAP: {', '.join(bag.messages)})", file=out)
    for message in dict.fromkeys(str(w.message) for w in caught):  # after success only
        print(f"nearopt: warning: {message}", file=sys.stderr)


def _ros_outputs(
    result: PlanResult | TaskResult,
    args: argparse.Namespace,
    outputs: dict[str, Output],
    contents: dict[Output, str | bytes],
) -> BagContents | None:
    """--ros-yaml into ``contents``; the --ros-bag folder's files (written after the others)."""
    if not (args.ros_yaml or args.ros_bag):
        return None
    trajectory = joint_trajectory(result, args.rate if args.ros_points == "rate" else None)
    if args.ros_yaml:
        contents[outputs["--ros-yaml"]] = goal_yaml(trajectory)
    if not args.ros_bag:
        return None
    name = Path(args.ros_bag).resolve().name
    return bag_files(result, name, args.rate, trajectory=trajectory)


def _show(result: PlanResult | TaskResult, out: TextIO) -> None:
    """Play the plan in the browser until Ctrl-C."""
    from .viz.viewer import show

    signal.signal(signal.SIGINT, signal.default_int_handler)  # Ctrl-C ends the show
    with show(result) as viewer:
        print(
            f"playing at {viewer.url} (meshcat on 127.0.0.1 only); Ctrl+C stops it",
            file=out,
            flush=True,
        )
        try:
            while True:
                time.sleep(1.0)
        except KeyboardInterrupt:
            pass


def _batch_command(args: argparse.Namespace) -> int:
    """``nearopt batch``: exit code 0 if every motion was planned, 1 if some failed, 130 on
    Ctrl-C (what was written stays: run it again to go on)."""
    from .batch import LISTED, progress_line, run_batch

    check_rate(args.rate, "--rate")
    if args.workers is not None and args.workers < 1:
        raise ConfigurationError(f"--workers must be ≥ 1, got {args.workers}")
    # Ctrl-C stops the batch (as it ends `plan`), even where SIGINT was inherited ignored
    signal.signal(signal.SIGINT, signal.default_int_handler)
    t0 = time.perf_counter()
    summary = run_batch(
        args.tasks,
        args.out,
        args.scheduler,
        workers=args.workers,
        rate=args.rate,
        retry_failed=args.retry_failed,
        progress=None if args.quiet else progress_line(),
        ros_bag=args.ros_bag,
        layout=args.layout,
    )
    wall = time.perf_counter() - t0
    fresh = summary.planned + summary.failed - summary.skipped
    print(
        f"{summary.count} motions: {summary.planned} planned, {summary.failed} failed"
        + (f" ({summary.skipped} done before, skipped)" if summary.skipped else "")
        + f", {wall:.1f} s"
        + (f" ({fresh / wall:.1f} motions/s, {summary.tasks} tasks)" if fresh and wall else "")
        + f"; wrote {Path(args.out) / 'summary.csv'}"
    )
    listed = [o for o in summary.outcomes if o.error or o.warnings]
    for outcome in listed[:LISTED]:
        if outcome.error:
            print(f"  {outcome.id}: {outcome.error}", file=sys.stderr)
        for message in outcome.warnings:
            print(f"  {outcome.id}: warning: {message}", file=sys.stderr)
    unlisted = summary.failed - sum(1 for o in listed[:LISTED] if o.error)
    if unlisted > 0 or len(listed) > LISTED:
        more = f"{unlisted} more failed" if unlisted > 0 else "more"
        print(f"  … {more}: {Path(args.out) / 'summary.csv'} lists every one", file=sys.stderr)
    return 1 if summary.failed else 0


def _plots_folder(target: str) -> Path:
    """The figures' folder: an existing folder, or a new one in an existing folder."""
    folder = Path(target).expanduser()
    if folder.exists() and not folder.is_dir():
        raise ConfigurationError(f"cannot write figures into {target}: it is not a folder")
    if not folder.exists() and not folder.parent.is_dir():
        raise ConfigurationError(
            f"cannot write figures into {target}: folder {folder.parent} does not exist"
        )
    if not folder.exists():
        resolve_output(folder)  # the folder can be made where it is asked for
    return folder


def _format(entry: Iteration) -> str:
    step = "" if entry.alpha is None else f"{entry.alpha:.3g}"
    return (
        f"iteration {entry.index:3d}  J = {entry.J:.6f}  step = {step:>8}  "
        f"te = {entry.duration:.4f} s  {entry.wall_time:7.2f} s"
    )


class _Interrupt:
    """Ctrl-C: the first SIGINT ends planning with the best plan so far (the planner turns the
    KeyboardInterrupt into that), a second one aborts at once (exit code 130, nothing written)."""

    def __init__(self) -> None:
        self.count = 0
        self.holding = False

    def _handler(self, signum: int, frame: FrameType | None) -> None:
        if _in_a_callback(frame) and hasattr(signal, "setitimer"):
            # Python code run by C code that cannot pass an exception on (numba unpickling a
            # constant: SystemError; a nanobind module's import: terminate): the signal again
            # in 5 ms, where the interpreter is back in plain Python
            previous = signal.getsignal(signal.SIGALRM)

            def again(_: int, later: FrameType | None) -> None:
                signal.signal(signal.SIGALRM, previous)
                self._handler(signum, later)

            signal.signal(signal.SIGALRM, again)
            signal.setitimer(signal.ITIMER_REAL, 0.005)
            return
        self.count += 1
        if self.count > 1:
            if self.holding:  # taken where the outputs are made (see held)
                return
            raise _Abort
        raise KeyboardInterrupt

    def abort_if_second(self) -> None:
        """Raise the abort if a second SIGINT came (its exception may have been caught)."""
        if self.count > 1:
            raise _Abort

    @contextlib.contextmanager
    def held(self) -> Iterator[None]:
        """While the outputs are made: a second SIGINT aborts when the step under way ends
        (:meth:`abort_if_second`), never inside it. An exception raised inside an extension
        module's import or callback (the page imports trimesh, whose import initialises a
        nanobind module) ends the process (C++'s terminate, exit −6 instead of 130)."""
        self.holding = True
        try:
            yield
        finally:
            self.holding = False
        self.abort_if_second()

    def armed(self) -> contextlib.AbstractContextManager:
        """While planning: SIGINT raises KeyboardInterrupt once; afterwards, any SIGINT aborts."""
        signal.signal(signal.SIGINT, self._handler)

        @contextlib.contextmanager
        def armed_once() -> Iterator[None]:
            yield
            self.count = max(self.count, 1)  # from here on, Ctrl-C aborts

        return armed_once()


class _Abort(BaseException):
    """A second Ctrl-C: stop now."""


def _in_a_callback(frame: FrameType | None) -> bool:
    """Whether the interrupted Python code runs inside an import or numba's unpickling of a
    constant (code that C code called, where an exception may not pass)."""
    while frame is not None:
        code = frame.f_code
        if code.co_filename.startswith("<frozen importlib") or code.co_name == "_numba_unpickle":
            return True
        frame = frame.f_back
    return False


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``nearopt`` console script; returns the exit code."""
    interrupt = _Interrupt()
    args: argparse.Namespace | None = None
    try:
        args = _parser().parse_args(argv)
        if args.command == "robots":
            print("\n".join(available_robots()))
            return 0
        if args.command == "batch":
            return _batch_command(args)
        try:
            return _plan_command(args, interrupt)
        except Exception:  # after a library swallowed the second Ctrl-C's abort (trimesh
            interrupt.abort_if_second()  # catches BaseException) and then failed on half a result
            raise
    except BrokenPipeError:  # what went to the standard output lost its reader (`| head`):
        quiet_standard_output()  # end quietly, as a POSIX tool killed by SIGPIPE
        return 128 + signal.SIGPIPE
    except VerificationError as exc:
        _fail(str(exc), code=1)
    except NearoptError as exc:
        _fail(str(exc))
    except OSError as exc:
        _fail(f"cannot write {exc.filename or 'an output file'}: {exc.strerror or exc}")
    except KeyboardInterrupt:
        if args is not None and args.command == "batch":
            _fail(
                "interrupted: the motions written so far are kept (run it again to go on)", code=130
            )
        _fail("interrupted before a plan was found; nothing written", code=130)
    except _Abort:
        _fail("aborted by a second Ctrl-C; nothing written", code=130)


if __name__ == "__main__":
    sys.exit(main())
