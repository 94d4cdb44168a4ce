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
motion tables of any size, the shards layout (:mod:`nearopt.batch.shards`, the default above 1 000
motions) streams the motions file, sends the motions in chunks, lets the workers write the
documents into ``DIR/shards/*.jsonl`` and appends ``DIR/summary.csv``, the index a resumed run
reads.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import fields, replace
from pathlib import Path
from typing import Any

from ..api import PlanRequest
from ..errors import ConfigurationError
from ..outputs import make_folder
from ..validate import check_rate
from .files import refuse_inputs, run_files
from .motions import (
    LISTED,
    MAX_ATTEMPTS,
    SUMMARY_FIELDS,
    BatchSummary,
    Layout,
    MotionOutcome,
    MotionRequest,
    OutcomeStatus,
    iter_requests,
    plan_request,
    progress_line,
    read_requests,
    worker_died,
)
from .pools import (
    PROBE_SECONDS,
    DaskPool,
    LocalPool,
    Pool,
    check_main_guard,
    pool_for,
    pool_in_use,
    probe_scheduler,
)
from .shards import SHARD_FIELDS, SHARDS_FROM, MotionsFile, run_sharded

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
    "LISTED",
    "MAX_ATTEMPTS",
    "PROBE_SECONDS",
    "SHARD_FIELDS",
    "SHARDS_FROM",
    "MotionsFile",
    "run_sharded",
    "refuse_inputs",
    "run_files",
    "pool_for",
    "pool_in_use",
]


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
    with pool_in_use(client, workers) as pool:
        for outcome in pool.run(requests, rate, keep_result=True):
            outcomes[order[outcome.id]] = outcome
    return outcomes  # type: ignore[return-value]


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
    cluster = None if client is None or isinstance(client, Pool) else pool_for(client, workers)
    if client is None:  # this machine's pool: a script without a main guard makes nothing
        check_main_guard()
    try:
        where = client if cluster is None else cluster
        if layout == Layout.FILES:
            requests = list(motions)
            return run_files(
                requests, out, where, workers, rate, retry_failed, progress, t0, ros_bag
            )
        folder = make_folder(out, "the motions")
        refuse_inputs(folder, [], motions.path)
        with pool_in_use(where, workers) as pool:
            summary = run_sharded(motions, folder, pool, rate, retry_failed, progress, ros_bag)
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
