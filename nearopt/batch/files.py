"""The files layout of a batch: ``DIR/<id>.json`` per motion, written by the client, and
``DIR/summary.csv`` in request order, rewritten as results arrive."""

from __future__ import annotations

import csv
import io
import json
import os
import shutil
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from ..api import FILE_FIELDS
from ..errors import ConfigurationError
from ..outputs import make_folder, resolve_output, write_atomically, write_outputs
from ..ros import check_bag_folder, replace_folder

if TYPE_CHECKING:
    pass

from .motions import (
    SUMMARY_FIELDS,
    BatchSummary,
    MotionOutcome,
    MotionRequest,
    OutcomeStatus,
)
from .pools import (
    pool_in_use,
)


def run_files(
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
    refuse_inputs(folder, requests)
    refuse_foreign(folder, requests)
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
        with pool_in_use(client, workers) as pool:
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
    return BatchSummary(
        tuple(outcomes[r.id] for r in requests if r.id in outcomes),
        skipped,
        time.perf_counter() - t0,
        tasks=len(todo),  # a motion each
    )


def _light(outcome: MotionOutcome) -> MotionOutcome:
    """The outcome without its document and plan (kept for the summary)."""
    return replace(outcome, document="", result=None, bag=None)


def refuse_inputs(folder: Path, requests: list[MotionRequest], source: Path | None = None) -> None:
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


def refuse_foreign(folder: Path, requests: Sequence[MotionRequest]) -> None:
    """A ConfigurationError naming the first file the batch would replace that no batch wrote:
    ``summary.csv`` not headed by :data:`SUMMARY_FIELDS`, ``bags/<id>`` that is not a bag
    (:func:`~nearopt.ros.check_bag_folder`); a motion's own files are checked as they are read
    (:func:`_done`). Files an earlier run wrote are replaced or resumed from; anything else in
    the folder is left alone."""
    summary = folder / "summary.csv"
    if summary.exists():
        try:
            first = summary.read_text(encoding="utf-8").split("\n", 1)[0]
        except (OSError, UnicodeDecodeError):
            first = None
        if first != ",".join(SUMMARY_FIELDS):
            raise ConfigurationError(
                f"{summary} is not a batch's summary: the batch would replace it; give --out a "
                "folder of its own"
            )
    for request in requests:
        check_bag_folder(folder / "bags" / request.id)


def _file(folder: Path, motion_id: str, planned: bool) -> Path:
    """Where a motion's outcome is written: DIR/<id>.json, or DIR/failed/<id>.json."""
    return folder / f"{motion_id}.json" if planned else folder / "failed" / f"{motion_id}.json"


def _done(
    folder: Path, request: MotionRequest, retry_failed: bool, rate: float
) -> MotionOutcome | None:
    """The outcome an earlier run wrote for the same request, or None; a ConfigurationError
    where the motion's file is not a motion's outcome (a JSON object with its ``request``: a
    file no batch wrote, which the batch would replace)."""
    wanted = json.loads(request.fingerprint(rate))
    done = None
    for planned in (True, False):
        path = _file(folder, request.id, planned)
        if not path.exists():
            continue
        try:
            document = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            document = None
        if not isinstance(document, dict) or "request" not in document:
            raise ConfigurationError(
                f"{path} is not the outcome of a motion: the batch would replace it (motion "
                f"{request.id!r}); give --out a folder of its own"
            )
        if done is None and document["request"] == wanted and (planned or not retry_failed):
            done = MotionOutcome.from_document({**document, "id": request.id}, planned)
    return done


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
