"""Many motions: plan a motion table on this machine's cores or on a Dask cluster.

A request is one motion of ``nearopt plan``: an ``id`` and the long options of the command
without their dashes, ``-`` written ``_`` (``{"id": "m1", "robot": "ur5", "q0": [...], "qe":
[...], "beta": 0.001}``; ``"time_optimal": true``; ``"via": [[...], [...]]``; ``"scene":
"cell.toml"``, ``"task": "pick.toml"``, ``"goal_pose": [x, y, z, qx, qy, qz, qw]``). Each is
read into the same :class:`~nearopt.api.PlanRequest` as ``nearopt plan`` makes of its options,
then planned and verified by the same code (:func:`nearopt.api.run`); the motion comes back
as the JSON document ``nearopt plan --json`` writes (with the ``id``, the request and a
``"batch"`` record added).

Where the motions run is a :class:`Pool`: :class:`LocalPool` (one process per core of this
machine, :mod:`concurrent.futures`; a worker that dies is replaced and its motions re-run) or
:class:`DaskPool` (the workers of a ``dask.distributed`` scheduler, which re-runs the tasks of a
worker that dies). Each worker process loads a robot once and keeps it for the motions that
follow.

:func:`run_batch` (``nearopt batch TASKS --out DIR``) writes ``DIR/<id>.json`` per motion planned
(``DIR/failed/<id>.json`` with the error per motion that failed) and ``DIR/summary.csv`` as the
results arrive, every file atomically; run again, it skips the motions whose files hold the same
request (the same options, the same contents of the files they name, the same rate).
:func:`plan_many` returns the plans themselves, in request order.

That is the files layout (:class:`Layout`), for batches of up to a few thousand motions. For
motion tables of any size, the shards layout (:mod:`nearopt.sharded`, the default above 1 000
motions) streams the motions file, sends the motions in chunks, lets the workers write the
documents into ``DIR/shards/*.jsonl`` and appends ``DIR/summary.csv``, the index a resumed run
reads.
"""

from __future__ import annotations

import ast
import concurrent.futures as cf
import contextlib
import csv
import io
import json
import math
import multiprocessing
import os
import re
import shutil
import socket
import struct
import sys
import threading
import time
import uuid
import warnings
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, fields, replace
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .api import FILE_FIELDS, PlanRequest, run
from .errors import ConfigurationError, NearoptError, SamplingWarning
from .outputs import make_folder, resolve_output, write_atomically, write_outputs
from .ros import BagContents, replace_folder
from .validate import check_rate

if TYPE_CHECKING:
    from .planning import PlanResult, TaskResult

__all__ = [
    "MotionRequest",
    "MotionOutcome",
    "OutcomeStatus",
    "Pool",
    "LocalPool",
    "DaskPool",
    "read_requests",
    "plan_request",
    "plan_many",
    "run_batch",
    "probe_scheduler",
    "check_main_guard",
    "BatchSummary",
    "SUMMARY_FIELDS",
    "Layout",
    "iter_requests",
    "worker_died",
    "progress_line",
]

SUMMARY_FIELDS = ("id", "status", "J", "te", "iterations", "wall_time", "error")
"""The columns of ``summary.csv``."""
_ID = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,127}")  # the whole id (fullmatch: no "\n")
MAX_ATTEMPTS = 3  # a motion whose worker died this many times is recorded as failed
LISTED = 20
"""Failed motions (and motions with warnings) a report lists; the summary table has them all."""


@dataclass(frozen=True)
class MotionRequest:
    """One motion of a batch.

    Attributes
    ----------
    id
        Its name: letters, digits, ``.``, ``_``, ``-`` (the output is ``<id>.json``).
    options
        The long options of ``nearopt plan`` without dashes, ``-`` as ``_``, with JSON values
        (a flag: ``true``; several values: a list; a repeated option such as ``via``: a list of
        lists). File paths absolute (:func:`read_requests` resolves them).
    """

    id: str
    options: Mapping[str, Any]
    source: Path | None = field(default=None, compare=False)
    """The motions file it was read from (:func:`read_requests`), if any."""

    @classmethod
    def from_dict(
        cls, data: Mapping[str, Any], default_id: str, folder: Path | None = None
    ) -> MotionRequest:
        """A request from a JSON object (``id`` and options); relative file paths are taken
        from ``folder`` (default: the working folder).

        Raises
        ------
        ConfigurationError
            If it is not an object, or its id is not a usable file name.
        """
        if not isinstance(data, Mapping):
            raise ConfigurationError(f"a motion is a JSON object, got {data!r:.80}")
        motion_id = data.get("id", default_id)
        if not isinstance(motion_id, str):
            raise ConfigurationError(
                f'motion id {motion_id!r}: an id is a JSON string, e.g. "{motion_id}" (it '
                "names the output files)"
            )
        if not _ID.fullmatch(motion_id):
            raise ConfigurationError(
                f"motion id {motion_id!r}: ids are 1-128 letters, digits, '.', '_' or '-', "
                "starting with a letter or digit (they name the output files)"
            )
        options = {k: _plain(v) for k, v in data.items() if k != "id"}
        for key, value in options.items():
            if not _is_json(value):
                what = "a robot's name (e.g. 'panda') or urdf=PATH" if key == "robot" else "JSON"
                raise ConfigurationError(
                    f"option {key!r}: a motion's options are JSON values ({what}), got "
                    f"{type(value).__name__} {value!r:.60}"
                )
        base = Path.cwd() if folder is None else folder
        for key in FILE_FIELDS:
            if isinstance(options.get(key), str) and options[key]:
                options[key] = str((base / Path(options[key]).expanduser()).resolve())
        return cls(motion_id, options)

    def plan_request(self, rate: float = 1000.0) -> PlanRequest:
        """The motion as a :class:`~nearopt.api.PlanRequest`, at the batch's ``rate`` [Hz]
        unless it sets its own.

        Raises
        ------
        ConfigurationError
            An unknown or output option, or a value of the wrong kind.
        """
        request = PlanRequest.from_mapping(self.options)
        return request if "rate" in self.options else request.with_rate(rate)

    def fingerprint(self, rate: float = 1000.0) -> str:
        """The motion's id and its request's :meth:`~nearopt.api.PlanRequest.fingerprint` (the
        options, the SHA-256 of every file they name, the samples' rate): a written motion counts
        as done only for the same. Options that make no request are taken as they are."""
        try:
            request: dict[str, Any] = json.loads(self.plan_request(rate).fingerprint())
        except ConfigurationError:
            request = {"options": dict(self.options), "batch_rate": float(rate)}
        return json.dumps({"id": self.id, **request}, sort_keys=True)


