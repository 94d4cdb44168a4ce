"""Motion tables at scale: a batch in chunks, its results in shards the workers write.

``nearopt batch TASKS --out DIR --layout shards`` (the default for more than
:data:`SHARDS_FROM` motions) plans the same motions as a batch of per-motion files, through
the same :func:`~nearopt.batch.plan_request` and on the same pools, but:

- the motions file is **streamed** (read twice, a line at a time: once to check every line and
  count the motions, once to plan them), never held whole;
- motions go to the workers in **chunks** (:class:`Chunk`), sized from the measured time per
  motion (about :data:`CHUNK_SECONDS` of work each, at most :data:`MAX_CHUNK` motions), with at
  most :data:`IN_FLIGHT` chunks per worker thread submitted at a time, topped up as they finish;
- each worker **writes its chunk's shard** ``DIR/shards/<chunk>.jsonl`` itself: one JSON document
  per line (the document ``nearopt plan --json`` writes, with the motion's ``id``, ``request``
  and ``batch`` record, or its ``error``), appended motion by motion to ``<chunk>.part`` and
  renamed when the chunk is done;
- the client **appends** a row per motion to ``DIR/summary.csv`` (never rewrites it): the
  columns of a per-motion batch's summary, then ``request`` (the SHA-256 of the motion's
  fingerprint, :meth:`~nearopt.batch.MotionRequest.fingerprint`) and ``shard`` (the file
  holding its document). The summary is the index a resumed batch reads: a motion whose last
  row has the same ``request`` is done and skipped (a failed one unless ``--retry-failed``),
  without opening any shard.

Nothing is lost and nothing planned twice: a worker that dies leaves its ``.part`` with the
motions it finished (the chunk, run again, plans only the rest; a motion whose worker died
:data:`~nearopt.batch.MAX_ATTEMPTS` times is recorded as failed); a client stopped before it
indexed a shard finds the shard on its next run and indexes it.

The client holds 8 bytes per motion while it checks the ids (a hash each) and 17 bytes per
motion done before (id hash, request hash, status) when it resumes, nothing per motion planned:
its memory is flat in the number of motions up to ~10⁷.
"""

from __future__ import annotations

import contextlib
import csv
import fcntl
import hashlib
import io
import itertools
import json
import os
import time
from array import array
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigurationError, NearoptError
from ..ros import replace_folder
from .motions import (
    LISTED,
    MAX_ATTEMPTS,
    SUMMARY_FIELDS,
    BatchSummary,
    MotionOutcome,
    MotionRequest,
    OutcomeStatus,
    iter_requests,
    plan_request,
    worker_died,
)
from .pools import Pool

_RUNS = itertools.count(1)  # the sharded runs of this process

__all__ = [
    "SHARD_FIELDS",
    "SHARDS_FROM",
    "CHUNK_SECONDS",
    "MAX_CHUNK",
    "IN_FLIGHT",
    "MotionsFile",
    "Chunk",
    "ChunkDone",
    "plan_chunk",
    "ShardIndex",
    "run_sharded",
    "request_digest",
]

SHARD_FIELDS = (*SUMMARY_FIELDS, "request", "shard")
"""The columns of a sharded batch's ``summary.csv`` (its index)."""
SHARDS_FROM = 1000
"""``--layout auto``: shards for a motions file of more motions than this, files otherwise."""
CHUNK_SECONDS = 2.0
"""The work a chunk is sized to [s] (from the mean time per motion measured so far)."""
FIRST_CHUNK = 4
"""Motions in each of the first chunks, before a time per motion is measured."""
MAX_CHUNK = 500
"""The most motions in a chunk."""
IN_FLIGHT = 2
"""Chunks submitted per worker thread at a time (one running, one waiting)."""


def request_digest(fingerprint: str) -> str:
    """The ``request`` column: the first 32 hex digits of the SHA-256 of a motion's
    fingerprint (:meth:`~nearopt.batch.MotionRequest.fingerprint`, canonical JSON)."""
    return hashlib.sha256(fingerprint.encode()).hexdigest()[:32]


