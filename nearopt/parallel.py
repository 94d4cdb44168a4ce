"""Independent pieces of one plan at once, in forked processes: a plan uses this machine's cores.

:func:`in_parallel` runs tasks (functions of no argument) at the same time: all but the first in
forked child processes, whose results come back pickled through pipes, the first in this process.
A forked child starts as a copy of this process (robot, collision model, compiled kernels), so a
task's result is the same number for number as if it had run here, and nothing needs pickling on
the way in.
"""

from __future__ import annotations

import gc
import os
import pickle
import signal
from collections.abc import Callable, Sequence
from typing import TypeVar

from .errors import SolverError

__all__ = ["in_parallel", "cores"]

T = TypeVar("T")


def cores() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def in_parallel(tasks: Sequence[Callable[[], T]]) -> list[T]:
    """The tasks' results, in order, the tasks run at the same time (see the module docstring);
    one after the other in this process where ``os.fork`` is missing or this process may run on
    one core only.

    A task should catch what it expects; anything else it raises in a child is raised here as a
    :class:`~nearopt.SolverError` naming it, after every child has ended. A Ctrl-C here (or an
    error of the first task) ends the children.
    """
    if len(tasks) < 2 or not hasattr(os, "fork") or cores() < 2:
        return [task() for task in tasks]
    children: list[tuple[int, int]] = []
    try:
        for task in tasks[1:]:
            children.append(_fork(task))
        first = tasks[0]()
        rest = []
        while children:
            rest.append(_collect(*children.pop(0)))
    except BaseException:
        for pid, read in children:  # those not collected yet
            _end(pid, read)
        raise
    return [first, *rest]


def _fork(task: Callable[[], object]) -> tuple[int, int]:
    """Start ``task`` in a forked child that writes its pickled outcome to a pipe; returns the
    child's pid and the pipe's end to read."""
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: run, reply, exit without this process's clean-up
        gc.freeze()  # the parent's objects stay out of the child's garbage collections
        os.close(read)
        try:
            reply: tuple[str, object] = ("ok", task())
            data = pickle.dumps(reply)
        except BaseException as exc:  # noqa: BLE001 - reported to the parent
            data = pickle.dumps(("error", f"{type(exc).__name__}: {exc}"))
        with os.fdopen(write, "wb") as stream:
            stream.write(data)
        os._exit(0)
    os.close(write)
    return pid, read


def _collect(pid: int, read: int) -> object:
    """A child's result (after it has ended); a Ctrl-C while waiting for it ends it."""
    try:
        with os.fdopen(read, "rb") as stream:
            data = stream.read()
    except BaseException:
        _kill(pid)
        raise
    os.waitpid(pid, 0)
    if not data:
        raise SolverError("a parallel part of the plan ended without an answer (its process died)")
    kind, value = pickle.loads(data)
    if kind == "error":
        raise SolverError(f"a parallel part of the plan failed: {value}")
    return value


def _end(pid: int, read: int) -> None:
    """End a child that is no longer wanted: kill and reap it, close its pipe."""
    _kill(pid)
    os.close(read)


def _kill(pid: int) -> None:
    try:
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
    except (ProcessLookupError, ChildProcessError):
        pass
