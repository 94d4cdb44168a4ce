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
it is verified and written, and the exit code is 130; a second Ctrl-C aborts at once.
"""

from __future__ import annotations

import argparse
import contextlib
import signal
import sys
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn

import numpy as np

from .catalog import available_robots
from .collision import Scene
from .cost import Cost, TimeCost, TorqueCost
from .errors import ConfigurationError, NearoptError, SamplingWarning
from .export import csv_text, json_text
from .kinematics import ToolPose
from .outputs import Output, OutputKind, check_outputs, resolve_output, write_outputs
from .path import StraightPath
from .planning import METHODS, Iteration, PlanResult, StopReason, Task, TaskResult, plan, plan_task
from .planning.task import check_targets
from .robot import Robot
from .verify import VerificationError, VerificationReport, verify

if TYPE_CHECKING:
    from collections.abc import Iterator, Sequence

    from numpy.typing import NDArray

__all__ = ["main", "plan_options", "parse_plan", "prepare", "solve", "check", "Prepared"]


class _Once(argparse._StoreAction):  # noqa: SLF001 - argparse's own store action
    """An option that may be given once: a second value is an error, not a silent override."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: object, option_string: str | None = None) -> None:
        given = namespace.__dict__.setdefault("_given", set())
        if self.dest in given:
            parser.error(f"{option_string} is given twice (options take one value list; "
                         "--via repeats)")
        given.add(self.dest)
        super().__call__(parser, namespace, values, option_string)


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are ConfigurationErrors (one line, exit code 2, no usage
    dump; a batch records them as the motion's error); an option given twice is an error."""

    def __init__(self, *args: object, **kwargs: object) -> None:
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self.register("action", None, _Once)
        self.register("action", "store", _Once)

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
    which = p.add_mutually_exclusive_group(required=True)
    which.add_argument("--robot", metavar="NAME", help="a known arm (see `nearopt robots`)")
    which.add_argument("--urdf", metavar="PATH", help="a URDF file")
    p.add_argument("--lock", nargs="+", default=[], metavar="JOINT",
                   help="joints of the URDF to hold fixed (e.g. gripper fingers)")
    p.add_argument("--tip", metavar="LINK",
                   help="plan for the chain of joints of the URDF that ends at this link (every "
                        "other joint held fixed at 0 within its limits)")
    p.add_argument("--base", metavar="LINK", help="the link that chain starts from (--tip)")
    p.add_argument("--srdf", metavar="FILE",
                   help="an SRDF of the URDF: its disabled collision pairs (and --group)")
    p.add_argument("--group", metavar="NAME",
                   help="plan for the joints of this SRDF group (a chain or a list of joints)")
    p.add_argument("--lock-at", nargs="+", default=[], metavar="JOINT=VALUE",
                   help="values [rad or m] at which locked joints are held (default 0 within "
                        "their limits)")
    p.add_argument("--effort-limit", nargs="+", type=float, metavar="U",
                   help="actuator limits |u| <= U [N·m or N]: one value or one per joint "
                        "(default: the URDF's)")
    p.add_argument("--velocity-limit", nargs="+", type=float, metavar="V",
                   help="joint speed limits [rad/s or m/s]: one value or one per joint")
    p.add_argument("--velocity-scale", type=float, metavar="F",
                   help="multiply every joint speed limit by F")
    p.add_argument("--q0", nargs="+", type=float, metavar="V",
                   help="start (required unless the --task file gives it; then this overrides it)")
    p.add_argument("--qe", nargs="+", type=float, metavar="V", help="goal")
    p.add_argument("--goal-pose", nargs="+", type=float, metavar="X",
                   help="goal as a tool pose instead of --qe: x y z [m] (position only) or "
                        "x y z qx qy qz qw (base frame), reached by inverse kinematics")
    p.add_argument("--frame", metavar="NAME",
                   help="the frame --goal-pose places (default: the robot's tip)")
    p.add_argument("--via", nargs="+", type=float, action="append", default=[], metavar="V",
                   help="a via-point passed through without stopping (joint values, like --q0); "
                        "repeat for several, in order")
    p.add_argument("--task", metavar="FILE",
                   help="a task (TOML): targets (joint values or tool poses) in order, each "
                        "stopped at or passed through, planned as one motion (instead of --qe)")
    p.add_argument("--fixed-goal", action="store_true",
                   help="keep inverse kinematics' goal configuration (by default it moves along "
                        "the pose with the path, to lower J)")
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
    p.add_argument("--time-limit", type=float, default=300.0,
                   help="wall-time budget [s] (300; inf: none); the best plan so far is kept")
    p.add_argument("--no-velocity-limits", action="store_true", help="ignore joint speed limits")
    p.add_argument("--acceleration-limit", nargs="+", type=float, metavar="A",
                   help="joint acceleration limits |qdd| <= A [rad/s²]: one value for every joint "
                        "or one per joint (default: none)")
    p.add_argument("--no-position-limits", action="store_true",
                   help="ignore joint position limits")
    p.add_argument("--scene", metavar="FILE",
                   help="obstacles (TOML): every link keeps the margin from them and from the "
                        "other links along the whole motion")
    p.add_argument("--margin", type=float, metavar="M",
                   help="clearance kept [m] (default: the scene's, else 0.01)")
    selfc = p.add_mutually_exclusive_group()
    selfc.add_argument("--self-collision", action="store_true", default=None,
                       help="keep the links apart (the default with --scene)")
    selfc.add_argument("--no-self-collision", dest="self_collision", action="store_false",
                       help="do not check the links against each other")
    p.add_argument("--json", metavar="FILE",
                   help="write the planned motion as JSON (- for the standard output)")
    p.add_argument("--csv", metavar="FILE", help="write the same samples as CSV (- likewise)")
    p.add_argument("--rate", type=float, default=1000.0, help="JSON/CSV sampling rate [Hz] (1000)")
    p.add_argument("--plots", metavar="DIR",
                   help="write torques.png, speeds.png, workspace.png, history.png")
    p.add_argument("--html", metavar="FILE", help="write the animation as a standalone HTML file")
    p.add_argument("--verify", action="store_true",
                   help="print the verification report (every plan is verified before output)")
    p.add_argument("--show", action="store_true",
                   help="play it in the browser (meshcat server on 127.0.0.1) until Ctrl+C")
    p.add_argument("--quiet", action="store_true", help="no per-iteration output")
    b = sub.add_parser("batch", help="plan many motions (JSON Lines) on this machine's cores or "
                                     "on a Dask cluster")
    b.add_argument("tasks", metavar="TASKS",
                   help="motions, one JSON object per line: id and the long options of "
                        "`nearopt plan` without dashes ('-' as '_')")
    b.add_argument("--out", required=True, metavar="DIR",
                   help="write DIR/<id>.json per motion and DIR/summary.csv")
    where = b.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, metavar="N",
                       help="worker processes on this machine (default: one per core)")
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="a dask.distributed scheduler, e.g. tcp://10.0.0.5:8786")
    b.add_argument("--rate", type=float, default=1000.0,
                   help="the JSON files' sampling rate [Hz] (1000)")
    b.add_argument("--retry-failed", action="store_true",
                   help="plan again the motions an earlier run recorded as failed")
    b.add_argument("--quiet", action="store_true", help="no progress bar")
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
MAX_RATE = 1e6  # [Hz] a sampling rate above a megahertz is a mistake, not a controller


