"""Shared fixtures: every arm nearopt knows, loaded once per session, with readable ids."""

from __future__ import annotations

import functools
import socket
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

import nearopt

ROBOT_NAMES = nearopt.available_robots()
BIN = Path(sys.executable).parent


@functools.cache
def load(name: str) -> nearopt.Robot:
    """Load a known robot once per test session (a Robot is immutable)."""
    return nearopt.Robot.from_name(name)


@pytest.fixture(params=ROBOT_NAMES, ids=ROBOT_NAMES)
def robot(request: pytest.FixtureRequest) -> nearopt.Robot:
    """Each known arm in turn: the bundled ones and those of example-robot-data."""
    return load(request.param)


@pytest.fixture
def rng() -> np.random.Generator:
    """A seeded generator, so that every random test is reproducible."""
    return np.random.default_rng(20261122)


def random_configuration(robot: nearopt.Robot, rng: np.random.Generator) -> np.ndarray:
    """A configuration drawn uniformly within the position limits (±π where there are none)."""
    lo = np.maximum(robot.limits.position_lower, -np.pi)
    hi = np.minimum(robot.limits.position_upper, np.pi)
    return rng.uniform(lo, hi)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict]:
    """A dask scheduler and two single-threaded workers (with nannies) on 127.0.0.1."""
    distributed = pytest.importorskip("distributed")
    folder = tmp_path_factory.mktemp("dask")
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    logs = [open(folder / f"{name}.log", "w") for name in ("scheduler", "w1", "w2")]  # noqa: SIM115
    processes = [
        subprocess.Popen(
            [
                str(BIN / "dask"),
                "scheduler",
                "--host",
                "127.0.0.1",
                "--port",
                str(port),
                "--no-dashboard",
            ],
            stdout=logs[0],
            stderr=subprocess.STDOUT,
            cwd=folder,
        )
    ]
    try:
        for log in logs[1:]:
            processes.append(
                subprocess.Popen(
                    [
                        str(BIN / "dask"),
                        "worker",
                        address,
                        "--nthreads",
                        "1",
                        "--nworkers",
                        "1",
                        "--no-dashboard",
                        "--host",
                        "127.0.0.1",
                    ],
                    stdout=log,
                    stderr=subprocess.STDOUT,
                    cwd=folder,
                )
            )
        client = distributed.Client(address, timeout=60)
        client.wait_for_workers(2, timeout=120)
        yield {"address": address, "client": client, "workers": processes[1:]}
        client.close()
    finally:
        for process in processes[::-1]:
            process.terminate()
        for process in processes:
            try:
                process.wait(timeout=20)
            except subprocess.TimeoutExpired:
                process.kill()
        for log in logs:
            log.close()