def _plain(value: object) -> object:
    """NumPy arrays and scalars, tuples: as the JSON values they stand for."""
    if hasattr(value, "tolist") and callable(value.tolist):  # numpy array or scalar
        value = value.tolist()
    if isinstance(value, tuple | list):
        return [_plain(v) for v in value]
    return value


def _no_repeated_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """A JSON object whose keys are all different (an option given twice is an error, as on
    the command line)."""
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise ConfigurationError(f"option {key!r} is given twice")
        out[key] = value
    return out


def _is_json(value: object) -> bool:
    """Whether a value is one JSON holds: a string, number, true/false, null, a list or an
    object (a value of the wrong kind for its option fails its motion, not the batch)."""
    if isinstance(value, list):
        return all(_is_json(v) for v in value)
    if isinstance(value, dict):
        return all(isinstance(k, str) and _is_json(v) for k, v in value.items())
    return value is None or isinstance(value, str | int | float | bool)


class OutcomeStatus(StrEnum):
    """Whether a motion of a batch was planned."""

    PLANNED = "planned"
    """Planned and verified: the document holds the motion."""
    FAILED = "failed"
    """Not planned: the error says why (infeasible, unreachable, a bad option, …)."""


@dataclass(frozen=True)
class MotionOutcome:
    """What became of one motion.

    Attributes
    ----------
    id
        The request's id.
    status
        Planned or failed.
    stop
        Why its planner stopped (a :class:`~nearopt.StopReason` value), when planned.
    J, te
        Its cost and duration [s], when planned.
    iterations
        Stage-2 iterations (summed over a task's segments), when planned.
    wall_time
        Seconds its worker spent on it (loading the robot included, the first time).
    error
        ``ErrorType: message`` when it failed.
    warnings
        Warnings about the planned motion (e.g. samples too sparse for a short phase).
    document
        The JSON text of ``DIR/<id>.json`` (planned) or of ``DIR/failed/<id>.json``.
    result
        The plan itself (:class:`~nearopt.PlanResult` or :class:`~nearopt.TaskResult`) when it
        was asked for (:func:`plan_many`) and planned.
    bag
        Its rosbag2's files when they were asked for (``DIR/bags/<id>/``) and it was planned.
    """

    id: str
    status: OutcomeStatus
    stop: str | None = None
    J: float | None = None  # noqa: N815 - the paper's name
    te: float | None = None
    iterations: int | None = None
    wall_time: float = 0.0
    error: str | None = None
    warnings: tuple[str, ...] = ()
    document: str = field(default="", repr=False)
    result: PlanResult | TaskResult | None = field(default=None, repr=False)
    bag: BagContents | None = field(default=None, repr=False)

    def row(self) -> dict[str, str]:
        """Its line of ``summary.csv``."""
        planned = self.status == OutcomeStatus.PLANNED
        return {
            "id": self.id,
            "status": str(self.stop if planned else self.status),
            "J": repr(self.J) if self.J is not None else "",
            "te": repr(self.te) if self.te is not None else "",
            "iterations": "" if self.iterations is None else str(self.iterations),
            "wall_time": f"{self.wall_time:.3f}",
            "error": self.error or "",
        }


# --------------------------------------------------------------------------------------------
# one motion, in a worker


def plan_request(
    request: MotionRequest, rate: float = 1000.0, keep_result: bool = False, ros_bag: bool = False
) -> MotionOutcome:
    """Plan, verify and write out one motion as ``nearopt plan`` would (in this process); with
    ``ros_bag`` its rosbag2 too (:func:`nearopt.ros.bag_files`, stamped from the time it was
    planned, named after the motion).

    Every error a motion can cause (a bad option, an infeasible request, a failed verification)
    is its outcome's ``error``, not an exception.
    """
    from .export import json_text

    t0 = time.perf_counter()
    try:
        outcome = run(request.plan_request(rate), robot_loader=_cached_robot)
        result = outcome.result
        iterations = result.iterations
        wall = time.perf_counter() - t0
        notes = list(outcome.warnings)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", SamplingWarning)
            text = json_text(
                result,
                outcome.prepared.request.rate,
                extra={
                    "id": request.id,
                    "request": json.loads(request.fingerprint(rate)),
                    "batch": {
                        "status": str(result.status),
                        "iterations": iterations,
                        "wall_time": wall,
                        "warnings": notes,
                    },
                },
            )
            bag = None
            if ros_bag:
                from .ros import bag_files

                bag = bag_files(result, request.id, outcome.prepared.request.rate)
    except (NearoptError, OSError, ArithmeticError, LookupError, TypeError, ValueError) as exc:
        # a nearopt error says what is wrong; anything else is a defect of nearopt's, recorded
        # against its motion (the batch goes on) rather than ending the batch with a traceback
        ours = isinstance(exc, NearoptError | OSError)
        prefix = "" if ours else "internal error, please report: "
        error = f"{prefix}{type(exc).__name__}: {' '.join(str(exc).split())}"
        wall = time.perf_counter() - t0
        document = json.dumps(
            {
                "id": request.id,
                "request": json.loads(request.fingerprint(rate)),
                "error": error,
                "wall_time": wall,
            }
        )
        return MotionOutcome(
            request.id, OutcomeStatus.FAILED, error=error, wall_time=wall, document=document
        )
    return MotionOutcome(
        request.id,
        OutcomeStatus.PLANNED,
        stop=str(result.status),
        J=float(result.J),
        te=float(result.duration),
        iterations=iterations,
        wall_time=wall,
        warnings=tuple(notes),
        document=text,
        result=result if keep_result else None,
        bag=bag,
    )