def _check_request(args: argparse.Namespace) -> None:
    """What can be checked before loading the robot: numbers and optional packages."""
    if not (np.isfinite(args.rate) and 0 < args.rate <= MAX_RATE):
        raise ConfigurationError(
            f"--rate must be a number of Hz in (0, {MAX_RATE:.0e}], got {args.rate}"
        )
    if not args.time_limit > 0:
        raise ConfigurationError(
            f"--time-limit must be a positive number of seconds (inf: none), got {args.time_limit}"
        )
    for option in ("lock", "tip", "base", "lock_at"):
        if getattr(args, option) and not args.urdf:
            raise ConfigurationError(
                f"--{option.replace('_', '-')} applies to --urdf (a named robot chooses its own "
                "joints)"
            )
    if args.base and not args.tip:
        raise ConfigurationError("--base needs --tip: the chain goes from the base to the tip")
    if sum(x is not None for x in (args.qe, args.goal_pose, args.task)) != 1:
        raise ConfigurationError(
            "give the goal as --qe (joint values), as --goal-pose or as a --task file, once"
        )
    if args.task is not None and args.via:
        raise ConfigurationError("--via applies to --qe or --goal-pose (a --task file lists its "
                                 "targets, stop = false to pass through)")
    if args.task is not None and args.frame:
        raise ConfigurationError("--frame applies to --goal-pose (a --task file gives its frame)")
    if args.task is None and args.q0 is None:
        raise ConfigurationError("give the start configuration, --q0")
    if args.task is not None and args.deg and args.q0 is None:
        raise ConfigurationError("--deg applies to --q0 (a --task file gives its units: "
                                 "units = \"deg\")")
    if args.goal_pose is not None and len(args.goal_pose) not in (3, 7):
        raise ConfigurationError(
            f"--goal-pose takes x y z [m] or x y z qx qy qz qw, got {len(args.goal_pose)} numbers"
        )
    if args.frame and args.goal_pose is None and args.task is None:
        raise ConfigurationError("--frame applies to --goal-pose")
    if args.fixed_goal and args.goal_pose is None and args.task is None:
        raise ConfigurationError("--fixed-goal applies to --goal-pose or --task")
    if args.group and not args.urdf:
        raise ConfigurationError("--group applies to --urdf (a named robot chooses its own joints)")
    if args.group and not args.srdf:
        raise ConfigurationError("--group needs --srdf: the group is read from the SRDF")
    if args.margin is not None and not (np.isfinite(args.margin) and args.margin >= 0):
        raise ConfigurationError(f"--margin must be a distance ≥ 0 [m], got {args.margin}")
    if args.margin is not None and not args.scene and not args.self_collision:
        raise ConfigurationError("--margin applies with --scene or --self-collision")
    if args.group and args.tip:
        raise ConfigurationError("give the arm as --tip or as an SRDF --group, not both")
    if args.plots:
        try:
            import matplotlib  # noqa: F401
        except ImportError:
            raise ConfigurationError(
                "--plots needs matplotlib: pip install 'nearopt[viz]'"
            ) from None


