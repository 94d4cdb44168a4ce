"""A batch's motions: the requests (read from a JSON Lines file), one motion planned in a worker,
its outcome, the summary of a batch, its progress line."""

from __future__ import annotations

import json
import math
import re
import sys
import threading
import time
import warnings
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field, replace
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..api import FILE_FIELDS, PlanRequest, run
from ..errors import ConfigurationError, NearoptError, SamplingWarning
from ..ros import BagContents

if TYPE_CHECKING:
    from ..planning import PlanResult, TaskResult


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
    fingerprint: str = field(default="", repr=False)
    """The request's :meth:`MotionRequest.fingerprint` at the batch's rate (set by
    :func:`plan_request`)."""

    @classmethod
    def from_document(cls, document: Mapping[str, Any], planned: bool) -> MotionOutcome:
        """The outcome a motion's document records (a file of the files layout, a line of a
        shard): of a motion ``planned`` (its ``batch`` record) or failed (its ``error``)."""
        if not planned:
            return cls(
                document["id"],
                OutcomeStatus.FAILED,
                error=str(document.get("error")),
                wall_time=float(document.get("wall_time", 0.0)),
            )
        record = document.get("batch", {})
        return cls(
            document["id"],
            OutcomeStatus.PLANNED,
            stop=record.get("status"),
            J=document.get("J"),
            te=document.get("duration"),
            iterations=record.get("iterations"),
            wall_time=float(record.get("wall_time", 0.0)),
            warnings=tuple(record.get("warnings", ())),
        )

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


def plan_request(
    request: MotionRequest, rate: float = 1000.0, keep_result: bool = False, ros_bag: bool = False
) -> MotionOutcome:
    """Plan, verify and write out one motion as ``nearopt plan`` would (in this process); with
    ``ros_bag`` its rosbag2 too (:func:`nearopt.ros.bag_files`, stamped from the time it was
    planned, named after the motion).

    Every error a motion can cause (a bad option, an infeasible request, a failed verification)
    is its outcome's ``error``, not an exception.
    """
    from ..export import json_text

    fingerprint = request.fingerprint(rate)
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
                    "request": json.loads(fingerprint),
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
                from ..ros import bag_files

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
                "request": json.loads(fingerprint),
                "error": error,
                "wall_time": wall,
            }
        )
        return MotionOutcome(
            request.id,
            OutcomeStatus.FAILED,
            error=error,
            wall_time=wall,
            document=document,
            fingerprint=fingerprint,
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
        fingerprint=fingerprint,
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


class Layout(StrEnum):
    """How a batch's results are written."""

    FILES = "files"
    """``DIR/<id>.json`` per motion planned (``DIR/failed/<id>.json`` per failure), written by
    the client, and ``DIR/summary.csv`` in request order, rewritten as results arrive: for
    batches of up to a few thousand motions."""
    SHARDS = "shards"
    """``DIR/shards/*.jsonl`` written by the workers, a chunk of motions each, and
    ``DIR/summary.csv`` appended (:mod:`nearopt.batch.shards`): for motion tables of any size."""
    AUTO = "auto"
    """The layout a folder has already; else shards for more than
    :data:`~nearopt.batch.shards.SHARDS_FROM` motions, files otherwise."""


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