def _id_hash(motion_id: str) -> int:
    """64 bits of a motion id's SHA-256 (as a signed integer)."""
    return int.from_bytes(hashlib.sha256(motion_id.encode()).digest()[:8], "little", signed=True)


# --------------------------------------------------------------------------------------------
# the motions file, streamed


@dataclass(frozen=True)
class MotionsFile:
    """The motions of a batch: a motions file checked whole (every line a motion, ids distinct)
    and counted, read again a motion at a time (:meth:`__iter__`); or motions given in memory
    (:meth:`of`)."""

    path: Path | None
    count: int
    requests: tuple[MotionRequest, ...] = field(default=(), repr=False)

    @classmethod
    def of(cls, requests: Iterable[MotionRequest]) -> MotionsFile:
        """Motions given as records.

        Raises
        ------
        ConfigurationError
            If two have one id.
        """
        requests = tuple(requests)
        seen: set[str] = set()
        for request in requests:
            if request.id in seen:
                raise ConfigurationError(f"motion id {request.id!r} appears twice")
            seen.add(request.id)
        return cls(None, len(requests), requests)

    @classmethod
    def scan(cls, path: str | Path) -> MotionsFile:
        """Read every line once, holding 8 bytes per motion (its id's hash).

        Raises
        ------
        ConfigurationError
            As :func:`~nearopt.batch.read_requests`: a line that is not a motion, a repeated id
            (naming both lines), no motions at all.
        """
        path = Path(path).expanduser().resolve()
        hashes = []
        for _, request in iter_requests(path):
            hashes.append(_id_hash(request.id))
        if not hashes:
            raise ConfigurationError(f"{path}: no motions (one JSON object per line)")
        values = np.sort(np.array(hashes, dtype=np.int64))
        del hashes
        same = values[1:][values[1:] == values[:-1]]
        if same.size:  # a repeated id (or, once in 10¹⁰ files, two ids with one hash)
            suspects = set(same.tolist())
            seen: dict[str, int] = {}
            for number, request in iter_requests(path):
                if _id_hash(request.id) not in suspects:
                    continue
                if request.id in seen:
                    raise ConfigurationError(
                        f"{path}, line {number}: id {request.id!r} repeats line {seen[request.id]}"
                    )
                seen[request.id] = number
        return cls(path, int(values.size))

    def __iter__(self) -> Iterator[MotionRequest]:
        if self.path is None:
            yield from self.requests
            return
        for _, request in iter_requests(self.path):
            yield request


# --------------------------------------------------------------------------------------------
# a chunk, in a worker


@dataclass(frozen=True)
class Chunk:
    """Motions planned by one task; ``name`` names its shard (unique in the folder)."""

    name: str
    requests: tuple[MotionRequest, ...]


@dataclass(frozen=True)
class ChunkDone:
    """A chunk's shard written: its summary rows (:data:`SHARD_FIELDS`), the seconds its
    motions took and how many of them were planned by this call (not found in a ``.part``)."""

    name: str
    rows: tuple[tuple[str, ...], ...]
    seconds: float
    planned: int


def plan_chunk(chunk: Chunk, folder: str, rate: float, ros_bag: bool = False) -> ChunkDone:
    """Plan a chunk's motions in order and write its shard ``folder/shards/<name>.jsonl``.

    Each motion's document is appended to ``<name>.part`` as soon as it is planned (and its
    rosbag2 ``folder/bags/<id>/`` written before it); the ``.part`` is renamed when all are. A
    chunk run again after its worker died plans only the motions its ``.part`` does not hold; one
    whose shard is there already plans nothing.

    Raises
    ------
    ConfigurationError
        If the shard cannot be written (naming it): the batch stops.
    """
    shards = Path(folder) / "shards"
    final = shards / f"{chunk.name}.jsonl"
    if final.exists():  # done before: its result was lost on the way to the client
        return ChunkDone(chunk.name, tuple(read_shard(final)), 0.0, 0)
    part = shards / f"{chunk.name}.part"
    rows = read_shard(part, cut=True) if part.exists() else []
    done = {row[0] for row in rows}
    seconds, planned = 0.0, 0
    try:
        with part.open("a", encoding="utf-8") as stream:
            for request in chunk.requests:
                if request.id in done:
                    continue
                outcome = plan_request(request, rate, ros_bag=ros_bag)
                if outcome.bag is not None:
                    replace_folder(Path(folder) / "bags" / request.id, outcome.bag.files)
                stream.write(outcome.document + "\n")
                stream.flush()  # a worker killed now keeps it: the kernel holds the bytes
                digest = request_digest(outcome.fingerprint)
                rows.append(_row(outcome, digest, final.name))
                seconds += outcome.wall_time
                planned += 1
            os.fsync(stream.fileno())
        os.replace(part, final)
    except OSError as exc:
        raise ConfigurationError(f"cannot write the shard {part}: {exc.strerror or exc}") from None
    return ChunkDone(chunk.name, tuple(rows), seconds, planned)


