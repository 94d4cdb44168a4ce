"""The README's examples cannot drift: every Python block runs (each after the quick start, in a
fresh folder that sees the repository's scripts/), and every ``nearopt`` command line uses only
options the command knows — those without placeholders are run."""

from __future__ import annotations

import os
import re
import shlex
from pathlib import Path

import pytest
from console import run_cli

import nearopt.cli

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")
BLOCKS = re.findall(r"^```(\w*)\n(.*?)^```", README, flags=re.S | re.M)
PYTHON = [code for lang, code in BLOCKS if lang == "python"]
COMMANDS = [
    " ".join(line.split())
    for lang, code in BLOCKS
    if lang == "bash"
    for line in code.replace("\\\n", " ").splitlines()
    if line.split("#")[0].strip().startswith("nearopt ")
]
COMMANDS += re.findall(r"`(nearopt plan [^`]*)`", README)  # those in the text


def without_comment(line: str) -> str:
    return line.split("  #")[0].split(" # ")[0].strip()


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    """A fresh working folder that sees the repository's scripts/ (the task files)."""
    (tmp_path / "scripts").symlink_to(ROOT / "scripts")
    here = os.getcwd()
    os.chdir(tmp_path)
    yield tmp_path
    os.chdir(here)


def test_the_readme_has_examples() -> None:
    assert len(PYTHON) >= 6 and len(COMMANDS) >= 8


@pytest.mark.parametrize("k", range(len(PYTHON)))
def test_every_python_block_runs(k: int, folder: Path) -> None:
    namespace: dict[str, object] = {"__name__": "__main__"}
    if k:  # the other blocks continue the quick start (robot, q0, qe, cost, result)
        exec(compile(PYTHON[0], "README quick start", "exec"), namespace)  # noqa: S102
    exec(compile(PYTHON[k], f"README python block {k + 1}", "exec"), namespace)  # noqa: S102
    viewer = namespace.get("viewer")
    if viewer is not None:  # the live viewer's server
        viewer.close()


def known_options(command: str) -> set[str]:
    parser = nearopt.cli._parser()  # noqa: SLF001 - the command line's own parser
    sub = next(a for a in parser._actions if a.dest == "command")  # noqa: SLF001
    return {o for a in sub.choices[command]._actions for o in a.option_strings}  # noqa: SLF001


@pytest.mark.parametrize("line", COMMANDS)
def test_every_command_line_uses_known_options(line: str, folder: Path) -> None:
    words = shlex.split(without_comment(line).replace("[", "").replace("]", ""))
    command = words[1]
    if command == "robots":
        assert run_cli("robots").returncode == 0
        return
    unknown = {w for w in words if w.startswith("--")} - known_options(command)
    assert not unknown, f"{line}: unknown options {unknown}"
    placeholders = ("...", "…", "DIR", "my_arm", "HOST", "FILE", "pick.toml", "cell.toml", "jsonl")
    if command == "plan" and not any(p in line for p in placeholders):
        quick = ["--max-iterations", "2"] if "--task" not in words else ["--max-iterations", "1"]
        done = run_cli(*words[1:], *quick)
        assert done.returncode == 0, f"{line}: {done.stderr}"