_robots: dict[tuple[object, ...], object] = {}
_robots_lock = threading.Lock()


def _cached_robot(key: tuple[object, ...], load: Callable[[], object]) -> object:
    """A worker's robots, loaded once per process and thread (a Robot keeps Pinocchio data,
    which two threads must not share)."""
    key = (threading.get_ident(), *key)
    with _robots_lock:
        robot = _robots.get(key)
    if robot is None:
        robot = load()
        with _robots_lock:
            _robots[key] = robot
    return robot


# --------------------------------------------------------------------------------------------
# where motions run


class Pool:
    """Where the motions of a batch run: submit motions, get their outcomes as they finish."""

    workers: int

    def run(
        self,
        requests: Sequence[MotionRequest],
        rate: float,
        keep_result: bool,
        ros_bag: bool = False,
    ) -> Iterator[MotionOutcome]:  # pragma: no cover - interface
        """Plan every request; yield the outcomes in the order they finish."""
        raise NotImplementedError

    retries_lost: bool = False
    """Whether the pool itself runs a task again when its worker dies (Dask does)."""

    def submit(self, fn: Callable[..., Any], *args: object) -> Any:  # pragma: no cover
        """Run ``fn(*args)`` on a worker; a future (``.result()``)."""
        raise NotImplementedError

    def wait(self, futures: Iterable[Any]) -> list[Any]:  # pragma: no cover - interface
        """Wait until one of ``futures`` is finished; all the finished ones."""
        raise NotImplementedError

    def lost(self, exc: BaseException) -> bool:
        """Whether a future's exception says its worker died (the pool is then ready for new
        tasks, and the dead worker's processes are gone)."""
        return False

    def cancel(self, futures: list[Any]) -> None:
        """Cancel what of ``futures`` has not run."""
        for future in futures:
            future.cancel()

    def close(self, abort: bool = False) -> None:
        """Release the workers (or the connection); ``abort``: stop what runs now."""

    def __enter__(self) -> Pool:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def check_main_guard() -> None:
    """Refuse to start worker processes from the top level of a script without
    ``if __name__ == "__main__":``: each spawned worker imports the script again, so it would run
    the script's top level (and start workers of its own, which Python refuses: every motion
    then failed as a dead worker).

    Raises
    ------
    ConfigurationError
        Naming the script and the line of the call.
    """
    import __main__

    script = getattr(__main__, "__file__", None)
    if script is None:  # an interactive session, python -c: nothing is imported again
        return
    frame = sys._getframe(1)  # noqa: SLF001 - the script's top level, where it runs now
    while frame is not None and not (
        frame.f_code.co_name == "<module>" and frame.f_globals is vars(__main__)
    ):
        frame = frame.f_back
    if frame is None:  # not under the script's top level (a thread, a callback)
        return
    try:
        tree = ast.parse(Path(script).read_text(encoding="utf-8"))
    except (OSError, SyntaxError, ValueError):
        return
    line = frame.f_lineno
    for node in ast.walk(tree):  # a guard anywhere (in a try, a with; `"__main__" == __name__`,
        if (  # `__name__ == "__main__" and …`), the call in its body
            isinstance(node, ast.If)
            and _tests_main(node.test)
            and node.body[0].lineno <= line <= (node.body[-1].end_lineno or node.lineno)
        ):
            return
    raise ConfigurationError(
        f"{script}, line {line}: plan_many and run_batch start worker processes that import "
        'this script again; put the call under `if __name__ == "__main__":` (see the README)'
    )


def _tests_main(test: ast.expr) -> bool:
    """Whether an ``if`` test compares ``__name__`` with ``"__main__"`` (in either order, alone or
    in a larger condition)."""
    for node in ast.walk(test):
        if isinstance(node, ast.Compare) and all(isinstance(op, ast.Eq) for op in node.ops):
            sides = [node.left, *node.comparators]
            if any(isinstance(s, ast.Name) and s.id == "__name__" for s in sides) and any(
                isinstance(s, ast.Constant) and s.value == "__main__" for s in sides
            ):
                return True
    return False


