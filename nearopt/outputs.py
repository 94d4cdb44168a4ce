"""Writing outputs without destroying what is there.

Every output path is resolved and checked before anything is computed (:func:`check_outputs`),
then written all or nothing (:func:`write_outputs`):

* a regular file (or a new one) is written to a temporary file in its folder and renamed over it,
  keeping the mode of a file it replaces — a failure leaves the old file as it was;
* a symbolic link is followed: its target is written (as above), the link stays;
* a character or block device, a FIFO or a socket (``/dev/null``, a named pipe, ``/dev/stdout``)
  is opened and written as a stream, never replaced;
* ``-`` is the standard output.

Two outputs to one place (after following links) are refused, and so is a folder, a missing
folder, a read-only file system or a place the user may not write.
"""

from __future__ import annotations

import contextlib
import os
import signal
import stat
import sys
import tempfile
import threading
from dataclasses import dataclass
from enum import Enum
from pathlib import Path
from typing import TYPE_CHECKING

from .errors import ConfigurationError

if TYPE_CHECKING:
    from collections.abc import Iterator

__all__ = [
    "OutputKind",
    "Output",
    "resolve_output",
    "check_outputs",
    "refuse_inputs",
    "is_standard_output",
    "ReaderTolerant",
    "quiet_standard_output",
    "write_outputs",
    "make_folder",
    "write_atomically",
]


class OutputKind(Enum):
    """How an output is written."""

    FILE = "file"
    """A regular file, written atomically (temporary file + rename)."""
    STREAM = "stream"
    """A device, FIFO or socket, opened and written in place."""
    STDOUT = "stdout"
    """The standard output (``-``)."""


@dataclass(frozen=True)
class Output:
    """A checked output place.

    Attributes
    ----------
    name
        The path as the user gave it (for messages).
    kind
        How it is written.
    path
        Where it is written: the link's target for a symbolic link; None for the standard output.
    identity
        (device, inode) of what is there already, or the resolved path of a new file: what two
        outputs to one place share.
    """

    name: str
    kind: OutputKind
    path: Path | None
    identity: object


def resolve_output(target: str | Path) -> Output:
    """Resolve and check one output place (see the module docstring).

    Raises
    ------
    ConfigurationError
        Naming the path and why it cannot be written.
    """
    name = str(target)
    if name == "":
        raise ConfigurationError("an output path is empty")
    if name == "-":
        info = os.fstat(sys.stdout.fileno())
        return Output(name, OutputKind.STDOUT, None, (info.st_dev, info.st_ino))
    given = Path(name).expanduser()
    if name.endswith(("/", os.sep)) and not given.is_dir():  # pathlib drops the slash
        raise ConfigurationError(
            f"cannot write {name}: it names a folder, which does not exist; give a file name"
        )
    try:
        info = given.stat()  # follows links
    except FileNotFoundError:
        info = None
    except OSError as exc:
        raise ConfigurationError(f"cannot write {name}: {exc.strerror or exc}") from None
    if info is not None and stat.S_ISDIR(info.st_mode):
        raise ConfigurationError(f"cannot write {name}: it is a directory")
    if info is not None and not stat.S_ISREG(info.st_mode):  # device, FIFO, socket
        if not os.access(given, os.W_OK):
            raise ConfigurationError(f"cannot write {name}: permission denied")
        return Output(name, OutputKind.STREAM, given, (info.st_dev, info.st_ino))
    path = Path(os.path.realpath(given))  # a link's target is what is replaced
    folder = path.parent
    if not folder.is_dir():
        raise ConfigurationError(f"cannot write {name}: folder {folder} does not exist")
    if info is not None and not os.access(path, os.W_OK):
        raise ConfigurationError(f"cannot write {name}: permission denied")
    _probe(folder, name)
    identity = (info.st_dev, info.st_ino) if info is not None else str(path)
    return Output(name, OutputKind.FILE, path, identity)


def _probe(folder: Path, name: str) -> None:
    """Create and remove a file in ``folder``: what a read-only file system, a pseudo file system
    or missing permissions refuse (``os.access`` does not see all of them, e.g. as root)."""
    try:
        fd, probe = tempfile.mkstemp(dir=folder, prefix=".nearopt-probe.")
    except OSError as exc:
        raise ConfigurationError(f"cannot write {name}: {exc.strerror or exc}") from None
    os.close(fd)
    os.unlink(probe)


def check_outputs(targets: dict[str, str | Path]) -> dict[str, Output]:
    """Resolve and check several outputs by role (e.g. ``{"--json": "plan.json"}``).

    Raises
    ------
    ConfigurationError
        If one cannot be written, or two go to the same place.
    """
    outputs = {role: resolve_output(target) for role, target in targets.items()}
    seen: dict[object, str] = {}
    for role, output in outputs.items():
        if output.identity in seen:
            raise ConfigurationError(
                f"{seen[output.identity]} and {role} would both write {output.name}: "
                "give them different paths"
            )
        seen[output.identity] = role
    return outputs


def is_standard_output(output: Output) -> bool:
    """Whether an output goes to the standard output: ``-``, or a path to what the standard
    output is (``/dev/stdout``, ``/proc/self/fd/1``, the terminal or pipe it is)."""
    if output.kind is OutputKind.STDOUT:
        return True
    try:
        info = os.fstat(sys.stdout.fileno())
    except (OSError, ValueError):  # no standard output (or one without a file)
        return False
    return output.kind is OutputKind.STREAM and output.identity == (info.st_dev, info.st_ino)


