"""Outputs that respect what is there: files replaced atomically, links followed, devices and FIFOs
written as streams, the standard output, and nothing destroyed or half-written on a failure —
as root and, where permissions matter, as an unprivileged user."""

from __future__ import annotations

import json
import os
import stat
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

import numpy as np
import pytest

import nearopt

STAGE1 = ["plan", "--robot", "two_link", "--q0", "0", "0", "--qe", "1", "1", "--stage1-only"]
ROOT = os.geteuid() == 0
NOBODY = 65534


def run(
    *args: str, user: int | None = None, cwd: Path | None = None, timeout: float = 300
) -> subprocess.CompletedProcess[bytes]:
    """The console script in a subprocess, optionally as another user (when run as root)."""
    return subprocess.run(
        [sys.executable, "-m", "nearopt.cli", *args],
        capture_output=True,
        timeout=timeout,
        cwd=cwd,
        user=user,
        group=user,
    )


def one_error_line(done: subprocess.CompletedProcess[bytes]) -> str:
    lines = done.stderr.decode().strip().splitlines()
    assert done.returncode == 2, done.stderr
    assert len(lines) == 1 and lines[0].startswith("nearopt: error: "), done.stderr
    return lines[0]


def test_a_symlink_is_followed_to_its_target(tmp_path: Path) -> None:
    target, link = tmp_path / "target.json", tmp_path / "link.json"
    target.write_text("old")
    link.symlink_to(target)
    done = run(*STAGE1, "--json", str(link), "--quiet")
    assert done.returncode == 0, done.stderr
    assert link.is_symlink() and os.readlink(link) == str(target)
    assert json.loads(target.read_text())["robot"] == "two_link"


def test_a_fifo_is_written_as_a_stream(tmp_path: Path) -> None:
    fifo = tmp_path / "plan.fifo"
    os.mkfifo(fifo)
    received: list[bytes] = []
    reader = threading.Thread(target=lambda: received.append(fifo.read_bytes()), daemon=True)
    reader.start()
    done = run(*STAGE1, "--json", str(fifo), "--quiet")
    reader.join(timeout=60)
    assert done.returncode == 0, done.stderr
    assert stat.S_ISFIFO(fifo.stat().st_mode)
    assert json.loads(received[0])["joint_names"] == ["joint1", "joint2"]


def test_standard_output_carries_the_file_and_nothing_else() -> None:
    done = run(*STAGE1, "--json", "-")
    assert done.returncode == 0, done.stderr
    doc = json.loads(done.stdout)  # the whole of stdout is the JSON
    assert len(doc["t"]) == len(doc["q"]) and doc["J"] > 0
    assert b"iteration limit" in done.stderr  # the summary went to stderr


@pytest.mark.skipif(not ROOT, reason="as root a device node could be replaced by a file")
def test_devices_stay_devices() -> None:
    assert run(*STAGE1, "--csv", "/dev/null", "--quiet").returncode == 0
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode)
    line = one_error_line(run(*STAGE1, "--json", "/dev/full", "--quiet"))
    assert "cannot write /dev/full: No space left on device" in line
    assert stat.S_ISCHR(os.stat("/dev/full").st_mode)


@pytest.mark.parametrize(
    ("outputs", "says"),
    [
        (["--json", "{p}/same", "--csv", "{p}/same"], "--json and --csv would both write"),
        (["--json", "-", "--csv", "/dev/stdout"], "--json and --csv would both write"),
        (["--json", "{p}/link-to-same", "--csv", "{p}/same"], "would both write"),
        (["--plots", "{p}", "--json", "{p}/speeds.png"], "--json and --plots speeds.png"),
        (["--plots", "{p}", "--csv", "{p}/jerks.png"], "--csv and --plots jerks.png"),
    ],
    ids=["same path", "stdout twice", "a link to the other", "a figure", "a figure not drawn"],
)
def test_two_outputs_to_one_place_are_refused(
    tmp_path: Path, outputs: list[str], says: str
) -> None:
    (tmp_path / "same").write_text("keep")
    (tmp_path / "link-to-same").symlink_to(tmp_path / "same")
    done = run(*STAGE1, *(o.format(p=tmp_path) for o in outputs))
    assert says in one_error_line(done)
    assert (tmp_path / "same").read_text() == "keep"


