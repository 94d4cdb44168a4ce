"""A planned motion as files: JSON and CSV samples at a controller rate, written atomically.

Both hold the same samples, t from 0 to t_e inclusive at ``rate`` Hz (the last step shorter), of
θ [rad], θ̇ [rad/s], θ̈ [rad/s²] and u [N·m] (prismatic joints: m, m/s, m/s², N). A file is written
through a temporary file in the same folder and renamed, so a failure leaves no partial file.
"""

from __future__ import annotations

import csv
import io
import json
import os
import tempfile
import warnings
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .errors import ConfigurationError, SamplingWarning

if TYPE_CHECKING:
    from .planning import PlanResult

__all__ = [
    "check_sampling",
    "check_writable",
    "write_all",
    "write_atomically",
    "json_text",
    "csv_text",
    "write_json",
    "write_csv",
    "KEYS",
]

KEYS = ("q", "qd", "qdd", "tau")


def check_writable(target: str | Path) -> Path:
    """The path, if a file can be written there; otherwise a ConfigurationError saying why."""
    path = Path(target).expanduser()
    folder = path.parent
    if path.is_dir():
        raise ConfigurationError(f"cannot write {target}: it is a directory")
    if not folder.is_dir():
        raise ConfigurationError(f"cannot write {target}: folder {folder} does not exist")
    if not os.access(folder, os.W_OK) or (path.exists() and not os.access(path, os.W_OK)):
        raise ConfigurationError(f"cannot write {target}: permission denied")
    return path


def write_all(contents: dict[Path, str | bytes]) -> list[Path]:
    """Write several files all or nothing: each to a temporary file in its folder first, then
    all renamed; if any temporary file cannot be written, none of the files is touched."""
    staged: list[tuple[str, Path]] = []
    umask = os.umask(0)
    os.umask(umask)
    try:
        for path, content in contents.items():
            path = check_writable(path)
            try:
                fd, tmp = tempfile.mkstemp(
                    dir=path.parent, prefix=f".{path.name}.", suffix=".tmp"
                )
                staged.append((tmp, path))
                with os.fdopen(fd, "wb") as handle:
                    handle.write(content.encode("utf-8") if isinstance(content, str) else content)
                os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; a new file gets the usual mode
            except OSError as exc:
                raise ConfigurationError(f"cannot write {path}: {exc.strerror or exc}") from exc
    except BaseException:
        for tmp, _ in staged:
            Path(tmp).unlink(missing_ok=True)
        raise
    for tmp, path in staged:
        os.replace(tmp, path)
    return [path for _, path in staged]


def write_atomically(path: str | Path, content: str | bytes) -> Path:
    """Write ``content`` (text as UTF-8, or bytes) to ``path`` via a temporary file, renamed."""
    return write_all({Path(path): content})[0]


def check_sampling(result: PlanResult, rate: float) -> str | None:
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


def json_text(result: PlanResult, rate: float = 1000.0) -> str:
    """The plan as ``{"robot", "joint_names", "cost", "J", "duration", "t", "q", "qd", "qdd",
    "tau", "history": [{"J", "alpha"}, …]}`` (lists of per-sample lists).

    Warns (:class:`~nearopt.SamplingWarning`) if the rate is too low to resolve the motion.
    """
    check_sampling(result, rate)
    samples = result.trajectory.sample(rate)
    document = {
        "robot": result.robot.name,
        "joint_names": list(result.robot.joint_names),
        "cost": result.cost.describe(),
        "J": result.J,
        "duration": result.duration,
        "t": samples.t.tolist(),
        **{key: getattr(samples, key).tolist() for key in KEYS},
        "history": [{"J": it.J, "alpha": it.alpha} for it in result.history],
    }
    return json.dumps(document)


def csv_text(result: PlanResult, rate: float = 1000.0) -> str:
    """The plan's samples as CSV: a header row ``t, q_<joint>…, qd_<joint>…, qdd_…, tau_…``.

    Warns (:class:`~nearopt.SamplingWarning`) if the rate is too low to resolve the motion.
    """
    check_sampling(result, rate)
    samples = result.trajectory.sample(rate)
    names = result.robot.joint_names
    header = ["t"] + [f"{key}_{name}" for key in KEYS for name in names]
    rows = np.column_stack([samples.t, *(getattr(samples, key) for key in KEYS)])
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(header)
    writer.writerows([repr(float(x)) for x in row] for row in rows)
    return buffer.getvalue()


def write_json(result: PlanResult, path: str | Path, rate: float = 1000.0) -> Path:
    """Write :func:`json_text` to ``path`` (atomically)."""
    return write_atomically(path, json_text(result, rate))


def write_csv(result: PlanResult, path: str | Path, rate: float = 1000.0) -> Path:
    """Write :func:`csv_text` to ``path`` (atomically)."""
    return write_atomically(path, csv_text(result, rate))