def _lock_values(pairs: list[str]) -> dict[str, float]:
    """``--lock-at NAME=VALUE …`` as a dict."""
    values = {}
    for pair in pairs:
        name, sep, value = pair.partition("=")
        try:
            values[name] = float(value)
        except ValueError:
            sep = ""
        if not sep or not name:
            raise ConfigurationError(f"--lock-at takes JOINT=VALUE pairs, got {pair!r}")
    return values


RobotLoader = Callable[[tuple[object, ...], Callable[[], Robot]], Robot]


def _robot(args: argparse.Namespace, loader: RobotLoader | None = None) -> Robot:
    """The arm, with the limits the command line overrides; ``loader(key, load)`` may return a
    robot loaded earlier for the same key (a batch worker keeps its robots)."""
    single_effort = (args.effort_limit[0] if args.effort_limit and len(args.effort_limit) == 1
                     else None)

    def load() -> Robot:
        if args.robot:
            return Robot.from_name(args.robot, **({"srdf": args.srdf} if args.srdf else {}))
        return Robot.from_urdf(
            args.urdf, locked_joints=tuple(args.lock), tip=args.tip, base=args.base,
            lock_at=_lock_values(args.lock_at), srdf=args.srdf, group=args.group,
            effort_limit=single_effort,
        )

    key = (args.robot, args.urdf, tuple(args.lock), args.tip, args.base, args.srdf, args.group,
           tuple(args.lock_at), None if args.robot else single_effort)
    robot = load() if loader is None else loader(key, load)
    overrides = {}
    for option, key in (("effort_limit", "effort"), ("velocity_limit", "velocity"),
                        ("acceleration_limit", "acceleration")):
        values = getattr(args, option)
        if values is not None:
            overrides[key] = _per_joint(values, robot, f"--{option.replace('_', '-')}")
    if args.velocity_scale is not None:
        if not (np.isfinite(args.velocity_scale) and args.velocity_scale > 0):
            raise ConfigurationError(
                f"--velocity-scale must be a positive number, got {args.velocity_scale}"
            )
        base = np.asarray(overrides.get("velocity", robot.limits.velocity), dtype=float)
        overrides["velocity"] = base * args.velocity_scale
    return robot.with_limits(**overrides) if overrides else robot


