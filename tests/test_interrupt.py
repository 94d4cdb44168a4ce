"""Ctrl-C: the first one ends planning with the best plan so far, verified and written (exit code
130); a second one aborts at once and writes nothing. In Python, a KeyboardInterrupt raised during
the iterations (here by the callback) returns the best plan with status ``INTERRUPTED``."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from checks import assert_independent_checks

import nearopt
from nearopt import cli
from nearopt.planning import Iteration, StopReason

PANDA = [
    "--robot",
    "panda",
    "--q0",
    "0",
    "-0.5",
    "0",
    "-2",
    "0",
    "1.5",
    "0.8",
    "--qe",
    "1.2",
    "0.3",
    "0.5",
    "-1.2",
    "0.4",
    "2.2",
    "-0.3",
]


def interrupted_cli(*args: str, second_after: float | None = None) -> tuple[int, list[str], str]:
    """Run ``nearopt plan``; send SIGINT when iteration 1 is printed and, if ``second_after`` is
    given, again that many seconds after the status line. Exit code, stdout lines, stderr."""
    process = subprocess.Popen(
        [sys.executable, "-u", "-m", "nearopt.cli", "plan", *PANDA, *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    lines = []
    assert process.stdout is not None and process.stderr is not None
    for line in process.stdout:
        lines.append(line.rstrip("\n"))
        if line.startswith("iteration   1 "):
            process.send_signal(signal.SIGINT)
        elif line.startswith("interrupted:") and second_after is not None:
            time.sleep(second_after)
            process.send_signal(signal.SIGINT)
    code = process.wait(timeout=300)
    return code, lines, process.stderr.read()


def test_the_first_ctrl_c_writes_the_best_plan_so_far(tmp_path: Path) -> None:
    target = tmp_path / "plan.json"
    code, lines, stderr = interrupted_cli("--json", str(target))
    assert code == 130, stderr
    status = next(line for line in lines if line.startswith("interrupted:"))
    assert f"wrote {target}" in lines
    iterations = [line for line in lines if line.startswith("iteration")]
    assert len(iterations) >= 2  # stopped early, after an improvement was found
    data = json.loads(target.read_text())
    J_line = float(status.split("straight line ")[1].split(")")[0])
    assert data["J"] < J_line  # better than the straight line: the best so far, not the start
    robot = nearopt.Robot.from_name("panda")
    q = np.asarray(data["q"])
    np.testing.assert_allclose(q[0], [float(v) for v in PANDA[3:10]], atol=1e-9)
    np.testing.assert_allclose(q[-1], [float(v) for v in PANDA[11:18]], atol=1e-9)
    assert robot.n == q.shape[1]


def test_a_second_ctrl_c_aborts_and_writes_nothing(tmp_path: Path) -> None:
    # the status line is printed before verification, figures and the page are made (seconds)
    code, lines, stderr = interrupted_cli(
        "--json",
        str(tmp_path / "plan.json"),
        "--html",
        str(tmp_path / "plan.html"),
        "--plots",
        str(tmp_path / "figures"),
        second_after=0.3,
    )
    assert code == 130, stderr
    assert stderr.strip().splitlines() == [
        "nearopt: error: aborted by a second Ctrl-C; nothing written"
    ]
    assert not any(line.startswith("wrote") for line in lines)
    assert [p.name for p in tmp_path.rglob("*") if p.is_file()] == []


def test_a_keyboard_interrupt_in_python_returns_the_best_plan() -> None:
    robot = nearopt.Robot.from_name("panda")
    q0 = np.array([float(v) for v in PANDA[3:10]])
    qe = np.array([float(v) for v in PANDA[11:18]])
    seen: list[Iteration] = []

    def stop_at_two(entry: Iteration) -> None:
        seen.append(entry)
        if entry.index == 2:
            raise KeyboardInterrupt

    result = nearopt.plan(robot, q0, qe, nearopt.TimeCost(), callback=stop_at_two)
    assert result.status is StopReason.INTERRUPTED
    assert [entry.index for entry in seen] == [0, 1, 2]
    assert result.J < result.initial.J
    assert_independent_checks(robot, result.trajectory, nearopt.TimeCost(), result.J, q0, qe)


def test_a_second_ctrl_c_swallowed_by_a_library_still_aborts(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """The CI failure of stop 35: a Ctrl-C while the page was made, its abort caught by a library
    (trimesh catches BaseException) that then failed on half-made arrays (a ValueError, exit 1,
    a traceback). The failure after a second Ctrl-C is the abort."""
    import nearopt.viz.viewer as viewer

    def swallowing_page(result: object) -> str:
        try:
            signal.raise_signal(signal.SIGINT)  # the second Ctrl-C (planning has ended)
        except BaseException:  # noqa: BLE001 (as trimesh does)
            pass
        return str(np.hstack([np.zeros((3, 1)), np.zeros((4, 1))]))  # the half-made result

    monkeypatch.setattr(viewer, "plan_html", swallowing_page)
    assert_aborted_while_the_page_is_made(tmp_path, capsys)


def assert_aborted_while_the_page_is_made(
    folder: Path, capsys: pytest.CaptureFixture[str], *more: str
) -> None:
    """``nearopt plan`` (two_link, stage 1, a page and ``more`` outputs in ``folder``) ends
    with the second Ctrl-C's abort: exit code 130, its one line, nothing written."""
    before = signal.getsignal(signal.SIGINT)
    try:
        with pytest.raises(SystemExit) as ended:
            cli.main(
                ["plan", "--robot", "two_link", "--q0", "45", "-90", "--qe", "-90", "0", "--deg"]
                + ["--stage1-only", "--html", str(folder / "p.html"), *more]
            )
    finally:
        signal.signal(signal.SIGINT, before)
    assert ended.value.code == 130
    assert capsys.readouterr().err.strip() == (
        "nearopt: error: aborted by a second Ctrl-C; nothing written"
    )
    assert list(folder.iterdir()) == []