class LocalPool(Pool):
    """One worker process per core of this machine (:mod:`concurrent.futures`, spawned fresh,
    one BLAS thread each). A worker that dies (killed, out of memory) is replaced and the motions
    it held are run again, up to :data:`MAX_ATTEMPTS` times each.

    Parameters
    ----------
    workers
        Worker processes (default: the number of cores).
    """

    def __init__(self, workers: int | None = None) -> None:
        count = (os.cpu_count() or 1) if workers is None else workers
        if not isinstance(count, int) or isinstance(count, bool) or count < 1:
            raise ConfigurationError(f"workers must be a positive integer, got {workers!r}")
        check_main_guard()
        self.workers = count
        self._executor: cf.ProcessPoolExecutor | None = None

    def _start(self) -> cf.ProcessPoolExecutor:
        if self._executor is None:
            self._executor = cf.ProcessPoolExecutor(
                self.workers,
                mp_context=multiprocessing.get_context("spawn"),
                initializer=_worker_start,
            )
        return self._executor

    def processes(self) -> list[int]:
        """The worker processes' ids (those started so far)."""
        executor = self._executor
        return [] if executor is None else list(executor._processes)  # noqa: SLF001

    def run(
        self,
        requests: Sequence[MotionRequest],
        rate: float,
        keep_result: bool,
        ros_bag: bool = False,
    ) -> Iterator[MotionOutcome]:
        attempts = dict.fromkeys((r.id for r in requests), 0)
        order = {r.id: k for k, r in enumerate(requests)}
        pending = list(requests)
        while pending:
            executor = self._start()
            futures = {
                executor.submit(plan_request, r, rate, keep_result, ros_bag): r for r in pending
            }
            for r in pending:
                attempts[r.id] += 1
            pending = []
            broken = False
            for future in cf.as_completed(futures):
                request = futures[future]
                try:
                    yield future.result()
                except cf.process.BrokenProcessPool:
                    broken = True
                    if attempts[request.id] >= MAX_ATTEMPTS:
                        yield worker_died(request, attempts[request.id])
                    else:
                        pending.append(request)
            if broken:  # a worker died: a fresh pool runs what was lost
                self._executor.shutdown(wait=False, cancel_futures=True)
                self._executor = None
            pending.sort(key=lambda r: order[r.id])

    def submit(self, fn: Callable[..., Any], *args: object) -> Any:
        return self._start().submit(fn, *args)

    def wait(self, futures: Iterable[Any]) -> list[Any]:
        return list(cf.wait(list(futures), return_when=cf.FIRST_COMPLETED).done)

    def lost(self, exc: BaseException) -> bool:
        if not isinstance(exc, cf.process.BrokenProcessPool):
            return False
        executor = self._executor
        if executor is not None and executor._broken:  # noqa: SLF001
            # the pool fails its futures before it stops its other workers: stop them first,
            # so that none writes on after the caller looks at what they wrote
            processes = list(executor._processes.values())  # noqa: SLF001
            for process in processes:
                process.terminate()
            for process in processes:
                process.join(10.0)
            executor.shutdown(wait=False, cancel_futures=True)
            self._executor = None
        return True

    def close(self, abort: bool = False) -> None:
        executor, self._executor = self._executor, None
        if executor is None:
            return
        if abort:  # Ctrl-C: the workers go now, not after their motions
            for process in list(executor._processes.values()):  # noqa: SLF001
                process.terminate()
        executor.shutdown(wait=True, cancel_futures=True)


def _worker_start() -> None:
    """A local worker: Ctrl-C is the parent's to handle (it cancels what is left)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)


def worker_died(request: MotionRequest, attempts: int) -> MotionOutcome:
    """The outcome of a motion whose worker died ``attempts`` times."""
    error = (
        f"WorkerDied: the worker process planning it died {attempts} times (killed, out of "
        "memory, or a crash in a native library)"
    )
    return MotionOutcome(
        request.id,
        OutcomeStatus.FAILED,
        error=error,
        document=json.dumps({"id": request.id, "error": error}),
    )


PROBE_SECONDS = 3.0
"""How long :func:`probe_scheduler` waits for a connection and for the scheduler's greeting."""


def probe_scheduler(address: str, wait: float = PROBE_SECONDS) -> None:
    """Check that a Dask scheduler answers at ``address`` (``tcp://host:port`` or
    ``host:port``; inproc:// and ucx:// are left to Dask), within ``wait`` seconds twice at
    most.

    A scheduler speaks first: on a new connection it sends its handshake, a message whose
    first 8 bytes are its length (over tcp://; over tls://, ws:// and wss:// the connection
    alone is checked). Anything else is named: nothing listening, no answer, an
    HTTP server (the dashboard, port 8787, is the commonest slip), another kind of server.

    Raises
    ------
    ConfigurationError
        Naming the address and what answered there.
    """
    text = str(address)
    scheme, _, rest = text.rpartition("://")
    if scheme in ("inproc", "ucx", "ucxx"):  # no socket to probe: Dask's own connection decides
        return
    if scheme not in ("", "tcp", "tls", "ws", "wss"):
        raise ConfigurationError(
            f"--scheduler {text}: {scheme}:// is not a Dask protocol; a scheduler's address is "
            "tcp://HOST:8786 (or tls://, ws://, wss://, inproc://, ucx://)"
        )
    host, colon, port = rest.rpartition(":")
    if not colon or not port.isdigit() or not 0 < int(port) < 65536:
        raise ConfigurationError(
            f"--scheduler {text}: give the scheduler's host and port, e.g. tcp://10.0.0.5:8786"
        )
    where = f"the Dask scheduler at {text}"
    try:
        sock = socket.create_connection((host.strip("[]") or "127.0.0.1", int(port)), wait)
    except TimeoutError:
        raise ConfigurationError(f"cannot connect to {where}: no answer in {wait:g} s") from None
    except OSError as exc:
        raise ConfigurationError(f"cannot connect to {where}: {exc.strerror or exc}") from None
    with sock:
        if scheme not in ("", "tcp"):  # encrypted or framed: Dask's own handshake decides
            return
        greeting = _received(sock, 8, wait)
        if len(greeting) == 8 and struct.unpack("<Q", greeting)[0] < 2**24:
            return  # a Dask message: its length, then the handshake
        reply = b""
        if not greeting:  # silent: an HTTP server waits for a request
            with contextlib.suppress(OSError):
                sock.sendall(b"GET / HTTP/1.0\r\n\r\n")
            reply = _received(sock, 5, wait)
    if (greeting or reply).startswith(b"HTTP/"):
        raise ConfigurationError(
            f"{text} is an HTTP server, not a Dask scheduler — the dashboard? the scheduler "
            "listens on port 8786 unless it was told otherwise"
        )
    if greeting:
        raise ConfigurationError(
            f"{text} answered, but not as a Dask scheduler (it sent {greeting!r:.40})"
        )
    raise ConfigurationError(
        f"{text} accepted the connection but said nothing in {wait:g} s: not a Dask scheduler"
    )