def _plan_actions() -> list[argparse.Action]:
    """The arguments of the ``plan`` subcommand."""
    parser = _parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))  # noqa: SLF001
    return sub.choices["plan"]._actions  # noqa: SLF001


def plan_options() -> tuple[str, ...]:
    """The long options of ``nearopt plan`` without dashes, ``-`` as ``_`` (a batch's keys)."""
    names = (o for a in _plan_actions() for o in a.option_strings)
    return tuple(sorted({o[2:].replace("-", "_") for o in names if o.startswith("--")} - {"help"}))


def repeatable_options() -> tuple[str, ...]:
    """The options of ``nearopt plan`` given once per value (``--via``): a batch's list of
    lists."""
    return tuple(a.dest for a in _plan_actions()
                 if isinstance(a, argparse._AppendAction))  # noqa: SLF001


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


@dataclass(frozen=True)
class Prepared:
    """A ``nearopt plan`` request read and checked: what to plan."""

    robot: Robot
    q0: NDArray[np.float64]
    qe: NDArray[np.float64] | ToolPose | None
    task: Task | None
    scene: Scene | None
    cost: Cost
    via: list[NDArray[np.float64]]


def prepare(args: argparse.Namespace, robot_loader: RobotLoader | None = None) -> Prepared:
    """Check a request and load what it names (robot, task, scene) before any planning.

    Raises
    ------
    NearoptError
        On anything the request gets wrong (naming the option, joint, value and limit).
    """
    _check_request(args)
    robot = _robot(args, robot_loader)
    if args.weights is not None and len(args.weights) != robot.n:
        raise ConfigurationError(
            f"--weights needs one weight per joint of {robot.name} ({robot.n}), "
            f"got {len(args.weights)}"
        )
    task = Task.from_file(args.task) if args.task is not None else None
    if args.q0 is not None:
        q0 = np.deg2rad(args.q0) if args.deg else np.asarray(args.q0)
    elif task is not None and task.start is not None:
        q0 = np.asarray(task.start)
    else:
        raise ConfigurationError(f"give the start configuration: --q0, or start = [...] in "
                                 f"{args.task}")
    qe: NDArray[np.float64] | ToolPose | None = None
    if args.goal_pose is not None:
        qe = ToolPose(args.goal_pose[:3], args.goal_pose[3:] or None, args.frame)
        robot.frame_id(args.frame)  # an unknown frame is named before any work
    elif args.qe is not None:
        qe = np.deg2rad(args.qe) if args.deg else np.asarray(args.qe)
    else:  # every target is checked before any work
        check_targets(robot, task.targets, q0, where=str(task.source))  # type: ignore[union-attr]
    scene = Scene.from_file(args.scene) if args.scene is not None else None
    via = [np.deg2rad(v) if args.deg else np.asarray(v) for v in args.via]
    return Prepared(robot, q0, qe, task, scene, _cost(args), via)


def solve(
    prepared: Prepared, args: argparse.Namespace,
    callback: Callable[[Iteration], None] | None = None,
    segment_callback: Callable[[int, Iteration], None] | None = None,
) -> PlanResult | TaskResult:
    """Plan the request: :func:`~nearopt.plan`, or :func:`~nearopt.plan_task` for a task."""
    common = dict(
        method=args.method,
        grid=args.grid,
        max_iterations=0 if args.stage1_only else args.max_iterations,
        time_limit=args.time_limit,
        velocity_limits=not args.no_velocity_limits,
        position_limits=not args.no_position_limits,
        scene=prepared.scene,
        margin=args.margin,
        self_collision=args.self_collision,
        optimise_goal=not args.fixed_goal,
    )
    if prepared.task is not None:
        return plan_task(prepared.robot, prepared.q0, prepared.task, prepared.cost,
                         callback=segment_callback, **common)  # type: ignore[arg-type]
    return plan(prepared.robot, prepared.q0, prepared.qe, prepared.cost, callback=callback,
                via=prepared.via, **common)  # type: ignore[arg-type]