def test_a_second_ctrl_c_while_an_output_is_made_waits_for_that_step_then_aborts(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """The CI failure of 2026-12-05: a second Ctrl-C while the page was made landed in trimesh's
    import of a nanobind module, whose initialisation cannot pass a Python exception on: C++'s
    terminate, exit −6. While an output is made the abort waits for that step to end."""
    import nearopt.viz.viewer as viewer

    finished = []

    def page(result: object) -> str:
        signal.raise_signal(signal.SIGINT)  # the second Ctrl-C (planning has ended)
        finished.append(True)  # (an exception here would have ended an extension's import)
        return "<html></html>"

    monkeypatch.setattr(viewer, "plan_html", page)
    assert_aborted_while_the_page_is_made(tmp_path, capsys, "--json", str(tmp_path / "p.json"))
    assert finished == [True]


def test_a_ctrl_c_during_an_import_is_taken_when_it_ends(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The CLI's handler does not raise inside an import (a nanobind module's initialisation
    cannot pass the exception on: terminate) nor inside numba's unpickling of a constant (a
    SystemError instead of the interrupt): it takes the signal again a few ms later."""
    (tmp_path / "nearopt_ctrl_c_probe.py").write_text(
        "import signal\nsignal.raise_signal(signal.SIGINT)\nFINISHED = True\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "nearopt_ctrl_c_probe", raising=False)
    interrupt = cli._Interrupt()
    before = signal.getsignal(signal.SIGINT)
    imported = False
    start = time.perf_counter()
    try:
        with pytest.raises(KeyboardInterrupt), interrupt.armed():
            import nearopt_ctrl_c_probe  # noqa: F401 - the Ctrl-C arrives inside its import

            imported = nearopt_ctrl_c_probe.FINISHED
            time.sleep(2.0)  # the interrupt is taken here
    finally:
        signal.signal(signal.SIGINT, before)
        sys.modules.pop("nearopt_ctrl_c_probe", None)
    assert imported
    assert time.perf_counter() - start < 1.0
