"""The installable distribution (#27): ``python -m build`` makes an sdist and a wheel that carry
the bundled robots and every data file, and a new virtual environment that installs only the
wheel (its dependencies seen from this one's site-packages, where a path in a .pth file does not
run this checkout's editable hook) lists the robots, plans the paper's example and writes its
animation — from the installed copy, not from this checkout. The compiled kernels run as plain
Python there (``NUMBA_DISABLE_JIT=1``): compiling them afresh for the new location took 30 s of
the test's 68, and the same sources are compiled by every other test."""

from __future__ import annotations

import os
import subprocess
import sys
import sysconfig
import tarfile
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAPER = ["--robot", "two_link", "--q0", "45", "-90", "--qe", "-90", "0", "--deg"]


def _run(
    *args: str | Path, cwd: Path | None = None, env: dict[str, str] | None = None
) -> subprocess.CompletedProcess[str]:
    done = subprocess.run(
        [str(a) for a in args], capture_output=True, text=True, timeout=900, cwd=cwd, env=env
    )
    assert done.returncode == 0, f"{args}: {done.stdout[-2000:]}\n{done.stderr[-2000:]}"
    return done


@pytest.mark.slow
def test_the_wheel_installs_and_plans_in_a_new_environment(tmp_path: Path) -> None:
    pytest.importorskip("build")
    dist = tmp_path / "dist"
    _run(sys.executable, "-m", "build", "--sdist", "--wheel", "--outdir", dist, ROOT)
    (wheel,) = dist.glob("nearopt-*.whl")
    (sdist,) = dist.glob("nearopt-*.tar.gz")
    robots = sorted(p.name for p in (ROOT / "robots").glob("*.urdf"))
    assert robots
    with zipfile.ZipFile(wheel) as archive:
        names = set(archive.namelist())
        entry = next(n for n in names if n.endswith("entry_points.txt"))
        assert "nearopt = nearopt.cli:main" in archive.read(entry).decode()
    for name in robots:
        assert f"nearopt/bundled_robots/{name}" in names
    modules = {str(p.relative_to(ROOT)) for p in (ROOT / "nearopt").rglob("*.py")}
    assert modules <= names  # every module, the compiled kernels' sources too
    assert "nearopt/py.typed" in names
    with tarfile.open(sdist) as archive:
        packed = {name.split("/", 1)[1] for name in archive.getnames() if "/" in name}
    assert {f"robots/{name}" for name in robots} | {"pyproject.toml", "README.md"} <= packed

    env = tmp_path / "env"
    _run(sys.executable, "-m", "venv", "--without-pip", env)
    python = env / "bin" / "python"
    _run(sys.executable, "-m", "pip", "--python", python, "install", "-q", "--no-deps", wheel)
    site = Path(_run(python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])")
                .stdout.strip())  # fmt: skip
    ours = sorted({sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]})
    (site / "0-dependencies.pth").write_text("\n".join(ours) + "\n")  # first, then theirs:
    for folder in ours:  # (cmeel's, for pin and coal) but this checkout's editable hook
        for hook in Path(folder).glob("*.pth"):
            if not hook.name.startswith("__editable__"):
                (site / hook.name).write_text(hook.read_text())
    where = _run(python, "-c", "import nearopt; print(nearopt.__file__)", cwd=tmp_path)
    where = where.stdout.strip()
    assert Path(where).is_relative_to(env), where
    listed = _run(env / "bin" / "nearopt", "robots", cwd=tmp_path).stdout
    assert "two_link" in listed
    work = tmp_path / "work"
    work.mkdir()
    planned = _run(
        env / "bin" / "nearopt", "plan", *PAPER, "--max-iterations", "1", "--html", "paper.html",
        "--json", "paper.json", cwd=work, env={**os.environ, "NUMBA_DISABLE_JIT": "1"},
    )  # fmt: skip
    assert "wrote paper.html" in planned.stdout
    page = (work / "paper.html").read_text()
    assert "<html" in page.lower() and len(page) > 10_000