def check(result: PlanResult | TaskResult, prepared: Prepared,
          args: argparse.Namespace) -> VerificationReport:
    """Verify a plan as the command does before writing it: at the controller's rate (never
    more coarsely than 1 kHz), its start, goal (or goal pose), targets, limits, clearance, J."""
    if args.rate * result.duration > MAX_SAMPLES:
        raise ConfigurationError(
            f"--rate {args.rate:g} Hz over te = {result.duration:.4g} s gives more than "
            f"{MAX_SAMPLES:.0e} samples"
        )
    qe = prepared.qe
    if prepared.task is not None:
        last = prepared.task.targets[-1].goal
        qe = last if isinstance(last, ToolPose) else np.asarray(last)
    return verify(
        result.trajectory, prepared.robot, rate=max(args.rate, 1000.0), q0=prepared.q0,
        qe=None if isinstance(qe, ToolPose) else qe, goal_pose=result.goal, cost=result.cost,
        J=result.J, velocity_limits=not args.no_velocity_limits,
        position_limits=not args.no_position_limits, collisions=result.collisions,
        waypoints=result.waypoints,
    )


def _plan_command(args: argparse.Namespace, interrupt: _Interrupt) -> int:
    _check_request(args)
    # every output is checked before planning, so that a bad path costs no planning time
    roles = {f"--{key}": getattr(args, key) for key in ("json", "csv", "html")
             if getattr(args, key)}
    plots = _plots_folder(args.plots) if args.plots else None
    if plots is not None and plots.is_dir():
        roles.update({f"--plots {name}": plots / name for name in FIGURE_NAMES})
    outputs = check_outputs(roles)
    to_stdout = any(o.kind is OutputKind.STDOUT for o in outputs.values())
    out = sys.stderr if to_stdout else sys.stdout  # the standard output may carry a file
    prepared = prepare(args)
    quiet = args.quiet or args.stage1_only

    def progress(entry: Iteration) -> None:
        print(_format(entry), file=out, flush=True)

    def segment_progress(k: int, entry: Iteration) -> None:
        print(f"segment {k + 1}  {_format(entry)}", file=out, flush=True)

    with interrupt.armed():
        result = solve(prepared, args, None if quiet else progress,
                       None if quiet else segment_progress)
    if isinstance(result, TaskResult):
        print(f"{result.status}: J = {result.J:.6f} (first paths {result.initial_J:.6f}), "
              f"te = {result.duration:.4f} s, {len(result.segments)} "
              f"segment{'s' if len(result.segments) > 1 else ''}, "
              f"{result.wall_time:.2f} s", file=out)
        for k, (t0, seg, reached) in enumerate(zip(result.trajectory.starts, result.segments,
                                                   result.segment_targets, strict=True)):
            to = ", ".join(t.name for t in reached)
            print(f"  segment {k + 1} (to {to}): t = {t0:.4f}-{t0 + seg.duration:.4f} s, "
                  f"J = {seg.J:.6f}, {len(seg.history) - 1} iterations, {seg.status} "
                  f"({seg.message})", file=out)
    else:
        first = "straight line" if isinstance(result.initial.trajectory.path, StraightPath) else (
            "first path, from OMPL")
        print(f"{result.status}: J = {result.J:.6f} ({first} {result.initial.J:.6f}), "
              f"te = {result.duration:.4f} s, {len(result.history) - 1} iterations, "
              f"{result.wall_time:.2f} s ({result.message})", file=out)
    if result.clearance is not None:
        c = result.clearance
        print(f"clearance: closest {c.closest.pair} {c.closest.distance * 1e3:.1f} mm "
              f"(margin {c.level * 1e3:.1f} mm, certified along the whole path)", file=out)
    report = check(result, prepared, args)
    if args.verify:
        print(report, file=out)
    report.raise_if_failed()  # nothing is written for a motion that fails
    # everything is produced first, then written: a failure leaves no file behind
    contents: dict[Output, str | bytes] = {}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", SamplingWarning)
        if args.json:
            contents[outputs["--json"]] = json_text(result, args.rate)
        if args.csv:
            contents[outputs["--csv"]] = csv_text(result, args.rate)
    if args.html:
        from .viz.viewer import plan_html

        contents[outputs["--html"]] = plan_html(result)
    if plots is not None:
        from .viz.figures import render_figures

        rendered = render_figures(result)
        plots.mkdir(exist_ok=True)
        contents.update({outputs.get(f"--plots {name}") or resolve_output(plots / name): png
                         for name, png in rendered.items()})
    for name in write_outputs(contents):
        print(f"wrote {name}", file=out)
    for message in dict.fromkeys(str(w.message) for w in caught):  # after success only
        print(f"nearopt: warning: {message}", file=sys.stderr)
    if args.show:
        from .viz.viewer import show

        signal.signal(signal.SIGINT, signal.default_int_handler)  # Ctrl-C ends the show
        with show(result) as viewer:
            print(f"playing at {viewer.url} (meshcat on 127.0.0.1 only); Ctrl+C stops it",
                  file=out, flush=True)
            try:
                while True:
                    time.sleep(1.0)
            except KeyboardInterrupt:
                pass
    return 130 if result.status == StopReason.INTERRUPTED else 0


