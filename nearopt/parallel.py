"""Independent pieces of one plan at once, in forked processes: a plan uses this machine's cores.

:func:`in_parallel` runs tasks (functions of no argument) at the same time: all but the first in
forked child processes, whose results come back pickled through pipes, the first in this process.
A forked child starts as a copy of this process (robot, collision model, compiled kernels), so a
task's result is the same number for number as if it had run here, and nothing needs pickling on
the way in.
"""

from __future__ import annotations

import ctypes
import gc
import os
import pickle
import select
import signal
import time
from collections.abc import Callable, Sequence
from typing import TypeVar

from .errors import NearoptError, SolverError

__all__ = ["in_parallel", "in_child", "in_children", "beside", "cores"]

T = TypeVar("T")
U = TypeVar("U")


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

    A task should catch what it expects; what it raises in a child is raised here (a nearopt
    error as it was, anything else as a :class:`~nearopt.SolverError` naming it). A Ctrl-C here
    (or an error of the first task) ends the children.
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


def in_children(
    tasks: Sequence[Callable[[], T]], what: str = "a parallel part of the plan"
) -> list[T]:
    """The tasks' results, in order, each task run in a forked child process of its own (as
    :func:`in_child`), all at the same time; one after the other here where ``os.fork`` is
    missing. Errors as :func:`in_parallel`, ``what`` naming the task in them; a Ctrl-C (or a
    child's error) ends the other children."""
    if not hasattr(os, "fork"):
        return [task() for task in tasks]
    children: list[tuple[int, int]] = []
    results = []
    try:
        for task in tasks:
            children.append(_fork(task))
        while children:
            results.append(_collect(*children.pop(0), what))
    except BaseException:
        for pid, read in children:  # those not collected yet
            _end(pid, read)
        raise
    return results  # type: ignore[return-value]


def beside(
    here: Callable[[], T],
    there: Callable[[], U],
    wanted: Callable[[T], bool],
    what: str = "a parallel part of the plan",
    deadline: float | None = None,
) -> tuple[T, U | None]:
    """``here()`` in this process while ``there()`` runs in a forked child; their results, the
    child's None where ``wanted(here's result)`` is false or the child has not answered by
    ``deadline`` (``time.perf_counter()``; the child is then ended without waiting for it: e.g.
    here was interrupted, or the child hangs). One after the other in this process where
    ``os.fork`` is missing or this process may run on one core only. Errors as
    :func:`in_parallel` (a child that dies: a :class:`~nearopt.SolverError`)."""
    if not hasattr(os, "fork") or cores() < 2:
        mine = here()
        return mine, there() if wanted(mine) else None
    child = _fork(there)
    try:
        mine = here()
    except BaseException:
        _end(*child)
        raise
    if not wanted(mine):
        _end(*child)
        return mine, None
    try:
        answered = deadline is None or _answers_by(child[1], deadline)
    except BaseException:
        _end(*child)
        raise
    if not answered:
        _end(*child)
        return mine, None
    return mine, _collect(*child, what)  # type: ignore[return-value]


def _answers_by(read: int, deadline: float) -> bool:
    """Whether the pipe ``read`` has something to read (the child's answer, or its end) by
    ``deadline``."""
    while True:
        left = deadline - time.perf_counter()
        if left <= 0.0:
            return False
        ready, _, _ = select.select([read], [], [], float(left) if left < 3600.0 else 3600.0)
        if ready:
            return True


def in_child(task: Callable[[], T], what: str = "a parallel part of the plan") -> T:
    """``task()`` in a forked child process (a copy of this one whose process-wide state, such
    as OMPL's generator seeded once per process, is its own); here where ``os.fork`` is missing.
    Errors as :func:`in_parallel`, ``what`` naming the task in them; a Ctrl-C ends the child."""
    if not hasattr(os, "fork"):
        return task()
    return _collect(*_fork(task), what)  # type: ignore[return-value]


def _fork(task: Callable[[], object]) -> tuple[int, int]:
    """Start ``task`` in a forked child that writes its pickled outcome to a pipe; returns the
    child's pid and the pipe's end to read."""
    read, write = os.pipe()
    parent = os.getpid()
    pid = os.fork()
    if pid == 0:  # the child: run, reply, exit without this process's clean-up
        _die_with(parent)
        gc.freeze()  # the parent's objects stay out of the child's garbage collections
        os.close(read)
        try:
            data = pickle.dumps(("ok", task()))
        except BaseException as exc:  # noqa: BLE001 - reported to the parent
            data = _error(exc)
        with os.fdopen(write, "wb") as stream:
            stream.write(data)
        os._exit(0)
    os.close(write)
    return pid, read


def _die_with(parent: int) -> None:
    """In a forked child: be killed when the parent ends (Linux's PR_SET_PDEATHSIG), and end
    now if it already has. A child that outlived a killed parent (a batch's pool worker ended by
    its pool) kept the parent's pipes open, and the pool waited for it forever."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG = 1
    except (OSError, AttributeError):  # not Linux: the child may outlive its parent
        return
    if os.getppid() != parent:
        os._exit(1)


def _error(exc: BaseException) -> bytes:
    """A child's error, pickled: a nearopt error itself (if it survives pickling), anything
    else in words."""
    if isinstance(exc, NearoptError):
        try:
            data = pickle.dumps(("raised", exc))
            pickle.loads(data)
            return data
        except Exception:  # noqa: BLE001 - an error that cannot travel goes in words
            pass
    return pickle.dumps(("error", f"{type(exc).__name__}: {exc}"))


def _collect(pid: int, read: int, what: str = "a parallel part of the plan") -> object:
    """A child's result (after it has ended); a Ctrl-C while waiting for it ends it."""
    try:
        with os.fdopen(read, "rb") as stream:
            data = stream.read()
    except BaseException:
        _kill(pid)
        raise
    os.waitpid(pid, 0)
    if not data:
        raise SolverError(f"{what} ended without an answer (its process died)")
    kind, value = pickle.loads(data)
    if kind == "raised":
        raise value
    if kind == "error":
        raise SolverError(f"{what} failed: {value}")
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
