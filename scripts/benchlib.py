"""What the benchmark scripts share."""

from __future__ import annotations

import os
import subprocess
import sys
import tarfile
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np


def median_time(fn: Callable[[], Any], repeat: int) -> tuple[float, Any]:
    """Median wall time [s] of ``repeat`` calls of ``fn``, and the last call's result."""
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), out


ROOT = Path(__file__).resolve().parent.parent


def unpack(revision: str, folder: Path) -> Path:
    """``nearopt/`` of an earlier commit (``git archive``) in ``folder``; the folder to put first
    on PYTHONPATH."""
    archive = folder / "baseline.tar"
    with archive.open("wb") as out:
        subprocess.run(
            ["git", "-C", str(ROOT), "archive", revision, "nearopt"], stdout=out, check=True
        )
    with tarfile.open(archive) as tar:
        tar.extractall(folder / "src", filter="data")
    return folder / "src"


def run_with(source: Path, script: str, *args: str, timeout: float = 3600) -> str:
    """The standard output of a benchmark script run with the nearopt in ``source`` (first on
    PYTHONPATH; the same interpreter and packages), from the temporary folder."""
    done = subprocess.run(
        [sys.executable, script, *args],
        env=dict(os.environ, PYTHONPATH=str(source)),
        cwd=tempfile.gettempdir(),
        capture_output=True,
        text=True,
        timeout=timeout,
        check=True,
    )
    return done.stdout


def head() -> str:
    """This checkout's commit, abbreviated."""
    done = subprocess.run(
        ["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    )
    return done.stdout.strip()