def _batch_command(args: argparse.Namespace) -> int:
    """``nearopt batch``: exit code 0 if every motion was planned, 1 if some failed, 130 on
    Ctrl-C (what was written stays: run it again to go on)."""
    from .batch import progress_line, read_requests, run_batch

    if not (np.isfinite(args.rate) and 0 < args.rate <= MAX_RATE):
        raise ConfigurationError(
            f"--rate must be a number of Hz in (0, {MAX_RATE:.0e}], got {args.rate}"
        )
    if args.workers is not None and args.workers < 1:
        raise ConfigurationError(f"--workers must be ≥ 1, got {args.workers}")
    requests = read_requests(args.tasks)
    # Ctrl-C stops the batch (as it ends `plan`), even where SIGINT was inherited ignored
    signal.signal(signal.SIGINT, signal.default_int_handler)
    t0 = time.perf_counter()
    summary = run_batch(
        requests, args.out, args.scheduler, workers=args.workers, rate=args.rate,
        retry_failed=args.retry_failed, progress=None if args.quiet else progress_line(),
    )
    planned = len(summary.outcomes) - summary.failed
    print(f"{len(requests)} motions: {planned} planned, {summary.failed} failed"
          + (f" ({summary.skipped} done before, skipped)" if summary.skipped else "")
          + f", {time.perf_counter() - t0:.1f} s; wrote {Path(args.out) / 'summary.csv'}")
    for outcome in summary.outcomes:
        if outcome.error:
            print(f"  {outcome.id}: {outcome.error}", file=sys.stderr)
        for message in outcome.warnings:
            print(f"  {outcome.id}: warning: {message}", file=sys.stderr)
    return 1 if summary.failed else 0


FIGURE_NAMES = ("torques.png", "workspace.png", "history.png")


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
    return (f"iteration {entry.index:3d}  J = {entry.J:.6f}  step = {step:>8}  "
            f"te = {entry.duration:.4f} s  {entry.wall_time:7.2f} s")


class _Interrupt:
    """Ctrl-C: the first SIGINT ends planning with the best plan so far (the planner turns the
    KeyboardInterrupt into that), a second one aborts at once (exit code 130, nothing written)."""

    def __init__(self) -> None:
        self.count = 0

    def _handler(self, signum: int, frame: object) -> None:
        self.count += 1
        if self.count > 1:
            raise _Abort
        raise KeyboardInterrupt

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
        return _plan_command(args, interrupt)
    except VerificationError as exc:
        _fail(str(exc), code=1)
    except NearoptError as exc:
        _fail(str(exc))
    except OSError as exc:
        _fail(f"cannot write {exc.filename or 'an output file'}: {exc.strerror or exc}")
    except KeyboardInterrupt:
        if args is not None and args.command == "batch":
            _fail("interrupted: the motions written so far are kept (run it again to go on)",
                  code=130)
        _fail("interrupted before a plan was found; nothing written", code=130)
    except _Abort:
        _fail("aborted by a second Ctrl-C; nothing written", code=130)


if __name__ == "__main__":
    sys.exit(main())