def _received(sock: socket.socket, count: int, wait: float) -> bytes:
    """Up to ``count`` bytes from ``sock``, waiting at most ``wait`` seconds in all."""
    data, deadline = b"", time.monotonic() + wait
    while len(data) < count:
        left = deadline - time.monotonic()
        if left <= 0:
            break
        sock.settimeout(left)
        try:
            chunk = sock.recv(count - len(data))
        except OSError:  # a timeout or a reset: what came so far
            break
        if not chunk:
            break
        data += chunk
    return data


class DaskPool(Pool):
    """The workers of a ``dask.distributed`` scheduler (``pip install 'nearopt[batch]'``;
    the workers need nearopt installed, and any URDF, scene or task file at the same path).

    The scheduler re-runs the tasks of a worker that dies (up to its ``allowed-failures``,
    then the motion is recorded as failed).

    Parameters
    ----------
    address
        The scheduler, e.g. ``tcp://10.0.0.5:8786``; or a ready ``distributed.Client``.
    timeout
        Seconds to wait for the connection.
    """

    def __init__(self, address: str | object, timeout: float = 30.0) -> None:
        try:
            import distributed
        except ImportError:
            raise ConfigurationError(
                "--scheduler needs Dask: pip install 'nearopt[batch]' (dask[distributed])"
            ) from None
        self._distributed = distributed
        if isinstance(address, distributed.Client):
            self.client, self._own = address, False
        else:
            probe_scheduler(str(address))
            try:
                self.client = distributed.Client(address, timeout=timeout)
            except (OSError, TimeoutError, ValueError) as exc:
                raise ConfigurationError(
                    f"cannot connect to the Dask scheduler at {address}: {exc}"
                ) from None
            self._own = True
        self.workers = max(
            1, sum(w.get("nthreads", 1) for w in self.client.scheduler_info()["workers"].values())
        )

    def run(
        self,
        requests: Sequence[MotionRequest],
        rate: float,
        keep_result: bool,
        ros_bag: bool = False,
    ) -> Iterator[MotionOutcome]:
        distributed = self._distributed
        futures = {
            self.client.submit(
                plan_request,
                r,
                rate,
                keep_result,
                ros_bag,
                pure=False,
                key=f"nearopt-{r.id}-{time.time_ns()}",
            ): r
            for r in requests
        }
        try:
            for future in distributed.as_completed(futures):
                request = futures[future]
                try:
                    yield future.result()
                except distributed.KilledWorker:
                    yield worker_died(request, MAX_ATTEMPTS)
        finally:
            self.client.cancel(list(futures))

    retries_lost = True

    def submit(self, fn: Callable[..., Any], *args: object) -> Any:
        return self.client.submit(fn, *args, pure=False, key=f"nearopt-{uuid.uuid4().hex}")

    def wait(self, futures: Iterable[Any]) -> list[Any]:
        return list(self._distributed.wait(list(futures), return_when="FIRST_COMPLETED").done)

    def lost(self, exc: BaseException) -> bool:
        return isinstance(exc, self._distributed.KilledWorker)

    def cancel(self, futures: list[Any]) -> None:
        if futures:
            self.client.cancel(futures)

    def close(self, abort: bool = False) -> None:
        if self._own:
            self.client.close()


# --------------------------------------------------------------------------------------------
# the batch


def read_requests(path: str | Path) -> list[MotionRequest]:
    """The motions of a JSON Lines file, one object per line (blank lines and lines starting
    with ``#`` skipped); relative file paths are read from the file's folder.

    Raises
    ------
    ConfigurationError
        A missing file, a line that is not a JSON object (naming the line), a bad or repeated id.
    """
    requests: list[MotionRequest] = []
    seen: dict[str, int] = {}
    for number, request in iter_requests(path):
        if request.id in seen:
            raise ConfigurationError(
                f"{request.source}, line {number}: id {request.id!r} repeats line "
                f"{seen[request.id]}"
            )
        seen[request.id] = number
        requests.append(request)
    if not requests:
        raise ConfigurationError(
            f"{Path(path).expanduser().resolve()}: no motions (one JSON object per line)"
        )
    return requests


def iter_requests(path: str | Path) -> Iterator[tuple[int, MotionRequest]]:
    """The motions of a JSON Lines file with their line numbers, read a line at a time (the
    file is never held whole); as :func:`read_requests`, without the check that ids differ.

    Raises
    ------
    ConfigurationError
        A missing file, a line that is not a JSON object (naming the line), a bad id.
    """
    path = Path(path).expanduser().resolve()
    try:
        stream = path.open(encoding="utf-8")
    except OSError as exc:
        raise ConfigurationError(
            f"cannot read the motions file {path}: {exc.strerror or exc}"
        ) from None
    with stream:
        number = 0
        while True:
            try:
                line = stream.readline()
            except (OSError, UnicodeDecodeError) as exc:
                raise ConfigurationError(
                    f"cannot read the motions file {path} after line {number}: "
                    f"{getattr(exc, 'strerror', None) or exc}"
                ) from None
            if not line:
                return
            number += 1
            if not line.strip() or line.lstrip().startswith("#"):
                continue
            yield number, _motion_line(path, number, line)


