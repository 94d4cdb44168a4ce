"""A planned motion as files: JSON and CSV samples at a controller rate, written atomically.

Both hold the same samples, t from 0 to t_e inclusive at ``rate`` Hz (the last step shorter), of
θ [rad], θ̇ [rad/s], θ̈ [rad/s²] and u [N·m] (prismatic joints: m, m/s, m/s², N). Files are written
by :mod:`nearopt.outputs` (atomically; links followed; devices and FIFOs as streams).
"""

from __future__ import annotations

import csv
import io
import json
import warnings
from pathlib import Path

import numpy as np

from .errors import ConfigurationError, SamplingWarning
from .outputs import write_atomically
from .planning import Plan, TaskResult
from .robot.kinematics import ToolPose
from .validate import check_rate

__all__ = [
    "MAX_VALUES",
    "check_record",
    "check_sampling",
    "json_text",
    "csv_text",
    "write_json",
    "write_csv",
    "KEYS",
]

KEYS = ("q", "qd", "qdd", "tau")

MAX_VALUES = 10_000_000
"""The most numbers a JSON or CSV record holds (t and θ, θ̇, θ̈, u of every joint per sample):
about 200 MB of text and 1 GB of memory while it is made. A longer record is refused before
anything is sampled (:func:`check_record`)."""


