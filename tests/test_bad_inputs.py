"""Every kind of bad request, answered by a specific nearopt exception (Python) and by one line on
stderr with a non-zero exit code and no output file (CLI) — never a traceback, never a silent plan.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from conftest import load
from console import run_cli
from urdfs import erd_urdf, write_urdf

import nearopt
from nearopt import (
    ConfigurationError,
    InfeasiblePathError,
    NearoptError,
    RobotNotFoundError,
    SceneError,
    URDFError,
)
from nearopt.api import PlanRequest, run
from nearopt.collision import Sphere
from nearopt.export import json_text, write_json
from nearopt.paper_example import THETA_0, THETA_E
from nearopt.viz import export_html
from nearopt.viz.figures import save_figures

WEAK = '<limit effort="1" velocity="2" lower="-3" upper="3"/>'  # gravity needs ≈ 3.9 N·m at 1.5 rad
PAPER = ["--q0", "45", "-90", "--qe", "-90", "0", "--deg"]


@dataclass(frozen=True)
class Case:
    """A bad input: how Python is asked, how the CLI is asked, what the answer must say."""

    python: Callable[[Path], object] | None
    cli: Callable[[Path], list[str]] | None
    error: type[Exception]
    says: str


def urdf(tmp_path: Path, text: str, name: str = "bad.urdf") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


ONE_RAD = ["--robot", "two_link", "--q0", "0", "0", "--qe", "1", "1"]  # a motion of 1 rad
UR5_DEG = ["--robot", "ur5", "--deg", "--qe", *"30 -100 110 -30 -50 -40".split()]
START3 = "start = [0.1, 0.2, 0.3]\n[[target]]\nq = [0.2, -0.3]\n"
FAR_BOX = '[[obstacle]]\nname = "box"\nbox = [0.1, 0.1, 0.1]\nposition = [5.0, 5.0, 5.0]\n'


def urdf_with_mesh(tmp_path: Path) -> Path:
    """The chain of :func:`write_urdf` whose link b is drawn by a mesh file next to it."""
    import trimesh

    trimesh.creation.box((0.05, 0.05, 0.05)).export(tmp_path / "part.stl")
    path = write_urdf(tmp_path)
    visual = '<visual><geometry><mesh filename="part.stl"/></geometry></visual>'
    text = path.read_text()
    head, tail = text.split('<link name="b">', 1)
    path.write_text(f'{head}<link name="b">{visual}{tail}')
    return path


def bad_group(tmp_path: Path) -> Path:
    """An SRDF whose group 'bad' names only a joint the chain of :func:`write_urdf` lacks."""
    path = tmp_path / "bad.srdf"
    path.write_text('<robot name="chain"><group name="bad"><joint name="nope"/></group></robot>')
    return path


def urdf_with_meshes_of_one_name(tmp_path: Path) -> Path:
    """The chain of :func:`write_urdf` drawn by three files of the same name in three folders
    (link a: x/part.stl; link b: y/part.stl and z/part.stl)."""
    import trimesh

    path = write_urdf(tmp_path)
    text = path.read_text()
    for link, folder in (("a", "x"), ("b", "y"), ("b", "z")):
        (tmp_path / folder).mkdir()
        trimesh.creation.box((0.05, 0.05, 0.05)).export(tmp_path / folder / "part.stl")
        visual = f'<visual><geometry><mesh filename="{folder}/part.stl"/></geometry></visual>'
        head, tail = text.split(f'<link name="{link}">', 1)
        text = f'{head}<link name="{link}">{visual}{tail}'
    path.write_text(text)
    return path


def hard_link(target: Path, link: Path) -> Path:
    link.hardlink_to(target)
    return link


def edited(tmp_path: Path, old: str, new: str, count: int = 1) -> Path:
    """The chain of :func:`write_urdf` with ``old`` replaced by ``new`` (``count`` times)."""
    path = write_urdf(tmp_path)
    text = path.read_text()
    assert old in text, old
    path.write_text(text.replace(old, new, count))
    return path


def from_edited(old: str, new: str, count: int = 1) -> Callable[[Path], object]:
    return lambda p: nearopt.Robot.from_urdf(edited(p, old, new, count))


def cli_edited(old: str, new: str, count: int = 1) -> Callable[[Path], list[str]]:
    return lambda p: ["--urdf", str(edited(p, old, new, count)), "--q0", "0", "0", "--qe", "1", "1"]


def two_link() -> nearopt.Robot:
    return load("two_link")


def plan(q0: object, qe: object, cost: nearopt.Cost | None = None, **kw: object) -> object:
    return nearopt.plan(two_link(), q0, qe, cost, grid=20, max_iterations=2, **kw)


GOOD = (THETA_0, THETA_E)
PANDA_URDF = erd_urdf("panda_description/urdf/panda.urdf")
PANDA_SRDF = erd_urdf("panda_description/srdf/panda.srdf")
PANDA_Q = [
    "--q0",
    "0",
    "-0.5",
    "0",
    "-2",
    "0",
    "1.5",
    "0.8",
    "--qe",
    "1",
    "0",
    "0.5",
    "-1.5",
    "0",
    "2",
    "0",
]

CASES = {
    "missing URDF": Case(
        lambda p: nearopt.Robot.from_urdf(p / "nope.urdf"),
        lambda p: ["--urdf", str(p / "nope.urdf"), "--q0", "0", "0", "--qe", "1", "1"],
        URDFError,
        "not found",
    ),
    "unreadable URDF (a folder)": Case(
        lambda p: nearopt.Robot.from_urdf(p),
        lambda p: ["--urdf", str(p), "--q0", "0", "0", "--qe", "1", "1"],
        URDFError,
        "is a directory",
    ),
    "malformed URDF": Case(
        lambda p: nearopt.Robot.from_urdf(urdf(p, '<robot name="x"><link name="a">')),
        lambda p: ["--urdf", str(urdf(p, "<robot")), "--q0", "0", "--qe", "1"],
        URDFError,
        "malformed",
    ),
    "URDF without inertias": Case(
        lambda p: nearopt.Robot.from_urdf(write_urdf(p, inertial=False)),
        lambda p: [
            "--urdf",
            str(write_urdf(p, inertial=False)),
            "--q0",
            "0",
            "0",
            "--qe",
            "1",
            "1",
        ],
        URDFError,
        "inertia",
    ),
    "URDF without effort limits": Case(
        lambda p: nearopt.Robot.from_urdf(write_urdf(p, limits=('<limit velocity="1"/>',) * 2)),
        lambda p: [
            "--urdf",
            str(write_urdf(p, limits=('<limit velocity="1"/>',) * 2)),
            "--q0",
            "0",
            "0",
            "--qe",
            "1",
            "1",
        ],
        URDFError,
        "effort",
    ),
    "floating base": Case(
        lambda p: nearopt.Robot.from_urdf(write_urdf(p, types=("floating", "revolute"))),
        lambda p: [
            "--urdf",
            str(write_urdf(p, types=("floating", "revolute"))),
            "--q0",
            "0",
            "--qe",
            "1",
        ],
        URDFError,
        "floating",
    ),
    "mimic joint": Case(
        lambda p: nearopt.Robot.from_urdf(write_urdf(p, extra=("", '<mimic joint="j1"/>'))),
        lambda p: [
            "--urdf",
            str(write_urdf(p, extra=("", '<mimic joint="j1"/>'))),
            "--q0",
            "0",
            "0",
            "--qe",
            "1",
            "1",
        ],
        URDFError,
        "mimic",
    ),
    "unknown robot name": Case(
        lambda p: nearopt.Robot.from_name("ur10"),
        lambda p: ["--robot", "ur10", *PAPER],
        RobotNotFoundError,
        "known robots: two_link, kinova, panda, so101, ur5, xarm7, z1",
    ),
    "q0 of the wrong length": Case(
        lambda p: plan([0.1], GOOD[1]),
        lambda p: ["--robot", "two_link", "--q0", "0.1", "--qe", "1", "1"],
        ConfigurationError,
        "q0 must have 2 values",
    ),
    "qe of the wrong length": Case(
        lambda p: plan(GOOD[0], [1, 2, 3]),
        lambda p: ["--robot", "two_link", "--q0", "0", "0", "--qe", "1", "2", "3"],
        ConfigurationError,
        "qe must have 2 values",
    ),
    "NaN in q0": Case(
        lambda p: plan([np.nan, 0.0], GOOD[1]),
        lambda p: ["--robot", "two_link", "--q0", "nan", "0", "--qe", "1", "1"],
        ConfigurationError,
        "q0 of joint 'joint1' is nan",
    ),
    "inf in qe": Case(
        lambda p: plan(GOOD[0], [0.0, np.inf]),
        lambda p: ["--robot", "two_link", "--q0", "0", "0", "--qe", "0", "inf"],
        ConfigurationError,
        "qe of joint 'joint2' is inf",
    ),
    "qe outside the position limits": Case(
        lambda p: nearopt.plan(load("panda"), [0, 0, 0, -1, 0, 1, 0], [0, 0, 0, -1, 0, 1, 3.5]),
        lambda p: [
            "--robot",
            "panda",
            "--q0",
            "0",
            "0",
            "0",
            "-1",
            "0",
            "1",
            "0",
            "--qe",
            "0",
            "0",
            "0",
            "-1",
            "0",
            "1",
            "3.5",
        ],
        ConfigurationError,
        "qe[6] = 3.5 rad is outside the position limits",
    ),
    "q0 == qe (zero-length motion)": Case(
        lambda p: plan(GOOD[0], GOOD[0]),
        lambda p: ["--robot", "two_link", "--q0", "45", "-90", "--qe", "45", "-90", "--deg"],
        ConfigurationError,
        "zero-length",
    ),
    "negative beta": Case(
        lambda p: nearopt.TorqueCost(-0.03),
        lambda p: ["--robot", "two_link", *PAPER, "--beta", "-0.03"],
        ConfigurationError,
        "beta must be finite and ≥ 0, got -0.03",
    ),
    "NaN beta": Case(
        lambda p: nearopt.TorqueCost(float("nan")),
        lambda p: ["--robot", "two_link", *PAPER, "--beta", "nan"],
        ConfigurationError,
        "beta must be finite and ≥ 0",
    ),
    "a via-point at the start": Case(
        lambda p: plan(*GOOD, via=[THETA_E * 0.5, THETA_E * 0.5]),
        lambda p: ["--robot", "two_link", *PAPER, "--via", "0", "0", "--via", "0", "0"],
        ConfigurationError,
        "via-point 0 and via-point 1 are the same configuration",
    ),
    "a via-point at the goal": Case(
        lambda p: plan(*GOOD, via=[THETA_E]),
        lambda p: ["--robot", "two_link", *PAPER, "--via", "-90", "0"],
        ConfigurationError,
        "via-point 0 and the goal are the same configuration",
    ),
    "a max_duration too short": Case(
        lambda p: plan(*GOOD, nearopt.TorqueCost(0.03), max_duration=0.01),
        lambda p: ["--robot", "two_link", *PAPER, "--beta", "0.03", "--max-duration", "0.01"],
        InfeasiblePathError,
        "max_duration 0.01 s is shorter than the time-optimal motion",
    ),
    "a NaN start velocity": Case(
        lambda p: plan(*GOOD, qd0=[0.0, np.nan]),
        lambda p: ["--robot", "two_link", *PAPER, "--qd0", "0", "nan"],
        ConfigurationError,
        "qd0 of joint 'joint2' is nan",
    ),
    "negative weight": Case(
        lambda p: nearopt.TorqueCost(weights=[0.1, -0.1]),
        lambda p: ["--robot", "two_link", *PAPER, "--weights", "0.1", "-0.1"],
        ConfigurationError,
        "weights must be finite and ≥ 0",
    ),
    "weights of the wrong length": Case(
        lambda p: plan(*GOOD, nearopt.TorqueCost(weights=[0.1, 0.1, 0.1])),
        lambda p: ["--robot", "two_link", *PAPER, "--weights", "0.1", "0.1", "0.1"],
        ConfigurationError,
        "weight",
    ),
    "rate <= 0": Case(
        lambda p: nearopt.optimal_timing(two_link(), nearopt.StraightPath(*GOOD)).trajectory.sample(
            0.0
        ),
        lambda p: ["--robot", "two_link", *PAPER, "--rate", "-5", "--json", str(p / "a.json")],
        ConfigurationError,
        "rate",
    ),
    "unwritable output path": Case(
        lambda p: write_json(plan(*GOOD), p / "missing" / "plan.json"),
        lambda p: ["--robot", "two_link", *PAPER, "--json", str(p / "missing" / "plan.json")],
        ConfigurationError,
        "does not exist",
    ),
    "output path is a folder": Case(
        lambda p: write_json(plan(*GOOD), p),
        lambda p: ["--robot", "two_link", *PAPER, "--csv", str(p)],
        ConfigurationError,
        "is a directory",
    ),
    "gravity beyond the limit at θ0": Case(
        lambda p: nearopt.plan(
            nearopt.Robot.from_urdf(write_urdf(p, limits=(WEAK, WEAK))), [1.5, 0.0], [0.0, 0.0]
        ),
        lambda p: [
            "--urdf",
            str(write_urdf(p, limits=(WEAK, WEAK))),
            "--q0",
            "1.5",
            "0",
            "--qe",
            "0",
            "0",
        ],
        InfeasiblePathError,
        "joint 'j1'",
    ),
    "gravity beyond the limit at θe": Case(
        lambda p: nearopt.plan(two_link().with_limits(effort=[3.0, 5.0]), *GOOD),
        None,  # the CLI takes the URDF's limits; the same check as the previous case
        InfeasiblePathError,
        "joint 'joint1', beyond its upper limit 3",
    ),
    "cost callable that raises": Case(
        lambda p: plan(*GOOD, nearopt.CallableCost(lambda q, qd, u: 1 / 0)),
        None,  # the CLI has no user callables
        NearoptError,
        "raised ZeroDivisionError",
    ),
    "cost callable that returns NaN": Case(
        lambda p: plan(*GOOD, nearopt.CallableCost(lambda q, qd, u: np.full(len(q), np.nan))),
        None,
        NearoptError,
        "returned nan",
    ),
    "unknown planning method": Case(
        lambda p: plan(*GOOD, method="newton"),
        lambda p: ["--robot", "two_link", *PAPER, "--method", "newton"],
        ConfigurationError,
        "method",
    ),
    "--lock with a named robot": Case(
        None,
        lambda p: ["--robot", "two_link", *PAPER, "--lock", "joint1"],
        ConfigurationError,
        "--lock applies to --urdf",
    ),
    "one weight for a two-joint arm (CLI)": Case(
        None,
        lambda p: ["--robot", "two_link", *PAPER, "--weights", "0.1"],
        ConfigurationError,
        "one weight per joint",
    ),
    "a later output fails after an earlier one could be written": Case(
        None,
        lambda p: [
            "--robot",
            "two_link",
            *PAPER,
            "--grid",
            "20",
            "--max-iterations",
            "2",
            "--json",
            str(p / "a.json"),
            "--plots",
            "/proc",
        ],
        ConfigurationError,
        "cannot write /proc",
    ),
    "grid too small": Case(
        lambda p: nearopt.plan(two_link(), *GOOD, grid=1),
        lambda p: ["--robot", "two_link", *PAPER, "--grid", "1"],
        ConfigurationError,
        "grid must be an integer ≥ 2",
    ),
    # ------------------------------------------------------------ URDF physics, one flaw each
    "negative mass": Case(
        from_edited('<mass value="1"/>', '<mass value="-1"/>'),
        cli_edited('<mass value="1"/>', '<mass value="-1"/>'),
        URDFError,
        "negative mass, -1 kg",
    ),
    "NaN mass": Case(
        from_edited('<mass value="1"/>', '<mass value="nan"/>'),
        cli_edited('<mass value="1"/>', '<mass value="nan"/>'),
        URDFError,
        "nan",
    ),
    "inertia not positive semi-definite": Case(
        from_edited('ixx="0.01"', 'ixx="-0.01"'),
        cli_edited('ixx="0.01"', 'ixx="-0.01"'),
        URDFError,
        "inertia",
    ),
    "inertia breaks the triangle inequality": Case(
        from_edited('izz="0.001"', 'izz="0.05"'),
        cli_edited('izz="0.001"', 'izz="0.05"'),
        URDFError,
        "triangle",
    ),
    "NaN in a joint origin": Case(
        from_edited('<origin xyz="0 0 0.2"/>', '<origin xyz="0 0 nan"/>'),
        cli_edited('<origin xyz="0 0 0.2"/>', '<origin xyz="0 0 nan"/>'),
        URDFError,
        "j1",
    ),
    "lower position limit above the upper": Case(
        from_edited('lower="-3" upper="3"', 'lower="3" upper="-3"'),
        cli_edited('lower="-3" upper="3"', 'lower="3" upper="-3"'),
        URDFError,
        "j1",
    ),
    "a joint whose position limits leave it no room": Case(
        from_edited('lower="-3" upper="3"', 'lower="0.5" upper="0.5"'),
        cli_edited('lower="-3" upper="3"', 'lower="0.5" upper="0.5"'),
        URDFError,
        "joint 'j1' has position limits lower = upper = 0.5: it cannot move",
    ),
    "negative joint damping": Case(
        from_edited("</joint>", '<dynamics damping="-1.0"/></joint>'),
        cli_edited("</joint>", '<dynamics damping="-1.0"/></joint>'),
        URDFError,
        "joint 'j1' has a negative damping -1.0",
    ),
    "a negative joint friction (Pinocchio's message named neither)": Case(
        from_edited("</joint>", '<dynamics friction="-1"/></joint>'),
        cli_edited("</joint>", '<dynamics friction="-1"/></joint>'),
        URDFError,
        "joint 'j1' has a negative friction -1 N·m",
    ),
    "a mass followed by a space (urdfdom dropped it, silently to nearopt)": Case(
        from_edited('<mass value="1"/>', '<mass value=" 1 "/>'),
        cli_edited('<mass value="1"/>', '<mass value=" 1 "/>'),
        URDFError,
        "<mass value> of link 'a' is ' 1 ': Pinocchio's URDF reader (urdfdom) reads no number "
        "followed by a space, tab or line break; write '1'",
    ),
    "an inertia without its products (urdfdom dropped it)": Case(
        from_edited('ixy="0" ixz="0" ', ""),
        cli_edited('ixy="0" ixz="0" ', ""),
        URDFError,
        "link 'a' has an <inertia> without ixy, ixz",
    ),
    "an empty effort limit (a traceback)": Case(
        from_edited('effort="5"', 'effort=""'),
        cli_edited('effort="5"', 'effort=""'),
        URDFError,
        "<limit effort> of joint 'j1' is '', not a number",
    ),
    "two numbers for one": Case(
        from_edited('<mass value="1"/>', '<mass value="1 2"/>'),
        cli_edited('<mass value="1"/>', '<mass value="1 2"/>'),
        URDFError,
        "<mass value> of link 'a' is '1 2': one number expected, not 2",
    ),
    "a digit separator Python reads and urdfdom does not": Case(
        from_edited('effort="5"', 'effort="5_0"'),
        cli_edited('effort="5"', 'effort="5_0"'),
        URDFError,
        "<limit effort> of joint 'j1' is '5_0', not a number",
    ),
    "a lower position limit alone, above the upper's default 0": Case(
        from_edited('lower="-3" upper="3"', 'lower="1"'),
        cli_edited('lower="-3" upper="3"', 'lower="1"'),
        URDFError,
        "joint 'j1' has position limits lower 1 > upper 0 (not given)",
    ),
    "negative effort limit": Case(
        from_edited('effort="5"', 'effort="-5"'),
        cli_edited('effort="5"', 'effort="-5"'),
        URDFError,
        "effort",
    ),
    "negative velocity limit": Case(
        from_edited('velocity="2"', 'velocity="-2"'),
        cli_edited('velocity="2"', 'velocity="-2"'),
        URDFError,
        "velocity",
    ),
    "zero joint axis": Case(
        from_edited('<axis xyz="0 1 0"/>', '<axis xyz="0 0 0"/>'),
        cli_edited('<axis xyz="0 1 0"/>', '<axis xyz="0 0 0"/>'),
        URDFError,
        "axis",
    ),
    "two joints of one name": Case(
        from_edited('name="j2"', 'name="j1"'), cli_edited('name="j2"', 'name="j1"'), URDFError, "j1"
    ),
    "a joint names an unknown link": Case(
        from_edited('<child link="b"/>', '<child link="c"/>'),
        cli_edited('<child link="b"/>', '<child link="c"/>'),
        URDFError,
        "'c'",
    ),
    "a link with two parents": Case(
        from_edited('<parent link="a"/><child link="b"/>', '<parent link="b"/><child link="a"/>'),
        cli_edited('<parent link="a"/><child link="b"/>', '<parent link="b"/><child link="a"/>'),
        URDFError,
        "'a'",
    ),
    "a robot without joints": Case(
        lambda p: nearopt.Robot.from_urdf(urdf(p, '<robot name="x"><link name="a"/></robot>')),
        lambda p: [
            "--urdf",
            str(urdf(p, '<robot name="x"><link name="a"/></robot>')),
            "--q0",
            "0",
            "--qe",
            "1",
        ],
        URDFError,
        "no moving joint",
    ),
    "unsupported joint type": Case(
        from_edited('type="revolute"', 'type="planar"'),
        cli_edited('type="revolute"', 'type="planar"'),
        URDFError,
        "planar",
    ),
    # ------------------------------------------------------------ choosing the arm in a URDF
    "--tip names an unknown link": Case(
        lambda p: nearopt.Robot.from_urdf(PANDA_URDF, tip="panda_link99"),
        lambda p: ["--urdf", str(PANDA_URDF), "--tip", "panda_link99", *PANDA_Q],
        URDFError,
        "panda_link99",
    ),
    "--base is not on the way to --tip": Case(
        lambda p: nearopt.Robot.from_urdf(PANDA_URDF, tip="panda_link3", base="panda_link5"),
        lambda p: [
            "--urdf",
            str(PANDA_URDF),
            "--tip",
            "panda_link3",
            "--base",
            "panda_link5",
            "--q0",
            "0",
            "0",
            "0",
            "--qe",
            "1",
            "1",
            "1",
        ],
        URDFError,
        "panda_link5",
    ),
    "--lock names an unknown joint": Case(
        lambda p: nearopt.Robot.from_urdf(write_urdf(p), locked_joints=["j7"]),
        lambda p: ["--urdf", str(write_urdf(p)), "--lock", "j7", "--q0", "0", "--qe", "1"],
        URDFError,
        "j7",
    ),
    "--lock-at names a joint that is not locked": Case(
        lambda p: nearopt.Robot.from_urdf(write_urdf(p), locked_joints=["j2"], lock_at={"j1": 0.1}),
        lambda p: [
            "--urdf",
            str(write_urdf(p)),
            "--lock",
            "j2",
            "--lock-at",
            "j1=0.1",
            "--q0",
            "0",
            "--qe",
            "1",
        ],
        ConfigurationError,
        "lock_at names joint 'j1', which is not locked",
    ),
    "--lock-at outside the joint's limits": Case(
        lambda p: nearopt.Robot.from_urdf(write_urdf(p), locked_joints=["j2"], lock_at={"j2": 4.0}),
        lambda p: [
            "--urdf",
            str(write_urdf(p)),
            "--lock",
            "j2",
            "--lock-at",
            "j2=4",
            "--q0",
            "0",
            "--qe",
            "1",
        ],
        ConfigurationError,
        "joint 'j2' cannot be locked at 4",
    ),
    "a URDF path with a NUL character (a bare ValueError)": Case(
        lambda p: nearopt.Robot.from_urdf(str(write_urdf(p)) + "\0x"),
        None,
        URDFError,
        "a path holds no NUL character: the URDF",
    ),
    "a device as the URDF (it was called not found)": Case(
        lambda p: nearopt.Robot.from_urdf("/dev/null"),
        lambda p: ["--urdf", "/dev/null", "--q0", "0", "--qe", "1"],
        URDFError,
        "/dev/null is not a regular file",
    ),
    "--lock-at without a value": Case(
        None,
        lambda p: [
            "--urdf",
            str(write_urdf(p)),
            "--lock",
            "j2",
            "--lock-at",
            "j2",
            "--q0",
            "0",
            "--qe",
            "1",
        ],
        ConfigurationError,
        "JOINT=VALUE",
    ),
    "an SRDF group of joints the URDF lacks (it said the URDF had no moving joint)": Case(
        lambda p: nearopt.Robot.from_urdf(write_urdf(p), srdf=bad_group(p), group="bad"),
        lambda p: [
            *("--urdf", str(write_urdf(p)), "--srdf", str(bad_group(p)), "--group", "bad"),
            *("--q0", "0", "--qe", "1"),
        ],
        URDFError,
        "holds no moving joint of",
    ),
    "a dict as q0 (it was called a single number)": Case(
        lambda p: nearopt.plan(two_link(), {"joint1": 0, "joint2": 0}, [1, 1]),
        None,
        ConfigurationError,
        "q0 is a list of 2 values in the joints' order (joint1, joint2), not a dict",
    ),
    "--srdf that does not exist": Case(
        lambda p: nearopt.Robot.from_urdf(PANDA_URDF, srdf=p / "nope.srdf", group="panda_arm"),
        lambda p: [
            "--urdf",
            str(PANDA_URDF),
            "--srdf",
            str(p / "nope.srdf"),
            "--group",
            "panda_arm",
            *PANDA_Q,
        ],
        URDFError,
        "nope.srdf",
    ),
    "--group unknown to the SRDF": Case(
        lambda p: nearopt.Robot.from_urdf(PANDA_URDF, srdf=PANDA_SRDF, group="left_arm"),
        lambda p: [
            "--urdf",
            str(PANDA_URDF),
            "--srdf",
            str(PANDA_SRDF),
            "--group",
            "left_arm",
            *PANDA_Q,
        ],
        URDFError,
        "left_arm",
    ),
    "--group without --srdf": Case(
        lambda p: nearopt.Robot.from_urdf(PANDA_URDF, group="panda_arm"),
        lambda p: ["--urdf", str(PANDA_URDF), "--group", "panda_arm", *PANDA_Q],
        ConfigurationError,
        "srdf",
    ),
    "--tip with a named robot": Case(
        None,
        lambda p: ["--robot", "two_link", *PAPER, "--tip", "link2"],
        ConfigurationError,
        "--tip",
    ),
    "both --robot and --urdf": Case(
        None,
        lambda p: ["--robot", "two_link", "--urdf", str(write_urdf(p)), *PAPER],
        ConfigurationError,
        "--urdf",
    ),
    "neither --robot nor --urdf": Case(None, lambda p: [*PAPER], ConfigurationError, "--robot"),
    # ------------------------------------------------------------ limit overrides
    "--effort-limit of the wrong length": Case(
        lambda p: two_link().with_limits(effort=[1.0, 2.0, 3.0]),
        lambda p: ["--robot", "two_link", *PAPER, "--effort-limit", "1", "2", "3"],
        ConfigurationError,
        "effort",
    ),
    "--effort-limit of zero": Case(
        lambda p: two_link().with_limits(effort=[0.0, 5.0]),
        lambda p: ["--robot", "two_link", *PAPER, "--effort-limit", "0", "5"],
        ConfigurationError,
        "effort limit of joint 'joint1' is 0, must be > 0",
    ),
    "--velocity-limit NaN": Case(
        lambda p: two_link().with_limits(velocity=[np.nan, 1.0]),
        lambda p: ["--robot", "two_link", *PAPER, "--velocity-limit", "nan", "1"],
        ConfigurationError,
        "joint1",
    ),
    "--velocity-scale of zero": Case(
        None,
        lambda p: ["--robot", "two_link", *PAPER, "--velocity-scale", "0"],
        ConfigurationError,
        "velocity-scale",
    ),
    "--acceleration-limit negative": Case(
        lambda p: two_link().with_limits(acceleration=-1.0),
        lambda p: ["--robot", "two_link", *PAPER, "--acceleration-limit", "-1"],
        ConfigurationError,
        "acceleration limit of joint 'joint1' is -1",
    ),
    "effort limits lower above upper": Case(
        lambda p: two_link().with_limits(effort=([1.0, 1.0], [0.0, 2.0])),
        None,  # the CLI takes symmetric limits
        ConfigurationError,
        "lower 1 is not below upper 0",
    ),
    # ------------------------------------------------------------ planner settings
    "negative max_iterations": Case(
        lambda p: nearopt.plan(two_link(), *GOOD, max_iterations=-1),
        lambda p: ["--robot", "two_link", *PAPER, "--max-iterations", "-1"],
        ConfigurationError,
        "max_iterations must be an integer ≥ 0",
    ),
    "time limit of zero": Case(
        lambda p: nearopt.plan(two_link(), *GOOD, time_limit=0),
        lambda p: ["--robot", "two_link", *PAPER, "--time-limit", "0"],
        ConfigurationError,
        "must be a positive number of seconds",
    ),
    "NaN time limit": Case(
        lambda p: nearopt.plan(two_link(), *GOOD, time_limit=float("nan")),
        lambda p: ["--robot", "two_link", *PAPER, "--time-limit", "nan"],
        ConfigurationError,
        "must be a positive number of seconds",
    ),
    "grid too fine": Case(
        lambda p: nearopt.plan(two_link(), *GOOD, grid=10**7),
        lambda p: ["--robot", "two_link", *PAPER, "--grid", "10000000"],
        ConfigurationError,
        "≤ 100000",
    ),
    "sampling rate above 1 MHz": Case(
        lambda p: nearopt.optimal_timing(two_link(), nearopt.StraightPath(*GOOD)).trajectory.sample(
            1e12
        ),
        lambda p: ["--robot", "two_link", *PAPER, "--rate", "2e6", "--json", str(p / "a.json")],
        ConfigurationError,
        "rate",
    ),
    "too many control points": Case(
        lambda p: plan(*GOOD, options=nearopt.SCPOptions(control_points=10**6)),
        None,
        ConfigurationError,
        "control_points must be an integer from 2 to 200",
    ),
    "fractional control points": Case(
        lambda p: plan(*GOOD, options=nearopt.SCPOptions(control_points=12.5)),
        None,
        ConfigurationError,
        "got 12.5",
    ),
    "paper method with no trials": Case(
        lambda p: plan(*GOOD, method="paper", options=nearopt.PaperOptions(trials=0)),
        None,
        ConfigurationError,
        "trials must be an integer from 1 to 100",
    ),
    "options of the other method": Case(
        lambda p: plan(*GOOD, method="paper", options=nearopt.SCPOptions()),
        None,
        ConfigurationError,
        "method 'paper' takes PaperOptions, got SCPOptions",
    ),
    "scp with a user cost": Case(
        lambda p: plan(
            *GOOD, nearopt.CallableCost(lambda q, qd, u: 1 + np.sum(u**2, axis=1)), method="scp"
        ),
        None,
        ConfigurationError,
        "use method='paper'",
    ),
    # ------------------------------------------------------------ wrong types in Python
    "robot given by name to plan()": Case(
        lambda p: nearopt.plan("two_link", *GOOD),
        None,
        ConfigurationError,
        "robot must be a nearopt.Robot",
    ),
    "cost given as a plain function": Case(
        lambda p: plan(*GOOD, lambda q, qd, u: 1.0), None, ConfigurationError, "CallableCost(f0)"
    ),
    "cost given as a string": Case(
        lambda p: plan(*GOOD, "time"), None, ConfigurationError, "cost must be a nearopt cost"
    ),
    "cost callable that returns zero": Case(
        lambda p: plan(
            *GOOD, nearopt.CallableCost(lambda q, qd, u: np.zeros(len(q))), method="paper"
        ),
        None,
        NearoptError,
        "f0 = 0",
    ),
    "cost that is not callable": Case(
        lambda p: nearopt.CallableCost(3), None, ConfigurationError, "f0 must be callable"
    ),
    "both beta and weights": Case(
        lambda p: nearopt.TorqueCost(0.1, weights=[1, 1]),
        lambda p: ["--robot", "two_link", *PAPER, "--beta", "0.1", "--weights", "1", "1"],
        ConfigurationError,
        "beta",
    ),
    "path given as a string": Case(
        lambda p: nearopt.optimal_timing(two_link(), "line"),
        None,
        ConfigurationError,
        "path must be a nearopt path",
    ),
    "straight line between vectors of different lengths": Case(
        lambda p: nearopt.StraightPath([0, 0], [1, 1, 1]),
        None,
        ConfigurationError,
        "theta0 has 2 joints but thetae has 3",
    ),
    "B-spline breaks out of order": Case(
        lambda p: nearopt.BSplinePath(np.zeros((6, 2)), [0.5, 0.2]),
        None,
        ConfigurationError,
        "breaks must be 2 increasing values",
    ),
    "unknown frame": Case(
        lambda p: two_link().frame_position([0, 0], "nope"),
        None,
        ConfigurationError,
        "no frame 'nope'",
    ),
    "verification at a negative rate": Case(
        lambda p: nearopt.verify(
            nearopt.optimal_timing(two_link(), nearopt.StraightPath(*GOOD)).trajectory,
            two_link(),
            rate=-1,
        ),
        None,
        ConfigurationError,
        "the controller rate must be a number of Hz in (0, 1e+06], got -1",
    ),
    # ------------------------------------------------------------ the Python API, misused
    "verify with another robot's motion": Case(
        lambda p: nearopt.verify(plan(*GOOD).trajectory, load("ur5")),
        None,
        ConfigurationError,
        "the motion moves 2 joints but ur5 has 6",
    ),
    "verify(result) instead of verify(result.trajectory)": Case(
        lambda p: nearopt.verify(plan(*GOOD), two_link()),
        None,
        ConfigurationError,
        "pass its motion, result.trajectory, or verify_plan(result)",
    ),
    "time_limit as a string": Case(
        lambda p: plan(*GOOD, time_limit="5"),
        None,
        ConfigurationError,
        "time_limit must be a positive number of seconds",
    ),
    "TorqueCost(array) for per-joint weights": Case(
        lambda p: nearopt.TorqueCost(np.array([0.1, 0.2])),
        None,
        ConfigurationError,
        "per-joint weights go by name: TorqueCost(weights=[...])",
    ),
    "plan_many with a Robot object in a request": Case(
        lambda p: nearopt.plan_many([{"robot": two_link(), "q0": [0, 0], "qe": [1, 1]}]),
        None,
        ConfigurationError,
        "option 'robot': a motion's options are JSON values",
    ),
    "plan_many with client=42": Case(
        lambda p: nearopt.plan_many([{"robot": "two_link", "q0": [0, 0], "qe": [1, 1]}], 42),
        None,
        ConfigurationError,
        "client must be None (this machine), a scheduler address",
    ),
    "q0=None": Case(
        lambda p: plan(None, THETA_E),
        None,
        ConfigurationError,
        "q0 is missing: give 2 values",
    ),
    "a goal pose the tool already holds": Case(
        lambda p: nearopt.plan(
            two_link(), THETA_0, nearopt.ToolPose(two_link().frame_placement(THETA_0).translation)
        ),
        None,
        ConfigurationError,
        "frame already holds the goal pose at q0",
    ),
    "a task's start of the wrong length": Case(
        lambda p: nearopt.plan_task(
            two_link(), None, nearopt.Task.from_file(urdf(p, START3, "t.toml"))
        ),
        lambda p: ["--robot", "two_link", "--task", str(urdf(p, START3, "t.toml"))],
        ConfigurationError,
        "t.toml: start must have 2 values",
    ),
    "a speed limit that makes the motion last 273 days": Case(
        None,
        lambda p: ["--robot", "two_link", *PAPER, "--velocity-scale", "1e-9"],
        ConfigurationError,
        "the motion would last at least 2.356e+07 s (273 days)",
    ),
    "a speed limit of 1e-300 rad/s (b underflowed: 'b must be finite')": Case(
        lambda p: nearopt.plan(two_link().with_limits(velocity=1e-300), *GOOD),
        lambda p: ["--robot", "two_link", *PAPER, "--velocity-limit", "1e-300"],
        ConfigurationError,
        "e+300 s",  # how long it would take, at least
    ),
    # ------------------------------------------------------------ a new user's pass (helper)
    "verify with a Scene as collisions": Case(
        lambda p: nearopt.verify(plan(*GOOD).trajectory, two_link(), collisions=nearopt.Scene(())),
        None,
        ConfigurationError,
        "collisions must be a CollisionModel (a plan's result.collisions",
    ),
    "verify with J but no cost": Case(
        lambda p: nearopt.verify(plan(*GOOD).trajectory, two_link(), J=0.1),
        None,
        ConfigurationError,
        "pass cost= too",
    ),
    "verify with J as a string": Case(
        lambda p: nearopt.verify(
            plan(*GOOD).trajectory, two_link(), cost=nearopt.TimeCost(), J="0.1"
        ),
        None,
        ConfigurationError,
        "J must be a number",
    ),
    "api.run with a dict": Case(
        lambda p: run({"robot": "two_link", "q0": [0, 0], "qe": [0.5, 0.3]}),
        None,
        ConfigurationError,
        "a request is a PlanRequest (PlanRequest.from_mapping",
    ),
    "export_html with a motion, not a plan": Case(
        lambda p: export_html(plan(*GOOD).trajectory, p / "x.html"),
        None,
        ConfigurationError,
        "a motion alone is not enough",
    ),
    "a Robot object as PlanRequest.robot": Case(
        lambda p: run(PlanRequest(robot=two_link(), q0=(0, 0), qe=(0.5, 0.3))),
        None,
        ConfigurationError,
        "option 'robot' is a known arm's name",
    ),
    "plan_many with one dict (not a list)": Case(
        lambda p: nearopt.plan_many({"robot": "two_link", "q0": [0, 0], "qe": [1, 1]}),
        None,
        ConfigurationError,
        "give a list of motions",
    ),
    "timing a path that does not move": Case(
        lambda p: nearopt.optimal_timing(two_link(), nearopt.StraightPath([0, 0], [0, 0])),
        None,
        ConfigurationError,
        "the path does not move",
    ),
    "--no-velocity-limits with --velocity-limit": Case(
        None,
        lambda p: [*ONE_RAD, "--no-velocity-limits", "--velocity-limit", "1"],
        ConfigurationError,
        "--no-velocity-limits turns off the speed limits that --velocity-limit sets",
    ),
    "a last target passed through (stop = false)": Case(
        None,
        lambda p: [
            *ONE_RAD[:5],
            "--task",
            str(urdf(p, "[[target]]\nq = [0.5, 0.3]\nstop = false\n", "t.toml")),
        ],
        ConfigurationError,
        "is the last: the motion ends there at rest",
    ),
    "--json with an empty path": Case(
        None, lambda p: [*ONE_RAD, "--json", ""], ConfigurationError, "--json is an empty path"
    ),
    "a scene mesh that is not a mesh": Case(
        None,
        lambda p: [
            "--robot",
            "ur5",
            *("--q0", "0", "-1.2", "1.2", "-1.5", "-1.57", "0"),
            *("--qe", "0.3", "-1.2", "1.2", "-1.5", "-1.57", "0"),
            "--scene",
            str(urdf(p, '[[obstacle]]\nname = "m"\nmesh = "cell.toml"\n', "cell.toml")),
        ],
        SceneError,
        "cell.toml: obstacle 'm': cannot load the mesh",
    ),
    "an obstacle named like a link": Case(
        lambda p: nearopt.CollisionModel(
            load("ur5"),
            nearopt.Scene((nearopt.Obstacle("shoulder_link", Sphere(0.05), (2, 2, 2)),)),
        ),
        None,
        SceneError,
        "has the name of a link of ur5",
    ),
    "--html over a mesh of the URDF": Case(
        None,
        lambda p: [
            "--urdf",
            str(urdf_with_mesh(p)),
            *ONE_RAD[2:],
            "--html",
            str(p / "part.stl"),
        ],
        ConfigurationError,
        "part.stl is a mesh of the URDF (part.stl) of this request",
    ),
    "--csv over one of three meshes of the same name": Case(
        None,
        lambda p: [
            "--urdf",
            str(urdf_with_meshes_of_one_name(p)),
            *ONE_RAD[2:],
            "--csv",
            str(p / "z" / "part.stl"),
        ],
        ConfigurationError,
        "z/part.stl is a mesh of the URDF",
    ),
    # ------------------------------------------------------------ the re-check pass (helper)
    "q0 and qe of the same wrong length": Case(
        lambda p: run(PlanRequest(robot="two_link", q0=(0, 0, 0), qe=(0.5, 0.3, 0.1))),
        lambda p: ["--robot", "two_link", "--q0", "0", "0", "0", "--qe", "0.5", "0.3", "0.1"],
        ConfigurationError,
        "q0 must have 2 values",
    ),
    "the cost class instead of a cost": Case(
        lambda p: plan(*GOOD, nearopt.TorqueCost),
        None,
        ConfigurationError,
        "got the class TorqueCost: call it",
    ),
    "a single number as a configuration": Case(
        lambda p: plan(0.3, THETA_E), None, ConfigurationError, "got the single number 0.3"
    ),
    "a flat via list in a PlanRequest": Case(
        lambda p: run(PlanRequest(robot="two_link", q0=(0, 0), qe=(0.5, 0.3), via=(0.2, 0.1))),
        None,
        ConfigurationError,
        "option 'via' is a list of via-points",
    ),
    "a string as PlanRequest.q0": Case(
        lambda p: run(PlanRequest(robot="two_link", q0="0 0", qe=(0.5, 0.3))),
        None,
        ConfigurationError,
        "option 'q0' is a list of numbers",
    ),
    "a number as PlanRequest.effort_limit": Case(
        lambda p: run(PlanRequest(robot="two_link", q0=(0, 0), qe=(0.5, 0.3), effort_limit=3)),
        None,
        ConfigurationError,
        "option 'effort_limit' is a list of numbers",
    ),
    "a string as PlanRequest.lock": Case(
        lambda p: run(PlanRequest(robot="two_link", q0=(0, 0), qe=(0.5, 0.3), lock="gripper")),
        None,
        ConfigurationError,
        "option 'lock' is a list of names",
    ),
    "a robot's name as CollisionModel's robot": Case(
        lambda p: nearopt.CollisionModel("ur5", nearopt.Scene(())),
        None,
        ConfigurationError,
        "robot must be a nearopt.Robot",
    ),
    "no inverse-kinematics attempts": Case(
        lambda p: nearopt.inverse_kinematics(
            load("ur5"), nearopt.ToolPose((0.5, 0.2, 0.3)), attempts=0
        ),
        None,
        ConfigurationError,
        "attempts must be a positive integer",
    ),
    "a motion asked at a time that is not a number": Case(
        lambda p: plan(*GOOD).trajectory("a"), None, ConfigurationError, "times are numbers"
    ),
    # ------------------------------------------------------------ command line and outputs
    "--json into a folder that does not exist (a trailing slash)": Case(
        None,
        lambda p: ["--robot", "two_link", *PAPER, "--json", str(p / "newdir") + "/"],
        ConfigurationError,
        "it names a folder, which does not exist",
    ),
    "q0 that is not a number": Case(
        None,
        lambda p: ["--robot", "two_link", "--q0", "abc", "0", "--qe", "1", "1"],
        ConfigurationError,
        "abc",
    ),
    "missing --qe": Case(
        None, lambda p: ["--robot", "two_link", "--q0", "0", "0"], ConfigurationError, "--qe"
    ),
    "one file for two outputs": Case(
        None,
        lambda p: [
            "--robot",
            "two_link",
            *PAPER,
            "--json",
            str(p / "a.out"),
            "--csv",
            str(p / "a.out"),
        ],
        ConfigurationError,
        "a.out",
    ),
    "--html into a missing folder": Case(
        None,
        lambda p: ["--robot", "two_link", *PAPER, "--html", str(p / "missing" / "a.html")],
        ConfigurationError,
        "does not exist",
    ),
    "a record too long for its rate (a 2000 s motion at 1 kHz)": Case(
        lambda p: json_text(
            nearopt.plan(two_link().with_limits(acceleration=1e-6), (0, 0), (1, 1), grid=20)
        ),
        lambda p: [*ONE_RAD, "--acceleration-limit", "1e-6", "--json", str(p / "long.json")],
        ConfigurationError,
        "ask for a rate of at most 555.6 Hz",
    ),
    "a record at a rate of NaN": Case(
        lambda p: json_text(nearopt.plan(two_link(), (0, 0), (1, 1), max_iterations=0), np.nan),
        None,
        ConfigurationError,
        "rate must be a number of Hz in (0, 1e+06], got nan",
    ),
    "--json over the scene file": Case(
        None,
        lambda p: [
            "--robot",
            "two_link",
            *PAPER,
            "--scene",
            str(urdf(p, FAR_BOX, "cell.toml")),
            "--json",
            str(p / "cell.toml"),
        ],
        ConfigurationError,
        "cell.toml is the scene of this request: writing it would destroy it",
    ),
    "--csv over the URDF": Case(
        None,
        lambda p: ["--urdf", str(write_urdf(p)), *ONE_RAD[2:], "--csv", str(write_urdf(p))],
        ConfigurationError,
        "is the URDF of this request",
    ),
    "--json over the task file (a hard link to it)": Case(
        None,
        lambda p: [
            *ONE_RAD[:5],
            "--task",
            str(urdf(p, "[[target]]\nq = [0.2, -0.3]\n", "t.toml")),
            "--json",
            str(hard_link(p / "t.toml", p / "t.json")),
        ],
        ConfigurationError,
        "t.json is the task of this request (the same file as",
    ),
    "--deg: q0 beyond a position limit, said in degrees": Case(
        None,
        lambda p: [*UR5_DEG, "--q0", *"10 -60 200 -90 -80 10".split()],
        ConfigurationError,
        "q0[2] = 200 deg is outside the position limits [-180, 180] deg of joint 'elbow_joint'",
    ),
    "--deg: qd0 beyond a speed limit, said in deg/s": Case(
        None,
        lambda p: [
            *UR5_DEG,
            "--q0",
            *"10 -60 80 -90 -80 10".split(),
            "--qd0",
            *"0 0 0 0 0 -400".split(),
        ],
        ConfigurationError,
        "qd0 of joint 'wrist_3_joint' is -400 deg/s, beyond its speed limit 183.346 deg/s",
    ),
    "--plots is a file": Case(
        lambda p: save_figures(plan(*GOOD), urdf(p, "x", "taken.png")),
        lambda p: ["--robot", "two_link", *PAPER, "--plots", str(urdf(p, "x", "taken"))],
        ConfigurationError,
        "not a folder",
    ),
}


@pytest.mark.parametrize("name", [n for n, c in CASES.items() if c.python is not None])
def test_python_raises_a_specific_nearopt_error(name: str, tmp_path: Path) -> None:
    case = CASES[name]
    with pytest.raises(case.error) as info:
        case.python(tmp_path)
    assert isinstance(info.value, NearoptError)
    assert case.says in str(info.value)


@pytest.mark.parametrize("name", [n for n, c in CASES.items() if c.cli is not None])
def test_cli_answers_with_one_line_and_writes_nothing(name: str, tmp_path: Path) -> None:
    case = CASES[name]
    work = tmp_path / "work"
    work.mkdir()
    args = case.cli(work)
    before = sorted(work.rglob("*"))
    done = run_cli("plan", *args, cwd=work)  # in this process: the console script is
    # tested as a process in test_cli.py (exit codes, one-line errors)
    assert done.returncode != 0
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("nearopt: error: "), done.stderr
    assert case.says in lines[0], lines[0]
    assert sorted(work.rglob("*")) == before  # no output file, not even a partial one


def test_max_duration_inf_is_no_limit() -> None:
    """``max_duration=inf`` (``--max-duration inf``) plans as without it, as ``time_limit=inf``
    does; it was refused as not finite."""
    cost = nearopt.TorqueCost(0.03)
    free = nearopt.plan(two_link(), *GOOD, cost, grid=20, max_iterations=0)
    unbounded = nearopt.plan(
        two_link(), *GOOD, cost, grid=20, max_iterations=0, max_duration=np.inf
    )
    assert unbounded.J == free.J and unbounded.duration == free.duration


def test_an_output_over_a_package_mesh_found_through_ros_package_path(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A mesh named ``package://mypkg/…`` that Pinocchio finds through ROS_PACKAGE_PATH is one of
    the request's inputs like any other mesh: ``--json`` onto it was written (the STL lost; a
    fuzz pass's note)."""
    import trimesh

    meshes = tmp_path / "ws" / "mypkg" / "meshes"
    meshes.mkdir(parents=True)
    trimesh.creation.box((0.05, 0.05, 0.05)).export(meshes / "part.stl")
    before = (meshes / "part.stl").read_bytes()
    path = write_urdf(tmp_path)
    visual = '<visual><geometry><mesh filename="package://mypkg/meshes/part.stl"/></geometry>'
    head, tail = path.read_text().split('<link name="b">', 1)
    path.write_text(f'{head}<link name="b">{visual}</visual>{tail}')
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path / "ws"))
    done = run_cli("plan", "--urdf", str(path), *ONE_RAD[2:], "--json", str(meshes / "part.stl"))
    assert done.returncode != 0
    assert "part.stl is a mesh of the URDF" in done.stderr, done.stderr
    assert (meshes / "part.stl").read_bytes() == before