def _row(outcome: MotionOutcome, digest: str, shard: str) -> tuple[str, ...]:
    """A motion's summary row (:data:`SHARD_FIELDS`)."""
    row = outcome.row()
    return (*(row[key] for key in SUMMARY_FIELDS), digest, shard)


def read_shard(path: Path, cut: bool = False) -> list[tuple[str, ...]]:
    """The summary rows of a shard's complete lines (a line cut short by a worker that died is
    left out; with ``cut``, also cut from the file, so that lines appended later stay lines)."""
    rows, good = [], 0
    with path.open("rb") as stream:
        for line in stream:
            try:
                document = json.loads(line) if line.endswith(b"\n") else None
            except ValueError:
                document = None
            if not isinstance(document, dict) or "id" not in document:
                break
            rows.append(_document_row(document, path.name.replace(".part", ".jsonl")))
            good += len(line)
    if cut and good < path.stat().st_size:
        os.truncate(path, good)
    return rows


def _document_row(document: dict[str, Any], shard: str) -> tuple[str, ...]:
    """The summary row of a motion's document as a shard holds it."""
    digest = request_digest(json.dumps(document.get("request"), sort_keys=True))
    outcome = MotionOutcome.from_document(document, "error" not in document)
    return _row(outcome, digest, shard)


# --------------------------------------------------------------------------------------------
# the index: summary.csv, appended


