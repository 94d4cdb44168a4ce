"""Benchmark: many motions (#13) — throughput against the number of local workers, and Dask.

A seeded motion table over two_link, ur5 and panda (f0 = 1 + 0.001 Σu², the planner's defaults,
each motion verified as ``nearopt plan`` does) is planned by ``run_batch`` on this machine's
process pool with 1 and 2 workers, and on a dask.distributed scheduler with two single-threaded
workers started here on 127.0.0.1. Printed: wall time, motions per minute, speed-up against one
worker; and the overhead per task of each pool (no-op tasks round-tripped).

With ``--baseline REV`` the same table is first planned by an earlier commit (its ``nearopt/``
from git archive, run by this script in a child process) and the rates compared.

    python scripts/bench_batch.py [--motions 30] [--baseline 5c1e9b0]
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import multiprocessing
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from benchlib import head, run_with, unpack

import nearopt
from nearopt.batch import LocalPool, MotionRequest, run_batch

BIN = Path(sys.executable).parent


def table(count: int, seed: int = 13) -> list[MotionRequest]:
    rng = np.random.default_rng(seed)
    arms = ["two_link", "ur5", "panda"]
    robots = {name: nearopt.Robot.from_name(name) for name in arms}
    out = []
    for k in range(count):
        robot = robots[arms[k % 3]]
        lo = np.maximum(robot.limits.position_lower, -np.pi)
        hi = np.minimum(robot.limits.position_upper, np.pi)
        mid, half = 0.5 * (lo + hi), 0.3 * (hi - lo)
        q0, qe = rng.uniform(mid - half, mid + half, (2, robot.n))
        out.append(
            MotionRequest(
                f"m{k:03d}",
                {"robot": robot.name, "q0": q0.tolist(), "qe": qe.tolist(), "beta": 0.001},
            )
        )
    return out


def noop(x: int) -> int:
    return x


def overhead(submit_all: object, tasks: int = 400) -> float:
    t0 = time.perf_counter()
    submit_all(tasks)  # type: ignore[operator]
    return (time.perf_counter() - t0) / tasks


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--motions", type=int, default=30)
    parser.add_argument(
        "--baseline", help="an earlier commit, run first (the same table) and compared"
    )
    args = parser.parse_args()
    if args.baseline:
        with tempfile.TemporaryDirectory() as tmp:
            before = run_with(
                unpack(args.baseline, Path(tmp)), __file__, "--motions", str(args.motions)
            )
        print(f"{args.baseline}:\n{before}\nthis checkout ({head()}):")
    rates = measure(args.motions)
    if args.baseline:
        print("\nmotions/min against " + args.baseline + ":")
        for line in before.splitlines():
            label = line[:26].strip()
            if label in rates:
                old = float(line.split()[-3])
                print(f"  {label:24} {old:8.1f} → {rates[label]:8.1f}  ({rates[label] / old:.2f}×)")


def measure(count: int) -> dict[str, float]:
    """The table planned on each pool (printed); motions/min by pool."""
    rates: dict[str, float] = {}
    requests = table(count)
    print(f"{len(requests)} motions (two_link, ur5, panda; planner defaults, verified)")
    print(f"{'pool':26} {'wall [s]':>9} {'motions/min':>12} {'speed-up':>9} {'failed':>7}")
    rows = []
    base = None
    for workers in (1, 2):
        with tempfile.TemporaryDirectory() as out, LocalPool(workers) as pool:
            t0 = time.perf_counter()
            result = run_batch(requests, out, pool)
            wall = time.perf_counter() - t0
        base = base or wall
        rows.append((f"local, {workers} worker(s)", wall, result.failed))
        rates[rows[-1][0]] = 60 * len(requests) / wall
        print(
            f"{rows[-1][0]:26} {wall:9.1f} {60 * len(requests) / wall:12.1f} "
            f"{base / wall:9.2f} {result.failed:7d}",
            flush=True,
        )
    import distributed

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    address = f"tcp://127.0.0.1:{port}"
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
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
    ]
    try:
        for _ in range(2):
            processes.append(
                subprocess.Popen(
                    [
                        str(BIN / "dask"),
                        "worker",
                        address,
                        "--nthreads",
                        "1",
                        "--no-dashboard",
                        "--host",
                        "127.0.0.1",
                    ],
                    stdout=subprocess.DEVNULL,
                    stderr=subprocess.DEVNULL,
                )
            )
        client = distributed.Client(address, timeout=60)
        client.wait_for_workers(2, timeout=120)
        client.run(lambda: __import__("nearopt.cli"))  # both workers import nearopt first
        with tempfile.TemporaryDirectory() as out:
            t0 = time.perf_counter()
            result = run_batch(requests, out, client)
            wall = time.perf_counter() - t0
        rates["dask, 2 workers"] = 60 * len(requests) / wall
        print(
            f"{'dask, 2 workers':26} {wall:9.1f} {60 * len(requests) / wall:12.1f} "
            f"{base / wall:9.2f} {result.failed:7d}",
            flush=True,
        )
        dask_overhead = overhead(
            lambda n: client.gather([client.submit(noop, k, pure=False) for k in range(n)])
        )
        client.close()
    finally:
        for p in processes[::-1]:
            p.terminate()
            p.wait()
    with cf.ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("spawn")) as ex:
        list(ex.map(noop, range(4)))  # started
        local_overhead = overhead(lambda n: list(ex.map(noop, range(n))))
    print(
        f"\noverhead per task (no-op tasks, 2 workers): dask {dask_overhead * 1e3:.2f} ms, "
        f"local process pool {local_overhead * 1e3:.2f} ms"
    )
    return rates


if __name__ == "__main__":
    main()