def test_lock_at_a_joint_whose_name_holds_an_equals_sign(tmp_path: Path) -> None:
    """``--lock-at a=b=0.5`` locks joint ``a=b`` at 0.5 (it was refused: split at the first =)."""
    path = write_urdf(tmp_path)
    path.write_text(path.read_text().replace('name="j2"', 'name="a=b"'))
    request = PlanRequest(urdf=str(path), lock=("a=b",), lock_at=("a=b=0.5",), q0=(0,), qe=(1,))
    outcome = run(request)
    assert outcome.prepared.robot.locked_joints == ("a=b",)
    zero = np.zeros(1)

    def gravity(robot: nearopt.Robot) -> np.ndarray:  # j1's, with link b's centre at 0.5 rad
        return robot.inverse_dynamics(zero, zero, zero)

    locked = nearopt.Robot.from_urdf(path, locked_joints=("a=b",), lock_at={"a=b": 0.5})
    np.testing.assert_allclose(gravity(outcome.prepared.robot), gravity(locked))
    at_zero = nearopt.Robot.from_urdf(path, locked_joints="a=b")
    assert not np.allclose(gravity(locked), gravity(at_zero))


def test_html_with_a_mesh_that_cannot_be_loaded_is_refused_before_planning(
    tmp_path: Path,
) -> None:
    """--html needs the URDF's visuals: a mesh file that is not there is named before any
    planning (it was named after the plan, which was lost; a fuzz pass's note)."""
    path = write_urdf(tmp_path)
    visual = '<visual><geometry><mesh filename="meshes/none.stl"/></geometry></visual>'
    head, tail = path.read_text().split('<link name="b">', 1)
    path.write_text(f'{head}<link name="b">{visual}{tail}')
    done = run_cli("plan", "--urdf", str(path), *ONE_RAD[2:], "--html", str(tmp_path / "a.html"))
    assert done.returncode != 0
    assert "cannot load the visuals" in done.stderr and "none.stl" in done.stderr, done.stderr
    assert "iteration" not in done.stdout and "converged" not in done.stdout, done.stdout
    assert not (tmp_path / "a.html").exists()