def test_a_replaced_file_keeps_its_mode_and_a_failure_keeps_the_old_one(tmp_path: Path) -> None:
    plan = tmp_path / "plan.json"
    plan.write_text("old")
    plan.chmod(0o640)
    assert run(*STAGE1, "--json", str(plan), "--quiet").returncode == 0
    assert stat.S_IMODE(plan.stat().st_mode) == 0o640
    written = plan.read_text()
    # a later output that cannot be written: nothing changes, no temporary file is left
    done = run(*STAGE1, "--json", str(plan), "--csv", "/proc/nearopt.csv", "--quiet")
    one_error_line(done)
    assert plan.read_text() == written
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plan.json"]


def run_as_nobody(*args: str) -> tuple[int, str]:
    """The CLI's ``main`` in a forked child that has dropped root for the unprivileged user
    (the interpreter and nearopt are loaded before, so the checkout may live in a folder that
    user cannot read, such as mktemp's); its exit code and stderr."""
    from nearopt.cli import main
    from nearopt.timing import load_kernel

    load_kernel()  # stage 1's compiled kernel (numba) too: the child may not read its files
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:  # child
        code = 3
        try:
            os.close(read)
            sys.stderr = os.fdopen(write, "w")
            os.setgroups([])
            os.setgid(NOBODY)
            os.setuid(NOBODY)
            code = main(list(args))
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else 3
        finally:
            sys.stderr.flush()
            os._exit(code)
    os.close(write)
    with os.fdopen(read) as stream:
        stderr = stream.read()
    _, status = os.waitpid(pid, 0)
    return os.waitstatus_to_exitcode(status), stderr


@pytest.mark.skipif(not ROOT, reason="needs root to become another user")
def test_an_unprivileged_user_is_told_and_nothing_is_written() -> None:
    # a folder the user can read but not write, outside pytest's root-only tmp_path
    with tempfile.TemporaryDirectory(dir="/tmp") as name:
        folder = Path(name)
        folder.chmod(0o755)
        (folder / "theirs.json").write_text("root's")
        (folder / "theirs.json").chmod(0o644)
        # the arm from a file that user can read, wherever the checkout is
        urdf = folder / "two_link.urdf"
        urdf.write_text(nearopt.Robot.from_name("two_link").urdf_path.read_text())
        urdf.chmod(0o644)
        request = ["plan", "--urdf", str(urdf), *STAGE1[3:]]
        for target, says in (
            (folder / "new.json", "Permission denied"),
            (folder / "theirs.json", "permission denied"),
        ):
            code, stderr = run_as_nobody(*request, "--json", str(target))
            lines = stderr.strip().splitlines()
            assert code == 2 and len(lines) == 1, stderr
            assert lines[0].startswith("nearopt: error: ") and says in lines[0], stderr
        assert sorted(p.name for p in folder.iterdir()) == ["theirs.json", "two_link.urdf"]
        assert (folder / "theirs.json").read_text() == "root's"


@pytest.mark.skipif(not ROOT, reason="a pseudo file system refuses new files even to root")
def test_a_file_system_that_refuses_files_is_found_before_planning() -> None:
    done = run(*STAGE1, "--json", "/sys/nearopt.json")
    assert "cannot write /sys/nearopt.json" in one_error_line(done)
    assert done.stdout == b""  # refused before any planning


def test_python_writers_follow_links(tmp_path: Path) -> None:
    import nearopt
    from nearopt.export import write_csv

    robot = nearopt.Robot.from_name("two_link")
    result = nearopt.plan(robot, [0.0, 0.0], [1.0, 1.0], max_iterations=0)
    target, link = tmp_path / "target.csv", tmp_path / "link.csv"
    target.write_text("old")
    link.symlink_to(target)
    assert write_csv(result, link, rate=2000.0) == target  # faithful at 2 kHz: no warning
    rows = np.loadtxt(target, delimiter=",", skiprows=1)
    assert rows.shape[1] == 1 + 4 * robot.n and link.is_symlink()
