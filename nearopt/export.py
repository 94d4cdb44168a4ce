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
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .errors import ConfigurationError

if TYPE_CHECKING:
    from .planner import PlanResult

__all__ = ["check_writable", "write_atomically", "write_json", "write_csv", "KEYS"]

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


def write_atomically(path: str | Path, text: str) -> Path:
    """Write ``text`` to ``path`` via a temporary file in the same folder and a rename."""
    path = check_writable(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="") as handle:
            handle.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def write_json(result: PlanResult, path: str | Path, rate: float = 1000.0) -> Path:
    """The plan as ``{"robot", "joint_names", "cost", "J", "duration", "t", "q", "qd", "qdd",
    "tau", "history": [{"J", "alpha"}, …]}`` (lists of per-sample lists)."""
    samples = result.trajectory.sample(rate)
    document = {
        "robot": result.robot.name,
        "joint_names": list(result.robot.joint_names),
        "cost": result.cost.describe(),
        "J": result.J,
        "duration": result.duration,
        "t": samples["t"].tolist(),
        **{key: samples[key].tolist() for key in KEYS},
        "history": [{"J": it.J, "alpha": it.alpha} for it in result.history],
    }
    return write_atomically(path, json.dumps(document))


def write_csv(result: PlanResult, path: str | Path, rate: float = 1000.0) -> Path:
    """The plan's samples as CSV: a header row ``t, q_<joint>…, qd_<joint>…, qdd_…, tau_…``."""
    samples = result.trajectory.sample(rate)
    names = result.robot.joint_names
    header = ["t"] + [f"{key}_{name}" for key in KEYS for name in names]
    rows = np.column_stack([samples["t"], *(samples[key] for key in KEYS)])
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(header)
    writer.writerows([repr(float(x)) for x in row] for row in rows)
    return write_atomically(path, buffer.getvalue())