@dataclass
class ShardIndex:
    """``DIR/summary.csv`` of a sharded batch: rows appended as chunks finish, read back (a
    line at a time) by a batch that resumes.

    What it knows of the motions done before this run is held in three arrays sorted by the
    id's hash (17 bytes per motion: the id's hash, the request's, failed or not), of the last
    row of each id; rows appended in this run are written only (a batch plans each id once).

    Attributes
    ----------
    shards
        The shard files the rows read at the start name.
    """

    path: Path
    shards: set[str] = field(default_factory=set)

    def __post_init__(self) -> None:
        self._ids, self._requests, self._failed = array("q"), array("q"), array("b")
        self._keys = np.zeros(0, np.int64)
        self._digests = np.zeros(0, np.int64)
        self._failures = np.zeros(0, bool)

    @classmethod
    def open(cls, folder: Path) -> ShardIndex:
        """The index of ``folder`` (made with its header if missing; a last line cut short is
        cut from the file), with the shards no row names indexed (:meth:`_recover`).

        Raises
        ------
        ConfigurationError
            If the folder's ``summary.csv`` is not a sharded batch's.
        """
        index = cls(folder / "summary.csv")
        header = ",".join(SHARD_FIELDS) + "\n"
        if not index.path.exists():
            with index.path.open("x", encoding="utf-8") as stream:
                stream.write(header)
        good = 0
        with index.path.open("rb") as stream:
            first = stream.readline()
            if first.decode("utf-8", "replace") != header:
                raise ConfigurationError(
                    f"{index.path} is not the summary of a sharded batch (its first line is "
                    f"{first[:80]!r}): give --out another folder, or --layout files for a batch "
                    "of per-motion files"
                )
            good = len(first)
            for line in stream:
                if not line.endswith(b"\n"):
                    break
                with contextlib.suppress(ValueError, IndexError):
                    index._note(next(csv.reader([line.decode("utf-8")])))
                good += len(line)
        if good < index.path.stat().st_size:
            os.truncate(index.path, good)
        index._recover(folder / "shards")
        index._freeze()
        return index

    def _note(self, row: list[str] | tuple[str, ...]) -> None:
        self._ids.append(_id_hash(row[0]))
        self._requests.append(_hash64(row[-2]))
        self._failed.append(_failed(row))
        self.shards.add(row[-1])

    def _freeze(self) -> None:
        """The rows read as sorted arrays, the last row of each id."""
        ids = np.frombuffer(self._ids, np.int64)[::-1]  # the last row first
        keys, first = np.unique(ids, return_index=True)
        self._keys = keys
        self._digests = np.frombuffer(self._requests, np.int64)[::-1][first].copy()
        self._failures = np.frombuffer(self._failed, np.int8)[::-1][first].astype(bool)
        self._ids, self._requests, self._failed = array("q"), array("q"), array("b")

    def __len__(self) -> int:
        """Motions indexed before this run."""
        return int(self._keys.size)

    def append(self, rows: tuple[tuple[str, ...], ...] | list[tuple[str, ...]]) -> None:
        """Append rows: one ``write`` call (Ctrl-C comes before or after it, not amid the
        rows), flushed to the disk."""
        if not rows:
            return
        buffer = io.StringIO()
        csv.writer(buffer, lineterminator="\n").writerows(rows)
        data = buffer.getvalue().encode()
        fd = os.open(self.path, os.O_WRONLY | os.O_APPEND)
        try:
            written = os.write(fd, data)
            while written < len(data):  # a regular file takes all at once; if not, the rest
                written += os.write(fd, data[written:])
            os.fsync(fd)
        finally:
            os.close(fd)

    def is_done(self, request: MotionRequest, rate: float, retry_failed: bool) -> bool | None:
        """Whether the motion was done before with this very request: True (planned), None
        (failed, and not to be retried), False (to plan)."""
        key = _id_hash(request.id)
        at = int(np.searchsorted(self._keys, key))
        if at == self._keys.size or self._keys[at] != key:
            return False
        failed = bool(self._failures[at])
        if failed and retry_failed:
            return False
        if _hash64(request_digest(request.fingerprint(rate))) != self._digests[at]:
            return False
        return None if failed else True

    def _recover(self, shards: Path) -> None:
        """Index the shards (and ``.part`` files) no row names, oldest first: written by a run
        whose client stopped before it indexed them (``.part`` files are renamed as shards). A
        motion's row is added unless the index has it already with the same request and
        status."""
        known: dict[int, tuple[int, bool]] | None = None
        paths = [*shards.glob("*.part"), *shards.glob("*.jsonl")]
        for path in sorted(paths, key=lambda p: p.stem):
            name = path.name.replace(".part", ".jsonl")
            if name in self.shards or not path.exists():
                continue
            if known is None:  # only when there is a shard to recover
                known = {
                    key: (digest, bool(failed))
                    for key, digest, failed in zip(
                        self._ids, self._requests, self._failed, strict=True
                    )
                }
            rows = read_shard(path, cut=True)
            if path.suffix == ".part":
                if not rows:
                    path.unlink()
                    continue
                os.replace(path, shards / name)
            fresh = []
            for row in rows:
                key, value = _id_hash(row[0]), (_hash64(row[-2]), _failed(row))
                if known.get(key) != value:
                    fresh.append(row)
                    known[key] = value
            self.append(fresh)
            for row in fresh:
                self._note(row)


def _hash64(digest: str) -> int:
    """The first 64 bits of a hex digest, as a signed integer."""
    return int.from_bytes(bytes.fromhex(digest[:16]), "little", signed=True)


def _failed(row: tuple[str, ...] | list[str]) -> bool:
    return row[1] == str(OutcomeStatus.FAILED)


# --------------------------------------------------------------------------------------------
# the client


