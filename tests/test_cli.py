"""The ``nearopt`` command line: JSON output checked against the robot, one-line errors."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from checks import torques_from_samples, worst_torque_excess
from conftest import load
from console import run_cli
from urdfs import erd_urdf

import nearopt

PAPER = ["--robot", "two_link", "--q0", "45", "-90", "--qe", "-90", "0", "--deg"]


def run(*args: str) -> subprocess.CompletedProcess[str]:
    """The console script as a user runs it (the module's entry point, in a subprocess): for
    what is about the process (exit codes, the entry point); the rest runs ``main`` in this
    process (:func:`console.run_cli`)."""
    return subprocess.run(
        [sys.executable, "-m", "nearopt.cli", *args], capture_output=True, text=True, timeout=600
    )


@pytest.mark.parametrize("mode", [[], ["--stage1-only"]], ids=["plan", "stage1-only"])
def test_plan_writes_the_documented_json(tmp_path: Path, mode: list[str]) -> None:
    target = tmp_path / "plan.json"
    table = tmp_path / "plan.csv"
    done = run_cli(
        "plan",
        *PAPER,
        "--beta",
        "0.03",
        "--grid",
        "100",
        "--max-iterations",
        "20",
        "--quiet",
        "--json",
        str(target),
        "--csv",
        str(table),
        "--rate",
        "500",
        *mode,
    )
    assert done.returncode == 0, done.stderr
    doc = json.loads(target.read_text())
    assert set(doc) == {
        "robot",
        "joint_names",
        "cost",
        "J",
        "duration",
        "t",
        "q",
        "qd",
        "qdd",
        "tau",
        "history",
    }
    assert doc["robot"] == "two_link" and doc["joint_names"] == ["joint1", "joint2"]
    t = np.array(doc["t"])
    # 500 Hz from 0 to te inclusive
    assert t[0] == 0.0 and t[-1] == pytest.approx(doc["duration"], abs=1e-12)
    np.testing.assert_allclose(np.diff(t[:-1]), 1 / 500, rtol=1e-9)
    assert t[-1] - t[-2] <= 1 / 500 + 1e-12
    q, qd, qdd, tau = (np.array(doc[k]) for k in ("q", "qd", "qdd", "tau"))
    assert q.shape == qd.shape == qdd.shape == tau.shape == (t.size, 2)
    np.testing.assert_allclose(q[0], np.deg2rad([45, -90]), atol=1e-12)
    np.testing.assert_allclose(q[-1], np.deg2rad([-90, 0]), atol=1e-8)
    # the torques in the file are those of the motion in the file, and within the limits
    robot = load("two_link")
    u = torques_from_samples(robot, q, qd, qdd)
    np.testing.assert_allclose(tau, u, atol=1e-9)
    assert worst_torque_excess(robot, tau) <= 1e-6
    history = doc["history"]
    assert history[0]["alpha"] is None and history[-1]["J"] <= history[0]["J"]
    assert (len(history) == 1) == bool(mode)
    # the CSV holds the same samples, with a header row
    header, *rows = table.read_text().splitlines()
    assert header.split(",") == ["t"] + [
        f"{k}_joint{i}" for k in ("q", "qd", "qdd", "tau") for i in (1, 2)
    ]
    values = np.array([[float(x) for x in row.split(",")] for row in rows])
    np.testing.assert_array_equal(values, np.column_stack([t, q, qd, qdd, tau]))


def test_plots_and_html_are_written(tmp_path: Path) -> None:
    done = run_cli(
        "plan",
        *PAPER,
        "--beta",
        "0.03",
        "--grid",
        "40",
        "--max-iterations",
        "3",
        "--quiet",
        "--plots",
        str(tmp_path / "figures"),
        "--html",
        str(tmp_path / "a.html"),
    )
    assert done.returncode == 0, done.stderr
    assert sorted(p.name for p in (tmp_path / "figures").iterdir()) == [
        "history.png",
        "speeds.png",
        "torques.png",
        "workspace.png",
    ]
    assert "MeshCat.Viewer" in (tmp_path / "a.html").read_text()


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["--robot", "nope", "--q0", "0", "--qe", "1"], "known robots: two_link"),
        (["--robot", "two_link", "--q0", "0", "--qe", "1", "1"], "q0 must have 2 values"),
        (["--robot", "two_link", "--q0", "0", "0", "--qe", "nan", "1"], "is nan"),
        (["--robot", "two_link", "--q0", "0", "0", "--qe", "0", "0"], "zero-length"),
        (["--robot", "two_link", "--q0", "0", "0", "--qe", "1", "1", "--beta", "-1"], "beta"),
        (["--robot", "two_link", "--q0", "0", "0", "--qe", "1", "1", "--rate", "0"], "--rate"),
        (
            [
                "--robot",
                "two_link",
                "--q0",
                "0",
                "0",
                "--qe",
                "1",
                "1",
                "--json",
                "/nonexistent/x.json",
            ],
            "does not exist",
        ),
        (["--urdf", "/nonexistent.urdf", "--q0", "0", "--qe", "1"], "not found"),
        (
            [
                "--robot",
                "two_link",
                "--q0",
                "0",
                "0",
                "--qe",
                "1",
                "1",
                "--beta",
                "1",
                "--time-optimal",
            ],
            "not allowed with",
        ),
        (["--q0", "0", "--qe", "1"], "one of the arguments --robot --urdf is required"),
        (
            [
                "--robot",
                "two_link",
                "--q0",
                "0",
                "0",
                "--qe",
                "1",
                "1",
                "--plots",
                "/nonexistent/figures",
            ],
            "does not exist",
        ),
        (
            ["--robot", "two_link", "--q0", "0", "0", "--qe", "1", "1", "--csv", "/"],
            "is a directory",
        ),
    ],
)
def test_bad_arguments_give_one_line_and_exit_code_2(args: list[str], expected: str) -> None:
    done = run("plan", *args)
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("nearopt: error: "), done.stderr
    assert expected in lines[0]
    assert done.stdout == ""


def test_robots_lists_the_known_arms() -> None:
    done = run("robots")
    assert done.returncode == 0
    assert done.stdout.split() == ["two_link", "kinova", "panda", "so101", "ur5", "xarm7", "z1"]


def test_console_script_is_installed() -> None:
    from importlib.metadata import entry_points

    (script,) = entry_points(group="console_scripts", name="nearopt")
    assert script.value == "nearopt.cli:main"


def replay_defects(
    robot, t: np.ndarray, q: np.ndarray, qd: np.ndarray, tau: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Each sample period replayed: from the sampled state, the sampled torques (linear in between)
    integrated with ABA (RK4, 8 steps); the largest position and speed defects at the next sample
    per period, each (M − 1,)."""
    import pinocchio as pin

    model, data, n = robot.model, robot.model.createData(), robot.n

    def f(x: np.ndarray, u: np.ndarray) -> np.ndarray:
        qdd = pin.aba(model, data, x[:n], x[n:], u - robot.damping * x[n:])
        return np.concatenate([x[n:], qdd])

    dq, dv = np.zeros(t.size - 1), np.zeros(t.size - 1)
    for k in range(t.size - 1):
        x, h = np.concatenate([q[k], qd[k]]), (t[k + 1] - t[k]) / 8
        for m in range(8):
            ua, ub = (tau[k] + (tau[k + 1] - tau[k]) * j / 8 for j in (m, m + 1))
            k1 = f(x, ua)
            k2 = f(x + h / 2 * k1, (ua + ub) / 2)
            k3 = f(x + h / 2 * k2, (ua + ub) / 2)
            k4 = f(x + h * k3, ub)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        dq[k], dv[k] = np.max(np.abs(x[:n] - q[k + 1])), np.max(np.abs(x[n:] - qd[k + 1]))
    return dq, dv


@pytest.mark.parametrize("name", ["ur5", "panda", "so101"])
def test_acceleration_limits_make_the_1khz_record_faithful(tmp_path: Path, name: str) -> None:
    """With --acceleration-limit A, every sample has |qdd| ≤ A and the 1 kHz record replays
    itself: θ̈ stays within ±A between samples, so the torques linear between two samples take
    the arm from one sampled state to the next within the bounds that implies (speed A·h/2,
    position A·h²/2 with h = 1 ms); without the limit so101's record does not."""
    robot = load(name)
    lo = np.maximum(robot.limits.position_lower, -np.pi)
    hi = np.minimum(robot.limits.position_upper, np.pi)
    ends = ["--q0", *map(str, lo + 0.3 * (hi - lo)), "--qe", *map(str, lo + 0.7 * (hi - lo))]
    limit, h = 10.0, 1e-3
    for extra in (["--acceleration-limit", str(limit)], []):
        target = tmp_path / "plan.json"
        done = run_cli(
            "plan",
            "--robot",
            name,
            *ends,
            "--max-iterations",
            "5",
            "--quiet",
            "--json",
            str(target),
            *extra,
        )
        assert done.returncode == 0, done.stderr
        doc = json.loads(target.read_text())
        t, q, qd, qdd, tau = (np.array(doc[k]) for k in ("t", "q", "qd", "qdd", "tau"))
        dq, dv = replay_defects(load(name), t, q, qd, tau)
        if extra:
            assert np.max(np.abs(qdd)) <= limit * (1 + 1e-9)
            assert np.max(dv) <= limit * h / 2 and np.max(dq) <= limit * h**2 / 2, (dq, dv)
            assert "warning" not in done.stderr
        elif name == "so101":  # bang phases shorter than a sample: the record misses them
            assert np.max(dv) > 10 * limit * h / 2
            assert "shorter than one sample period" in done.stderr


SHIPPED = {  # URDFs of example-robot-data as users have them, the options they need, and the
    # motion as fractions of every joint's range (talos: gravity alone exceeds its shoulder's
    # effort limit with the arm held out sideways, so its motion stays low)
    "talos_left_arm": ("talos_data/robots/talos_left_arm.urdf", [], (0.1, 0.4)),
    "so100": ("so_arm_description/urdf/so100.urdf", [], (0.3, 0.7)),
    "double_pendulum": (
        "double_pendulum_description/urdf/double_pendulum.urdf",
        ["--effort-limit", "2"],
        (0.3, 0.7),
    ),
    "tiago_arm": ("tiago_description/robots/tiago.urdf", ["--tip", "arm_7_link"], (0.3, 0.7)),
}


@pytest.mark.parametrize("name", list(SHIPPED))
def test_shipped_urdfs_plan_from_the_command_line(tmp_path: Path, name: str) -> None:
    """A URDF as shipped (and the option it needs) plans between two fractions of every joint's
    range; the JSON's torques, recomputed by RNEA from its samples, meet the robot's limits."""
    relative, options, (start, end) = SHIPPED[name]
    path = erd_urdf(relative)
    robot = nearopt.Robot.from_urdf(
        path,
        effort_limit=2.0 if "--effort-limit" in options else None,
        tip="arm_7_link" if "--tip" in options else None,
    )
    lo = np.maximum(robot.limits.position_lower, -np.pi)
    hi = np.minimum(robot.limits.position_upper, np.pi)
    q0, qe = lo + start * (hi - lo), lo + end * (hi - lo)
    target = tmp_path / "plan.json"
    done = run_cli(
        "plan",
        "--urdf",
        str(path),
        *options,
        "--q0",
        *map(str, q0),
        "--qe",
        *map(str, qe),
        "--max-iterations",
        "4",
        "--quiet",
        "--json",
        str(target),
    )
    assert done.returncode == 0, done.stderr
    doc = json.loads(target.read_text())
    assert doc["joint_names"] == list(robot.joint_names)
    q, qd, qdd = (np.array(doc[k]) for k in ("q", "qd", "qdd"))
    np.testing.assert_allclose(q[0], q0, atol=1e-9)
    np.testing.assert_allclose(q[-1], qe, atol=1e-6)
    np.testing.assert_allclose(np.abs(qd[[0, -1]]), 0.0, atol=1e-6)
    tau = torques_from_samples(robot, q, qd, qdd)
    scale = np.max(robot.limits.effort_upper)
    np.testing.assert_allclose(tau, np.array(doc["tau"]), atol=1e-6 * scale)
    assert worst_torque_excess(robot, tau) <= 1e-6
    assert np.all(np.abs(qd) <= robot.limits.velocity * (1 + 1e-9))


def test_a_motion_too_long_to_record_is_refused_in_bounded_memory(tmp_path: Path) -> None:
    """A 2000 s motion (acceleration limit 1e-6 rad/s²) asked for at 1 kHz: 18 million numbers
    would be sampled (a 6798 s one took 24 GB before it was killed). The command refuses the
    record in one line naming the highest rate that fits, writes nothing, and its address
    space never grows by 2 GB over a process that has loaded nearopt."""
    script = textwrap.dedent(
        f"""
        import os, resource, sys
        import nearopt.cli
        used = int(open("/proc/self/statm").read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
        resource.setrlimit(resource.RLIMIT_AS, (used + 2 * 2**30, resource.RLIM_INFINITY))
        sys.exit(nearopt.cli.main(["plan", "--robot", "two_link", "--q0", "0", "0", "--qe", "1",
                                   "1", "--acceleration-limit", "1e-6", "--json",
                                   {str(tmp_path / "long.json")!r}]))
        """
    )
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 2, done.stderr[-2000:]
    line = done.stderr.strip().splitlines()
    assert len(line) == 1 and "ask for a rate of at most 555.6 Hz (--rate)" in line[0], line
    assert "2,000,002 samples" in line[0]
    assert not (tmp_path / "long.json").exists()


PAPER_ARGS = ["--robot", "two_link", "--q0", "45", "-90", "--qe", "-90", "0", "--deg"]


def test_a_record_to_the_standard_output_is_all_it_carries(tmp_path: Path) -> None:
    """``--json /dev/stdout | consumer``: the progress and "wrote" lines go to stderr whenever
    an output is the standard output (by ``-`` or by any path to it), so the consumer reads the
    JSON alone."""
    for target in ("/dev/stdout", "-"):
        done = run("plan", *PAPER_ARGS, "--max-iterations", "2", "--json", target)
        assert done.returncode == 0, done.stderr
        document = json.loads(done.stdout)
        assert document["robot"] == "two_link" and len(document["t"]) > 100
        assert "iteration" in done.stderr and "wrote" in done.stderr


def test_a_reader_that_goes_away_ends_quietly(tmp_path: Path) -> None:
    """``nearopt plan … | head -1``: the lines after the first are dropped, the plan's file is
    still written, exit 0 and no "Broken pipe"; a record to a pipe closed before it was read
    ends quietly: 141 (128 + SIGPIPE, as POSIX tools do) when the write saw the pipe closed,
    0 when the pipe took it all first; the other outputs are written all the same."""
    command = f"{sys.executable} -m nearopt.cli"
    out = tmp_path / "plan.json"
    script = (
        f"{command} plan {' '.join(PAPER_ARGS)} --max-iterations 3 --json {out} | head -1; "
        f"echo status ${{PIPESTATUS[0]}}; "
        f"{command} plan {' '.join(PAPER_ARGS)} --quiet --max-iterations 1 --rate 10000 "
        "--json - | head -c 10; echo; echo status ${PIPESTATUS[0]}; "
        f"{command} plan {' '.join(PAPER_ARGS)} --quiet --max-iterations 1 --rate 10000 "
        f"--json - --csv {tmp_path / 'kept.csv'} | true; echo status ${{PIPESTATUS[0]}}"
    )
    done = subprocess.run(
        ["bash", "-c", script], capture_output=True, text=True, timeout=600, cwd=tmp_path
    )
    statuses = [line.split()[1] for line in done.stdout.splitlines() if line.startswith("status")]
    assert statuses[0] == "0" and statuses[1] in ("0", "141"), (done.stdout, done.stderr)
    assert statuses[2] == "141", (done.stdout, done.stderr)  # 300 kB into a closed pipe
    assert (tmp_path / "kept.csv").read_text().startswith("t,")  # the files are still written
    assert "Broken pipe" not in done.stderr and "Traceback" not in done.stderr, done.stderr
    assert json.loads(out.read_text())["robot"] == "two_link"


def test_the_summary_names_where_the_first_path_came_from(tmp_path: Path) -> None:
    """A plan with via-points and no scene starts from a path through them, not from OMPL."""
    done = run_cli("plan", *PAPER_ARGS, "--via", "0", "-45", "--max-iterations", "1", "--quiet")
    assert done.returncode == 0, done.stderr
    assert "(first path, through the via-points" in done.stdout, done.stdout
    assert "OMPL" not in done.stdout
    # with a scene the via path is clear of: the same first path (OMPL only where it collides)
    scene = tmp_path / "scene.toml"
    scene.write_text('[[obstacle]]\nname = "box"\nbox = [0.1, 0.1, 0.1]\nposition = [5, 5, 5]\n')
    done = run_cli(
        "plan", *PAPER_ARGS, "--via", "0", "-45", "--scene", str(scene), "--max-iterations", "1"
    )
    assert done.returncode == 0, done.stderr
    assert "(first path, through the via-points" in done.stdout, done.stdout
    assert "OMPL" not in done.stdout
