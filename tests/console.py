"""The ``nearopt`` command in this process: ``nearopt.cli.main`` with its standard streams
captured, for the tests whose subject is what the command does, not the console script itself
(signals, exit codes of the process and streams keep their subprocess tests)."""

from __future__ import annotations

import contextlib
import io
import os
import signal
import subprocess
from pathlib import Path

from nearopt.cli import main


def run_cli(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    """``nearopt ARGS`` as ``main`` runs it: exit code, stdout and stderr as text (the shape of
    ``subprocess.run(..., capture_output=True, text=True)``). The working folder and the SIGINT
    handler are restored afterwards."""
    out, err = io.StringIO(), io.StringIO()
    handler = signal.getsignal(signal.SIGINT)
    here = os.getcwd()
    try:
        if cwd is not None:
            os.chdir(cwd)
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main(list(args))
            except SystemExit as exc:
                code = exc.code if isinstance(exc.code, int) else 1
    finally:
        os.chdir(here)
        signal.signal(signal.SIGINT, handler)
    return subprocess.CompletedProcess(["nearopt", *args], code, out.getvalue(), err.getvalue())
