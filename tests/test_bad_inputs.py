"""Every kind of bad request, answered by a specific nearopt exception (Python) and by one line on
stderr with a non-zero exit code and no output file (CLI) — never a traceback, never a silent plan.
"""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from conftest import load
from urdfs import write_urdf

import nearopt
from nearopt import (
    ConfigurationError,
    InfeasiblePathError,
    NearoptError,
    RobotNotFoundError,
    URDFError,
)
from nearopt.export import write_json

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


def two_link() -> nearopt.Robot:
    return load("two_link")


def plan(q0: object, qe: object, cost: nearopt.Cost | None = None, **kw: object) -> object:
    return nearopt.plan(two_link(), q0, qe, cost, grid=20, max_iterations=2, **kw)


GOOD = (np.deg2rad([45.0, -90.0]), np.deg2rad([-90.0, 0.0]))

CASES = {
    "missing URDF": Case(
        lambda p: nearopt.Robot.from_urdf(p / "nope.urdf"),
        lambda p: ["--urdf", str(p / "nope.urdf"), "--q0", "0", "0", "--qe", "1", "1"],
        URDFError, "not found"),
    "unreadable URDF (a folder)": Case(
        lambda p: nearopt.Robot.from_urdf(p),
        lambda p: ["--urdf", str(p), "--q0", "0", "0", "--qe", "1", "1"],
        URDFError, "is a directory"),
    "malformed URDF": Case(
        lambda p: nearopt.Robot.from_urdf(urdf(p, '<robot name="x"><link name="a">')),
        lambda p: ["--urdf", str(urdf(p, "<robot")), "--q0", "0", "--qe", "1"],
        URDFError, "malformed"),
    "URDF without inertias": Case(
        lambda p: nearopt.Robot.from_urdf(write_urdf(p, inertial=False)),
        lambda p: ["--urdf", str(write_urdf(p, inertial=False)), "--q0", "0", "0", "--qe", "1",
                   "1"],
        URDFError, "inertia"),
    "URDF without effort limits": Case(
        lambda p: nearopt.Robot.from_urdf(write_urdf(p, limits=('<limit velocity="1"/>',) * 2)),
        lambda p: ["--urdf", str(write_urdf(p, limits=('<limit velocity="1"/>',) * 2)), "--q0",
                   "0", "0", "--qe", "1", "1"],
        URDFError, "effort"),
    "floating base": Case(
        lambda p: nearopt.Robot.from_urdf(write_urdf(p, types=("floating", "revolute"))),
        lambda p: ["--urdf", str(write_urdf(p, types=("floating", "revolute"))), "--q0", "0",
                   "--qe", "1"],
        URDFError, "floating"),
    "mimic joint": Case(
        lambda p: nearopt.Robot.from_urdf(write_urdf(p, extra=("", '<mimic joint="j1"/>'))),
        lambda p: ["--urdf", str(write_urdf(p, extra=("", '<mimic joint="j1"/>'))), "--q0", "0",
                   "0", "--qe", "1", "1"],
        URDFError, "mimic"),
    "unknown robot name": Case(
        lambda p: nearopt.Robot.from_name("ur10"),
        lambda p: ["--robot", "ur10", *PAPER],
        RobotNotFoundError, "known robots: two_link, kinova, panda, so101, ur5, xarm7, z1"),
    "q0 of the wrong length": Case(
        lambda p: plan([0.1], GOOD[1]),
        lambda p: ["--robot", "two_link", "--q0", "0.1", "--qe", "1", "1"],
        ConfigurationError, "q0 must have 2 values"),
    "qe of the wrong length": Case(
        lambda p: plan(GOOD[0], [1, 2, 3]),
        lambda p: ["--robot", "two_link", "--q0", "0", "0", "--qe", "1", "2", "3"],
        ConfigurationError, "qe must have 2 values"),
    "NaN in q0": Case(
        lambda p: plan([np.nan, 0.0], GOOD[1]),
        lambda p: ["--robot", "two_link", "--q0", "nan", "0", "--qe", "1", "1"],
        ConfigurationError, "q0 of joint 'joint1' is nan"),
    "inf in qe": Case(
        lambda p: plan(GOOD[0], [0.0, np.inf]),
        lambda p: ["--robot", "two_link", "--q0", "0", "0", "--qe", "0", "inf"],
        ConfigurationError, "qe of joint 'joint2' is inf"),
    "qe outside the position limits": Case(
        lambda p: nearopt.plan(load("panda"), [0, 0, 0, -1, 0, 1, 0], [0, 0, 0, -1, 0, 1, 3.5]),
        lambda p: ["--robot", "panda", "--q0", "0", "0", "0", "-1", "0", "1", "0", "--qe", "0",
                   "0", "0", "-1", "0", "1", "3.5"],
        ConfigurationError, "qe[6] = 3.5 rad is outside the position limits"),
    "q0 == qe (zero-length motion)": Case(
        lambda p: plan(GOOD[0], GOOD[0]),
        lambda p: ["--robot", "two_link", "--q0", "45", "-90", "--qe", "45", "-90", "--deg"],
        ConfigurationError, "zero-length"),
    "negative beta": Case(
        lambda p: nearopt.TorqueCost(-0.03),
        lambda p: ["--robot", "two_link", *PAPER, "--beta", "-0.03"],
        ConfigurationError, "beta must be finite and ≥ 0"),
    "NaN beta": Case(
        lambda p: nearopt.TorqueCost(float("nan")),
        lambda p: ["--robot", "two_link", *PAPER, "--beta", "nan"],
        ConfigurationError, "beta must be finite and ≥ 0"),
    "negative weight": Case(
        lambda p: nearopt.TorqueCost(weights=[0.1, -0.1]),
        lambda p: ["--robot", "two_link", *PAPER, "--weights", "0.1", "-0.1"],
        ConfigurationError, "weights must be finite and ≥ 0"),
    "weights of the wrong length": Case(
        lambda p: plan(*GOOD, nearopt.TorqueCost(weights=[0.1, 0.1, 0.1])),
        lambda p: ["--robot", "two_link", *PAPER, "--weights", "0.1", "0.1", "0.1"],
        ConfigurationError, "weight"),
    "rate <= 0": Case(
        lambda p: nearopt.optimal_timing(two_link(), nearopt.StraightPath(*GOOD)).trajectory
        .sample(0.0),
        lambda p: ["--robot", "two_link", *PAPER, "--rate", "-5", "--json", str(p / "a.json")],
        ConfigurationError, "rate"),
    "unwritable output path": Case(
        lambda p: write_json(plan(*GOOD), p / "missing" / "plan.json"),
        lambda p: ["--robot", "two_link", *PAPER, "--json", str(p / "missing" / "plan.json")],
        ConfigurationError, "does not exist"),
    "output path is a folder": Case(
        lambda p: write_json(plan(*GOOD), p),
        lambda p: ["--robot", "two_link", *PAPER, "--csv", str(p)],
        ConfigurationError, "is a directory"),
    "gravity beyond the limit at θ0": Case(
        lambda p: nearopt.plan(nearopt.Robot.from_urdf(write_urdf(p, limits=(WEAK, WEAK))),
                               [1.5, 0.0], [0.0, 0.0]),
        lambda p: ["--urdf", str(write_urdf(p, limits=(WEAK, WEAK))), "--q0", "1.5", "0",
                   "--qe", "0", "0"],
        InfeasiblePathError, "joint 'j1'"),
    "gravity beyond the limit at θe": Case(
        lambda p: nearopt.plan(two_link().with_limits(effort=[3.0, 5.0]), *GOOD),
        None,  # the CLI takes the URDF's limits; the same check as the previous case
        InfeasiblePathError, "joint 'joint1', beyond its upper limit 3"),
    "cost callable that raises": Case(
        lambda p: plan(*GOOD, nearopt.CallableCost(lambda q, qd, u: 1 / 0)),
        None,  # the CLI has no user callables
        NearoptError, "raised ZeroDivisionError"),
    "cost callable that returns NaN": Case(
        lambda p: plan(*GOOD, nearopt.CallableCost(lambda q, qd, u: np.full(len(q), np.nan))),
        None,
        NearoptError, "returned nan"),
    "unknown planning method": Case(
        lambda p: plan(*GOOD, method="newton"),
        lambda p: ["--robot", "two_link", *PAPER, "--method", "newton"],
        ConfigurationError, "method"),
    "--lock with a named robot": Case(
        None,
        lambda p: ["--robot", "two_link", *PAPER, "--lock", "joint1"],
        ConfigurationError, "--lock applies to --urdf"),
    "one weight for a two-joint arm (CLI)": Case(
        None,
        lambda p: ["--robot", "two_link", *PAPER, "--weights", "0.1"],
        ConfigurationError, "one weight per joint"),
    "a later output fails after an earlier one could be written": Case(
        None,
        lambda p: ["--robot", "two_link", *PAPER, "--grid", "20", "--max-iterations", "2",
                   "--json", str(p / "a.json"), "--plots", "/proc"],
        ConfigurationError, "cannot write /proc"),
    "grid too small": Case(
        lambda p: nearopt.plan(two_link(), *GOOD, grid=1),
        lambda p: ["--robot", "two_link", *PAPER, "--grid", "1"],
        ConfigurationError, "grid must be an integer ≥ 2"),
}


def test_the_table_covers_at_least_twenty_kinds() -> None:
    assert len(CASES) >= 20


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
    done = subprocess.run([sys.executable, "-m", "nearopt.cli", "plan", *args],
                          capture_output=True, text=True, timeout=300, cwd=work)
    assert done.returncode != 0
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("nearopt: error: "), done.stderr
    assert case.says in lines[0], lines[0]
    assert sorted(work.rglob("*")) == before  # no output file, not even a partial one