@dataclass
class _Chunking:
    """Chunk sizes from the time per motion measured so far."""

    workers: int
    seconds: float = 0.0
    motions: int = 0

    def size(self, left: int) -> int:
        if self.motions == 0:
            size = FIRST_CHUNK
        else:
            size = round(CHUNK_SECONDS * self.motions / max(self.seconds, 1e-9))
        # near the end, keep every worker busy rather than one with a long chunk
        size = min(size, -(-left // (IN_FLIGHT * self.workers)))
        return int(min(max(size, 1), MAX_CHUNK))

    def measured(self, done: ChunkDone) -> None:
        self.seconds += done.seconds
        self.motions += done.planned


@dataclass
class _Counts:
    total: int
    planned: int = 0
    failed: int = 0
    skipped: int = 0
    tasks: int = 0
    listed: list[MotionOutcome] = field(default_factory=list)

    def add(self, rows: tuple[tuple[str, ...], ...] | list[tuple[str, ...]]) -> None:
        for row in rows:
            if _failed(row):
                self.failed += 1
                if len(self.listed) < LISTED:
                    self.listed.append(MotionOutcome(row[0], OutcomeStatus.FAILED, error=row[6]))
            else:
                self.planned += 1


def run_sharded(
    motions: MotionsFile,
    folder: Path,
    pool: Pool,
    rate: float,
    retry_failed: bool = False,
    progress: Callable[[int, int, int, int, float], None] | None = None,
    ros_bag: bool = False,
) -> BatchSummary:
    """Plan every motion of ``motions`` not done in ``folder`` on ``pool`` (see the module's
    docstring); the summary's ``outcomes`` are the first :data:`LISTED` failures of this run."""
    t0 = time.perf_counter()
    shards = folder / "shards"
    shards.mkdir(exist_ok=True)
    with _locked(folder):
        index = ShardIndex.open(folder)
        counts = _Counts(motions.count)
        run = _Run(index, pool, motions, folder, rate, retry_failed, ros_bag, counts, progress)
        run.all()
    return BatchSummary(
        tuple(counts.listed),
        counts.skipped,
        time.perf_counter() - t0,
        total=counts.total,
        planned_count=counts.planned,
        failed_count=counts.failed,
        tasks=counts.tasks,
    )


@contextlib.contextmanager
def _locked(folder: Path) -> Iterator[None]:
    """Hold ``folder/batch.lock``: one batch at a time writes a folder."""
    path = folder / "batch.lock"
    with path.open("a+") as stream:
        try:
            fcntl.flock(stream, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            stream.seek(0)
            holder = stream.read().strip() or "another process"
            raise ConfigurationError(
                f"another nearopt batch is writing {folder} ({holder}): wait for it, or give "
                "--out another folder"
            ) from None
        stream.truncate(0)
        stream.write(f"pid {os.getpid()} on {os.uname().nodename}\n")
        stream.flush()
        yield


@dataclass
class _Run:
    """One run of a sharded batch: chunks formed from the stream, submitted, collected."""

    index: ShardIndex
    pool: Pool
    motions: MotionsFile
    folder: Path
    rate: float
    retry_failed: bool
    ros_bag: bool
    counts: _Counts
    progress: Callable[[int, int, int, int, float], None] | None
    started: float = field(default_factory=time.perf_counter)
    attempts: dict[str, int] = field(default_factory=dict)
    serial: int = 0

    def __post_init__(self) -> None:
        # unique per run: two runs of one process within a second gave the same chunk names,
        # and the second took the first's shard for its own chunk, done (a failure retried was
        # never planned again)
        self.prefix = time.strftime("%Y%m%dT%H%M%S") + f"-{os.getpid()}-{next(_RUNS):04d}"
        self.chunking = _Chunking(self.pool.workers)
        self.stream = iter(self.motions)
        self.left = self.motions.count  # motions not yet read from the stream
        self.waiting: list[MotionRequest] = []  # motions of lost chunks, to submit again

    def all(self) -> None:
        futures: dict[Any, Chunk] = {}
        try:
            while True:
                while len(futures) < IN_FLIGHT * self.pool.workers:
                    chunk = self._next_chunk()
                    if chunk is None:
                        break
                    futures[
                        self.pool.submit(
                            plan_chunk, chunk, str(self.folder), self.rate, self.ros_bag
                        )
                    ] = chunk
                    self.counts.tasks += 1
                if not futures:
                    return
                for future in self.pool.wait(futures):
                    self._collect(future, futures.pop(future))
        finally:
            self.pool.cancel(list(futures))

    def _next_chunk(self) -> Chunk | None:
        """The next motions to plan, the lost ones first; None when there are none."""
        size = self.chunking.size(self.left + len(self.waiting))
        requests = self.waiting[:size]
        del self.waiting[:size]
        while len(requests) < size:
            request = next(self.stream, None)
            if request is None:
                break
            self.left -= 1
            done = self.index.is_done(request, self.rate, self.retry_failed)
            if done is False:
                requests.append(request)
                continue
            self.counts.skipped += 1
            if done is None:
                self.counts.failed += 1
            else:
                self.counts.planned += 1
        if not requests:
            return None
        self.serial += 1
        return Chunk(f"{self.prefix}-{self.serial:06d}", tuple(requests))

    def _collect(self, future: Any, chunk: Chunk) -> None:
        """A chunk's result: its rows indexed; or, its worker lost, what it finished indexed
        and the rest planned again."""
        try:
            done = future.result()
        except NearoptError:
            raise
        except BaseException as exc:
            if not self.pool.lost(exc):
                raise
            self._lost(chunk)
        else:
            self.index.append(done.rows)
            self.counts.add(done.rows)
            self.chunking.measured(done)
        self._report()

    def _lost(self, chunk: Chunk) -> None:
        """A chunk whose worker died: index the motions its ``.part`` holds; the motion it was
        planning counts an attempt (failed at :data:`MAX_ATTEMPTS`, or at once where the pool
        retried it already); the rest wait to be submitted again."""
        shards = self.folder / "shards"
        part = shards / f"{chunk.name}.part"
        final = shards / f"{chunk.name}.jsonl"
        rows = []
        if final.exists() or part.exists():
            path = final if final.exists() else part
            rows = read_shard(path, cut=True)
            if path is part:
                os.replace(part, final) if rows else part.unlink()
        self.index.append(rows)
        self.counts.add(rows)
        finished = {row[0] for row in rows}
        rest = [r for r in chunk.requests if r.id not in finished]
        if not rest:
            return
        first = rest[0]
        self.attempts[first.id] = self.attempts.get(first.id, 0) + 1
        if self.pool.retries_lost:  # the pool ran it again itself, up to its own limit
            self.attempts[first.id] = MAX_ATTEMPTS
        if self.attempts[first.id] >= MAX_ATTEMPTS:
            self._died(first, self.attempts[first.id])
            rest = rest[1:]
        self.waiting[:0] = rest

    def _died(self, request: MotionRequest, attempts: int) -> None:
        """Record a motion whose worker died ``attempts`` times as failed, in a shard of its own."""
        outcome = worker_died(request, attempts)
        document = json.loads(outcome.document)
        fingerprint = request.fingerprint(self.rate)
        document["request"] = json.loads(fingerprint)
        self.serial += 1
        name = f"{self.prefix}-{self.serial:06d}.jsonl"
        path = self.folder / "shards" / name
        tmp = path.with_suffix(".part")
        tmp.write_text(json.dumps(document) + "\n", encoding="utf-8")
        os.replace(tmp, path)
        row = _row(outcome, request_digest(fingerprint), name)
        self.index.append([row])
        self.counts.add([row])

    def _report(self) -> None:
        if self.progress is None:
            return
        counts = self.counts
        finished = counts.planned + counts.failed
        fresh = finished - counts.skipped
        elapsed = time.perf_counter() - self.started
        left = counts.total - finished
        eta = elapsed / fresh * left if fresh else float("nan")
        self.progress(finished, counts.failed, min(self.pool.workers, left), counts.total, eta)