def check_record(result: Plan, rate: float) -> int:
    """The number of samples of ``result`` at ``rate`` [Hz]; refused if the record would hold
    more than :data:`MAX_VALUES` numbers.

    Raises
    ------
    ConfigurationError
        Saying the duration, the samples and the highest rate within the cap; a rate that is
        not a positive finite number up to :data:`~nearopt.validate.MAX_RATE`.
    """
    rate = check_rate(rate)
    duration, n = result.duration, result.robot.n
    samples = int(np.floor(duration * rate + 1e-9)) + 2
    per_sample = 1 + len(KEYS) * n
    if samples * per_sample <= MAX_VALUES:
        return samples
    highest = (MAX_VALUES // per_sample - 2) / max(duration, 1e-300)
    raise ConfigurationError(
        f"the motion lasts {duration:.6g} s: its record at {rate:g} Hz would hold {samples:,} "
        f"samples of {per_sample} numbers, more than the {MAX_VALUES:,} numbers a JSON or CSV "
        f"record holds (about 200 MB); ask for a rate of at most {highest:.4g} Hz (--rate)"
    )


def check_sampling(result: Plan, rate: float) -> str | None:
    """A warning (also issued as :class:`~nearopt.SamplingWarning`) if samples at ``rate`` [Hz]
    can miss a constant-acceleration phase of the motion, else None."""
    faithful = result.trajectory.faithful_rate()
    if rate >= faithful:
        return None
    message = (
        f"the motion has a constant-acceleration phase of {1e3 / faithful:.3g} ms, shorter than "
        f"one sample period at {rate:g} Hz: the samples are not a faithful record of it (sample at "
        f"≥ {faithful:.4g} Hz, or limit the joint accelerations)"
    )
    warnings.warn(message, SamplingWarning, stacklevel=3)
    return message


def json_text(result: Plan, rate: float = 1000.0, extra: dict[str, object] | None = None) -> str:
    """The plan as ``{"robot", "joint_names", "cost", "J", "duration", "t", "q", "qd", "qdd",
    "tau", "history": [{"J", "alpha"}, …]}`` (lists of per-sample lists), ``"via": [{"t",
    "q"}, …]`` when the motion passes via-points, and ``"duration_asked": {"seconds",
    "exact"}`` when its duration was set (t_e = seconds, or at most that), ``"qd0"`` and
    ``"qde"`` (the joint velocities asked for at the ends) when it starts or ends moving.

    A task (:class:`~nearopt.TaskResult`) has, instead of ``"history"`` and ``"via"``,
    ``"targets": [{"name", "t", "q", "stop", "pose", "frame", "velocity", "window"}, …]``
    (``"pose"``: position and quaternion (x, y, z, w), and the frame it places; null for a joint
    target; ``"velocity"`` [rad/s] and ``"window"`` [s] as asked, null where not, a window's
    open end null) and
    ``"segments": [{"t_start", "t_end", "J", "status", "targets", "history"}, …]``: the
    pieces, whose boundaries are the targets stopped at or passed at a velocity.

    ``extra`` keys come first (a batch's ``"id"``, ``"request"`` and ``"batch"`` record).

    Warns (:class:`~nearopt.SamplingWarning`) if the rate is too low to resolve the motion;
    refuses a record longer than :data:`MAX_VALUES` numbers (:func:`check_record`).
    """
    check_record(result, rate)
    check_sampling(result, rate)
    samples = result.trajectory.sample(rate)
    document: dict[str, object] = {
        **(extra or {}),
        "robot": result.robot.name,
        "joint_names": list(result.robot.joint_names),
        "cost": result.cost.describe(),
        "J": result.J,
        "duration": result.duration,
        **{key: _Spliced(key) for key in ("t", *KEYS)},  # the samples: see _dumps
    }
    segments = result.segments if isinstance(result, TaskResult) else None
    if segments is None:
        document["history"] = [{"J": it.J, "alpha": it.alpha} for it in result.history]
        asked = getattr(result, "duration_asked", None)
        if asked is not None:
            document["duration_asked"] = {"seconds": asked[0], "exact": asked[1]}
        for key in ("qd0", "qde"):
            value = getattr(result, key, None)
            if value is not None:
                document[key] = [float(v) for v in value]
        if result.via:  # where the motion passes its via-points
            document["via"] = [
                {"t": float(t), "q": q.tolist()}
                for t, q in zip(result.via_times, result.via, strict=True)
            ]
        return _dumps(document, samples)
    document["targets"] = [
        {
            "name": target.name,
            "t": float(t),
            "q": q.tolist(),
            "stop": target.stop,
            "pose": _pose(target.goal),
            "frame": (target.goal.frame or result.robot.tip)
            if isinstance(target.goal, ToolPose)
            else None,
            "velocity": None
            if target.velocity is None
            else np.asarray(target.velocity, dtype=float).tolist(),
            "window": None  # an open end (inf): null
            if target.window is None
            else [float(w) if np.isfinite(w) else None for w in target.window],
        }
        for target, t, q in zip(
            result.targets, result.target_times, result.target_configurations, strict=True
        )
    ]
    document["segments"] = [
        {
            "t_start": float(t0),
            "t_end": float(t0 + seg.duration),
            "J": seg.J,
            "status": str(seg.status),
            "targets": [t.name for t in reached],
            "history": [{"J": it.J, "alpha": it.alpha} for it in seg.history],
        }
        for t0, seg, reached in zip(
            result.trajectory.starts, segments, result.segment_targets, strict=True
        )
    ]
    return _dumps(document, samples)


class _Spliced(str):
    """The place of a sample array in a document (see :func:`_dumps`)."""

    __slots__ = ()

    def __new__(cls, key: str) -> _Spliced:
        return super().__new__(cls, f"\x00{key}\x00")


def _dumps(document: dict[str, object], samples: object, chunk: int = 65536) -> str:
    """``json.dumps(document)`` with the sample arrays in the places marked by
    :class:`_Spliced`, the same text as with their lists in place, made a chunk of samples at a
    time: the whole record's Python floats never exist at once (a record of
    :data:`MAX_VALUES` numbers takes ~0.6 GB instead of ~1.4 GB)."""
    rest = json.dumps(document)
    pieces: list[str] = []
    for key in ("t", *KEYS):  # in the document's order
        head, rest = rest.split(json.dumps(_Spliced(key)), 1)
        values = getattr(samples, key)
        chunks = [
            json.dumps(values[i : i + chunk].tolist())[1:-1] for i in range(0, len(values), chunk)
        ]
        pieces += [head, "[", ", ".join(chunks), "]"]
    return "".join([*pieces, rest])


def _pose(goal: object) -> list[float] | None:
    """A tool pose as [x, y, z] or [x, y, z, qx, qy, qz, qw]; None for a joint vector."""
    if not isinstance(goal, ToolPose):
        return None
    return [float(x) for x in (*goal.position, *(goal.quaternion or ()))]


def csv_text(result: Plan, rate: float = 1000.0) -> str:
    """The plan's samples as CSV: a header row ``t, q_<joint>…, qd_<joint>…, qdd_…, tau_…``;
    a task's has a last column ``segment`` (1, 2, …: the rest-to-rest piece a sample belongs
    to; a sample on a stop belongs to the piece that starts there, the last to the last).

    Warns (:class:`~nearopt.SamplingWarning`) if the rate is too low to resolve the motion;
    refuses a record longer than :data:`MAX_VALUES` numbers (:func:`check_record`).
    """
    check_record(result, rate)
    check_sampling(result, rate)
    samples = result.trajectory.sample(rate)
    names = result.robot.joint_names
    header = ["t"] + [f"{key}_{name}" for key in KEYS for name in names]
    rows = np.column_stack([samples.t, *(getattr(samples, key) for key in KEYS)])
    segments = result.segments if isinstance(result, TaskResult) else None
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    if segments is None:
        writer.writerow(header)
        writer.writerows([repr(float(x)) for x in row] for row in rows)
    else:
        part = result.trajectory.part_at(samples.t) + 1
        writer.writerow([*header, "segment"])
        writer.writerows(
            [*(repr(float(x)) for x in row), str(k)] for row, k in zip(rows, part, strict=True)
        )
    return buffer.getvalue()


def write_json(result: Plan, path: str | Path, rate: float = 1000.0) -> Path:
    """Write :func:`json_text` to ``path`` (atomically)."""
    return write_atomically(path, json_text(result, rate))


def write_csv(result: Plan, path: str | Path, rate: float = 1000.0) -> Path:
    """Write :func:`csv_text` to ``path`` (atomically)."""
    return write_atomically(path, csv_text(result, rate))