def quiet_standard_output() -> None:
    """Send the rest of the standard output to /dev/null: its reader has gone (a closed pipe,
    ``| head``), and Python would complain about it again when it flushes at exit."""
    with contextlib.suppress(OSError, ValueError):
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)


class ReaderTolerant:
    """A text stream for progress lines that goes quiet when its reader has gone (a closed
    pipe): the work and its files go on, the lines are dropped."""

    def __init__(self, stream: object) -> None:
        self.stream = stream
        self.reader_gone = False

    def write(self, text: str) -> int:
        if not self.reader_gone:
            try:
                self.stream.write(text)  # type: ignore[attr-defined]
            except BrokenPipeError:
                self._gone()
        return len(text)

    def flush(self) -> None:
        if not self.reader_gone:
            try:
                self.stream.flush()  # type: ignore[attr-defined]
            except BrokenPipeError:
                self._gone()

    def _gone(self) -> None:
        self.reader_gone = True
        if self.stream is sys.stdout:
            quiet_standard_output()


def refuse_inputs(outputs: dict[str, Output], inputs: dict[str, str | Path]) -> None:
    """Refuse an output that is one of the request's input files (the same file after
    following symbolic links, or a hard link to it).

    Raises
    ------
    ConfigurationError
        Naming the output's role, its path and the input it would destroy.
    """
    read: dict[object, tuple[str, str]] = {}
    for what, path in inputs.items():
        try:
            info = Path(path).expanduser().stat()
        except OSError:  # what cannot be read is refused where it is read
            continue
        read[(info.st_dev, info.st_ino)] = (what, str(path))
    for role, output in outputs.items():
        if output.identity in read:
            what, path = read[output.identity]
            same = os.path.realpath(Path(output.name).expanduser()) == os.path.realpath(path)
            raise ConfigurationError(
                f"{role} {output.name} is {what} of this request"
                + ("" if same else f" (the same file as {path})")
                + ": writing it would destroy it; give the output another path"
            )


def write_outputs(contents: dict[Output, str | bytes]) -> list[str]:
    """Write every output, all or nothing for the files: each file is staged in a temporary file
    next to it first; the streams are written next; only then are the files renamed into place.
    If anything fails, no file is touched (a stream may have received part of its content).

    Returns the names written.

    Raises
    ------
    ConfigurationError
        Naming the output that could not be written and why.
    """
    staged: list[tuple[str, Output]] = []
    umask = os.umask(0)
    os.umask(umask)
    data = {
        output: (c.encode("utf-8") if isinstance(c, str) else c) for output, c in contents.items()
    }
    try:
        for output, content in data.items():
            if output.kind is not OutputKind.FILE:
                continue
            path = output.path
            try:
                fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
                staged.append((tmp, output))
                with os.fdopen(fd, "wb") as handle:
                    handle.write(content)
                mode = path.stat().st_mode & 0o7777 if path.exists() else 0o666 & ~umask
                os.chmod(tmp, mode)  # mkstemp makes 0600: keep the replaced file's mode
            except OSError as exc:
                raise ConfigurationError(
                    f"cannot write {output.name}: {exc.strerror or exc}"
                ) from None
        broken = False  # the standard output's reader went away: the files are still written
        for output, content in data.items():
            if output.kind is OutputKind.FILE:
                continue
            try:
                if output.kind is OutputKind.STDOUT:
                    sys.stdout.flush()
                    sys.stdout.buffer.write(content)
                    sys.stdout.buffer.flush()
                else:
                    with open(output.path, "wb") as handle:
                        handle.write(content)
            except BrokenPipeError:
                if not is_standard_output(output):
                    raise ConfigurationError(f"cannot write {output.name}: broken pipe") from None
                broken = True
            except OSError as exc:
                raise ConfigurationError(
                    f"cannot write {output.name}: {exc.strerror or exc}"
                ) from None
    except BaseException:
        for tmp, _ in staged:
            Path(tmp).unlink(missing_ok=True)
        raise
    with _no_interrupts():  # all renames or none, even on Ctrl-C
        for tmp, output in staged:
            os.replace(tmp, output.path)
    if broken:  # ended quietly by the caller (the POSIX way: 141)
        raise BrokenPipeError("the standard output's reader went away")
    return [output.name for output in data]


@contextlib.contextmanager
def _no_interrupts() -> Iterator[None]:
    """SIGINT held back (in the main thread) until the block ends."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def write_atomically(target: str | Path, content: str | bytes) -> Path:
    """Write ``content`` (text as UTF-8, or bytes) to one place, as :func:`write_outputs` does.

    Returns the path written (the target of a symbolic link; ``-`` for the standard output).
    """
    output = resolve_output(target)
    write_outputs({output: content})
    return output.path if output.path is not None else Path("-")


def make_folder(folder: str | Path, what: str) -> Path:
    """An output folder, made with its parents if missing.

    Raises
    ------
    ConfigurationError
        If it is a file or cannot be made (``what`` names it in the message, e.g. "figures").
    """
    if str(folder) == "":
        raise ConfigurationError(f"the folder for {what} is an empty path")
    path = Path(folder).expanduser()
    if path.exists() and not path.is_dir():
        raise ConfigurationError(f"cannot write {what} into {folder}: it is not a folder")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigurationError(
            f"cannot make the folder {folder}: {exc.strerror or exc}"
        ) from None
    return path