def _motion_line(path: Path, number: int, line: str) -> MotionRequest:
    """Line ``number`` of the motions file ``path`` as a request."""
    try:
        data = json.loads(line, object_pairs_hook=_no_repeated_keys)
    except json.JSONDecodeError as exc:
        raise ConfigurationError(f"{path}, line {number}: not JSON ({exc})") from None
    except ConfigurationError as exc:  # a repeated key
        raise ConfigurationError(f"{path}, line {number}: {exc}") from None
    try:
        request = MotionRequest.from_dict(data, f"line{number}", path.parent)
    except ConfigurationError as exc:
        raise ConfigurationError(f"{path}, line {number}: {exc}") from None
    return replace(request, source=path)


def _requests(
    requests: Iterable[MotionRequest | PlanRequest | Mapping[str, Any]],
) -> list[MotionRequest]:
    if isinstance(requests, Mapping | MotionRequest | PlanRequest | str):
        raise ConfigurationError(
            f"give a list of motions (one {type(requests).__name__} is one motion: [motion])"
        )
    out, seen = [], set()
    for k, r in enumerate(requests):
        if isinstance(r, PlanRequest):  # the one request model: its options, defaults left out
            r = {
                f.name: getattr(r, f.name)
                for f in fields(PlanRequest)
                if getattr(r, f.name) != f.default
            }
        request = r if isinstance(r, MotionRequest) else MotionRequest.from_dict(r, f"m{k}")
        if request.id in seen:
            raise ConfigurationError(f"motion id {request.id!r} appears twice")
        seen.add(request.id)
        out.append(request)
    return out


def _pool(client: object | None, workers: int | None) -> Pool:
    if client is None:
        return LocalPool(workers)
    if isinstance(client, Pool):
        return client
    if workers is not None:
        raise ConfigurationError("workers applies to this machine's pool, not to a Dask client")
    if not isinstance(client, str) and type(client).__name__ != "Client":
        raise ConfigurationError(
            "client must be None (this machine), a scheduler address such as "
            f"'tcp://10.0.0.5:8786', a distributed.Client or a Pool, got "
            f"{type(client).__name__} {client!r:.60}"
        )
    return DaskPool(client)


def plan_many(
    requests: Iterable[MotionRequest | PlanRequest | Mapping[str, Any]],
    client: object | None = None,
    *,
    workers: int | None = None,
    rate: float = 1000.0,
) -> list[MotionOutcome]:
    """Plan many motions in parallel; their outcomes in request order, each with its plan.

    Parameters
    ----------
    requests
        :class:`MotionRequest` records, :class:`~nearopt.api.PlanRequest` records (ids
        ``m<k>``), or dicts of ``id`` (default ``m<k>``) and the options of ``nearopt plan``
        (see the module docstring; relative paths from the working folder).
    client
        None: this machine's cores (:class:`LocalPool`); a ``distributed.Client`` or a scheduler
        address: that cluster (:class:`DaskPool`); or a :class:`Pool`.
    workers
        Worker processes of the local pool (default: one per core).
    rate
        The samples' rate of the JSON documents [Hz].
    """
    check_rate(rate)
    requests = _requests(requests)
    order = {r.id: k for k, r in enumerate(requests)}
    outcomes: list[MotionOutcome | None] = [None] * len(requests)
    pool = _pool(client, workers)
    own = pool is not client
    aborted = True
    try:
        for outcome in pool.run(requests, rate, keep_result=True):
            outcomes[order[outcome.id]] = outcome
        aborted = False
    finally:
        if own:
            pool.close(abort=aborted)
    return outcomes  # type: ignore[return-value]


class Layout(StrEnum):
    """How a batch's results are written."""

    FILES = "files"
    """``DIR/<id>.json`` per motion planned (``DIR/failed/<id>.json`` per failure), written by
    the client, and ``DIR/summary.csv`` in request order, rewritten as results arrive: for
    batches of up to a few thousand motions."""
    SHARDS = "shards"
    """``DIR/shards/*.jsonl`` written by the workers, a chunk of motions each, and
    ``DIR/summary.csv`` appended (:mod:`nearopt.sharded`): for motion tables of any size."""
    AUTO = "auto"
    """The layout a folder has already; else shards for more than
    :data:`~nearopt.sharded.SHARDS_FROM` motions, files otherwise."""


@dataclass(frozen=True)
class BatchSummary:
    """How a batch went.

    Attributes
    ----------
    outcomes
        Files layout: every motion's outcome, in request order (those skipped as done read back
        from their files, without ``document``). Shards layout: the first failures of this run
        (the summary table has them all).
    skipped
        Motions found done from an earlier run and not planned again.
    wall_time
        Seconds this run took.
    total, planned_count, failed_count
        Motions in the batch, planned, failed (the skipped ones included); counted from
        ``outcomes`` when not given.
    tasks
        Tasks submitted to the pool (a motion each in the files layout, a chunk in shards).
    layout
        How its results were written.
    """

    outcomes: tuple[MotionOutcome, ...]
    skipped: int
    wall_time: float
    total: int | None = None
    planned_count: int | None = None
    failed_count: int | None = None
    tasks: int = 0
    layout: Layout = Layout.FILES

    @property
    def failed(self) -> int:
        """Motions that failed."""
        if self.failed_count is not None:
            return self.failed_count
        return sum(o.status == OutcomeStatus.FAILED for o in self.outcomes)

    @property
    def planned(self) -> int:
        """Motions planned (in this run or before)."""
        if self.planned_count is not None:
            return self.planned_count
        return sum(o.status == OutcomeStatus.PLANNED for o in self.outcomes)

    @property
    def count(self) -> int:
        """Motions in the batch."""
        return len(self.outcomes) if self.total is None else self.total


def run_batch(
    requests: Sequence[MotionRequest] | str | Path,
    out: str | Path,
    client: object | None = None,
    *,
    workers: int | None = None,
    rate: float = 1000.0,
    retry_failed: bool = False,
    progress: Callable[[int, int, int, int, float], None] | None = None,
    ros_bag: bool = False,
    layout: Layout | str = Layout.AUTO,
) -> BatchSummary:
    """Plan every motion not already done and write its results (see :class:`Layout`).

    Parameters
    ----------
    requests
        The motions (:func:`read_requests`), or a motions file (JSON Lines), read a line at a
        time in the shards layout.
    out
        The output folder (made if missing).
    client, workers, rate
        As :func:`plan_many`.
    retry_failed
        Plan again the motions an earlier run recorded as failed (default: skip them too).
    progress
        Called as results arrive with (done, failed, running, total, ETA [s]).
    ros_bag
        Also write each motion planned in this run as a rosbag2 ``DIR/bags/<id>/``
        (:func:`nearopt.ros.write_ros_bag`; before its JSON, so that a motion whose JSON is
        written has its bag; a motion skipped as done gets none).
    layout
        Files, shards, or auto (:class:`Layout`).

    Raises
    ------
    ConfigurationError
        A bad motions file or option, a folder of the other layout, a folder another batch is
        writing, an unreachable scheduler: before anything is planned.
    """
    from .sharded import MotionsFile, run_sharded

    t0 = time.perf_counter()
    check_rate(rate)
    layout = _layout_value(layout)
    if isinstance(requests, str | Path):
        motions = MotionsFile.scan(requests)
    else:
        motions = MotionsFile.of(requests)
    layout = _layout_of(Path(out).expanduser(), layout, motions.count)
    # a cluster is reached (and its address probed, DaskPool) before anything is made; this
    # machine's pool starts when needed
    cluster = None if client is None or isinstance(client, Pool) else _pool(client, workers)
    if client is None:  # this machine's pool: a script without a main guard makes nothing
        check_main_guard()
    try:
        where = client if cluster is None else cluster
        if layout == Layout.FILES:
            listed = list(motions) if motions.path is not None else list(motions.requests)
            return _run_batch(
                listed, out, where, workers, rate, retry_failed, progress, t0, ros_bag
            )
        folder = make_folder(out, "the motions")
        _refuse_inputs(folder, [], motions.path)
        pool = _pool(where, workers)
        own, aborted = pool is not where, True
        try:
            summary = run_sharded(motions, folder, pool, rate, retry_failed, progress, ros_bag)
            aborted = False
        finally:
            if own:
                pool.close(abort=aborted)
        return replace(summary, wall_time=time.perf_counter() - t0, layout=Layout.SHARDS)
    finally:
        if cluster is not None:
            cluster.close()


def _layout_value(layout: Layout | str) -> Layout:
    try:
        return Layout(layout)
    except ValueError:
        raise ConfigurationError(
            f"layout {layout!r}: one of {', '.join(repr(str(v)) for v in Layout)}"
        ) from None


def _layout_of(folder: Path, layout: Layout, count: int) -> Layout:
    """The layout a batch writes ``folder`` in: the one asked for, if the folder holds no
    batch of the other; for auto, the folder's own, else by the number of motions.

    Raises
    ------
    ConfigurationError
        A folder of the other layout.
    """
    from .sharded import SHARD_FIELDS, SHARDS_FROM

    found = None
    try:
        with (folder / "summary.csv").open(encoding="utf-8") as stream:
            header = stream.readline().rstrip("\n").split(",")
        found = Layout.SHARDS if tuple(header) == SHARD_FIELDS else Layout.FILES
    except (OSError, UnicodeDecodeError):
        if (folder / "shards").is_dir():
            found = Layout.SHARDS
    if layout == Layout.AUTO:
        if found is not None:
            return found
        return Layout.SHARDS if count > SHARDS_FROM else Layout.FILES
    if found is not None and found != layout:
        raise ConfigurationError(
            f"{folder} holds a batch in the {found} layout, not {layout}: give --out another "
            f"folder, or --layout {found} (or auto) to go on with it"
        )
    return layout


def _run_batch(
    requests: Sequence[MotionRequest],
    out: str | Path,
    client: object | None,
    workers: int | None,
    rate: float,
    retry_failed: bool,
    progress: Callable[[int, int, int, int, float], None] | None,
    t0: float,
    ros_bag: bool = False,
) -> BatchSummary:
    """:func:`run_batch` once the pool is known (``client``: None or a :class:`Pool`)."""
    folder = make_folder(out, "the motions")
    _refuse_inputs(folder, requests)
    outcomes: dict[str, MotionOutcome] = {}
    for request in requests:
        done = _done(folder, request, retry_failed, rate)
        if done is not None:
            outcomes[request.id] = done
    skipped = len(outcomes)
    todo = [r for r in requests if r.id not in outcomes]
    _write_summary(folder, requests, outcomes)
    total, started = len(requests), time.perf_counter()
    if todo:
        pool = _pool(client, workers)
        own = pool is not client
        aborted = True
        try:
            finished = 0
            for outcome in pool.run(todo, rate, keep_result=False, ros_bag=ros_bag):
                planned = outcome.status == OutcomeStatus.PLANNED
                name = _file(folder, outcome.id, planned)
                _file(folder, outcome.id, not planned).unlink(missing_ok=True)  # stale
                bag = folder / "bags" / outcome.id
                if outcome.bag is not None:  # first: a motion whose JSON is there has its bag
                    replace_folder(bag, outcome.bag.files)
                elif not planned and (bag / "metadata.yaml").is_file():  # stale
                    shutil.rmtree(bag)
                outcomes[outcome.id] = _light(outcome)
                # the motion's file and the summary that lists it: both or neither (Ctrl-C)
                if not planned:
                    name.parent.mkdir(exist_ok=True)
                write_outputs(
                    {
                        resolve_output(name): outcome.document,
                        resolve_output(folder / "summary.csv"): _summary_text(requests, outcomes),
                    }
                )
                finished += 1
                if progress is not None:
                    elapsed = time.perf_counter() - started
                    left = len(todo) - finished
                    eta = elapsed / finished * left
                    failed = sum(o.status == OutcomeStatus.FAILED for o in outcomes.values())
                    progress(len(outcomes), failed, min(pool.workers, left), total, eta)
            aborted = False
        finally:
            if own:
                pool.close(abort=aborted)
    return BatchSummary(
        tuple(outcomes[r.id] for r in requests if r.id in outcomes),
        skipped,
        time.perf_counter() - t0,
    )


def _light(outcome: MotionOutcome) -> MotionOutcome:
    """The outcome without its document and plan (kept for the summary)."""
    return replace(outcome, document="", result=None, bag=None)


def _refuse_inputs(folder: Path, requests: list[MotionRequest], source: Path | None = None) -> None:
    """Refuse a batch whose outputs (a motion's file, the summary) would replace one of its
    inputs (the motions file, a motion's URDF, SRDF, scene or task), before anything is
    planned."""
    summary = folder / "summary.csv"
    for output in (summary, folder / "batch.lock"):
        if source is not None and _same_file(output, source):
            raise ConfigurationError(
                f"the motions file {source} is the batch's {output.name}: give --out another folder"
            )
    for request in requests:
        inputs = {} if request.source is None else {"the motions file": request.source}
        for key in FILE_FIELDS:
            value = request.options.get(key)
            if isinstance(value, str) and value:
                inputs[f"its {key}"] = Path(value)
        for output in (summary, _file(folder, request.id, True), _file(folder, request.id, False)):
            for what, path in inputs.items():
                if _same_file(output, path):
                    fix = (
                        "give --out another folder"
                        if output == summary
                        else "give --out another folder or the motion another id"
                    )
                    raise ConfigurationError(
                        f"motion {request.id!r}: its output {output} is {what} ({path}); {fix}"
                    )


def _same_file(a: Path, b: Path) -> bool:
    """Whether two paths name one file (through symbolic and hard links)."""
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist (yet): the same place, or not
        return os.path.realpath(a) == os.path.realpath(b)


def _file(folder: Path, motion_id: str, planned: bool) -> Path:
    """Where a motion's outcome is written: DIR/<id>.json, or DIR/failed/<id>.json."""
    return folder / f"{motion_id}.json" if planned else folder / "failed" / f"{motion_id}.json"


def _done(
    folder: Path, request: MotionRequest, retry_failed: bool, rate: float
) -> MotionOutcome | None:
    """The outcome an earlier run wrote for the same request, or None."""
    wanted = json.loads(request.fingerprint(rate))
    for planned in (True, False):
        if not planned and retry_failed:
            continue
        try:
            document = json.loads(_file(folder, request.id, planned).read_text(encoding="utf-8"))
        except (OSError, ValueError):
            continue
        if not isinstance(document, dict) or document.get("request") != wanted:
            continue
        if not planned:
            return MotionOutcome(
                request.id,
                OutcomeStatus.FAILED,
                error=document.get("error"),
                wall_time=float(document.get("wall_time", 0.0)),
            )
        record = document.get("batch", {})
        return MotionOutcome(
            request.id,
            OutcomeStatus.PLANNED,
            stop=record.get("status"),
            J=document.get("J"),
            te=document.get("duration"),
            iterations=record.get("iterations"),
            wall_time=float(record.get("wall_time", 0.0)),
            warnings=tuple(record.get("warnings", ())),
        )
    return None


def _write_summary(
    folder: Path, requests: Sequence[MotionRequest], outcomes: Mapping[str, MotionOutcome]
) -> None:
    write_atomically(folder / "summary.csv", _summary_text(requests, outcomes))


def _summary_text(requests: Sequence[MotionRequest], outcomes: Mapping[str, MotionOutcome]) -> str:
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, SUMMARY_FIELDS, lineterminator="\n")
    writer.writeheader()
    for request in requests:
        if request.id in outcomes:
            writer.writerow(outcomes[request.id].row())
    return buffer.getvalue()


def progress_line(
    stream: Any = None, every: float = 10.0
) -> Callable[[int, int, int, int, float], None]:
    """A progress reporter: a bar rewritten in place on a terminal (motions done of all,
    failed, running, motions per second in this run, ETA); elsewhere (a log) the same as a line
    at most every ``every`` seconds, and the last."""
    stream = sys.stderr if stream is None else stream
    tty = getattr(stream, "isatty", lambda: False)()
    first: list[float] = []  # (time, done) of the first report
    last = [-math.inf]

    def report(done: int, failed: int, running: int, total: int, eta: float) -> None:
        now = time.monotonic()
        if not first:
            first.extend((now, done))
        if not tty and now - last[0] < every and done < total:
            return
        last[0] = now
        width = 24
        bar = "#" * round(width * done / max(total, 1))
        elapsed = now - first[0]
        rate = f"{(done - first[1]) / elapsed:.1f}/s" if elapsed > 0 else "-/s"
        if math.isfinite(eta):
            minutes, seconds = divmod(round(eta), 60)
            hours, minutes = divmod(minutes, 60)
            left = f"{hours}h{minutes:02d}m" if hours else f"{minutes}m{seconds:02d}s"
        else:
            left = "-"
        line = (
            f"[{bar:<{width}}] {done}/{total} done, {failed} failed, {running} running, "
            f"{rate}, ETA {left}"
        )
        print(("\r" + line) if tty else line, end="" if tty else "\n", file=stream, flush=True)
        if tty and done == total:
            print(file=stream)

    return report
