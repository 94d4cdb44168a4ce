"""Benchmark: motion tables at scale (#28) — ``nearopt batch --layout shards`` on 10⁴–10⁵ quick
motions, on this machine's pool and on a real Dask scheduler with two workers on 127.0.0.1.

The motions: seeded stage-1-only two-link motions (``max_iterations: 0``, grid 40; each planned,
verified and written as ``nearopt plan --json`` would, ~40 ms), the last one infeasible. For
every pool and table size the CLI runs in a child process of its own; printed: wall time,
motions per second, the client's peak resident memory and CPU time (its process only, polled
every 0.1 s),
tasks submitted, files written, and the cost per motion on the W workers (wall × W / motions)
against a bare loop of the same plans in one process (``plan_request`` on ``--bare`` motions,
no pool, no files): the overhead of the batch; and against the same loop run by as many
processes as workers side by side (the cost per motion when the cores are shared, which no pool
avoids): the batch's own overhead. Every run is checked: each
motion once in the summary and once in the shards.

    python scripts/bench_table.py [--sizes 10000 100000] [--pools local dask] [--bare 1000]
"""

from __future__ import annotations

import argparse
import csv
import json
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from pathlib import Path

import numpy as np
import psutil
from benchlib import head

BIN = Path(sys.executable).parent
WORKERS = 2


def write_motions(path: Path, count: int, seed: int = 28) -> None:
    """``count`` seeded quick motions, a line each (written as they are made)."""
    rng = np.random.default_rng(seed)
    with path.open("w") as stream:
        for k in range(count - 1):
            q0, qe = rng.uniform(-2, 2, (2, 2)).round(4).tolist()
            line = {"id": f"m{k:07d}", "robot": "two_link", "q0": q0, "qe": qe}
            stream.write(json.dumps({**line, "max_iterations": 0, "grid": 40}) + "\n")
        stream.write(json.dumps({"id": "infeasible", "robot": "two_link", "qe": [9, 0]}) + "\n")


def bare(path: Path, count: int, processes: int = 1) -> float:
    """Seconds per motion of ``plan_request`` over ``count`` motions (after 20 to warm up) in a
    child process; with ``processes`` > 1, that many at once on different motions (the wall
    time of the slowest over all their motions, times ``processes``: the cost per motion on
    as many cores, as a pool's workers see it)."""
    code = (
        "import sys, time, itertools\n"
        "from nearopt.batch import iter_requests, plan_request\n"
        "skip = int(sys.argv[1])\n"
        f"lines = itertools.islice(iter_requests({str(path)!r}), skip, skip + {count + 20})\n"
        "motions = [r for _, r in lines]\n"
        "for r in motions[:20]: plan_request(r)\n"
        "t0 = time.perf_counter()\n"
        "for r in motions[20:]: plan_request(r)\n"
        "print(time.perf_counter() - t0)\n"
    )
    children = [
        subprocess.Popen(
            [sys.executable, "-c", code, str(k * (count + 20))], stdout=subprocess.PIPE, text=True
        )
        for k in range(processes)
    ]
    walls = [float(child.communicate()[0].split()[-1]) for child in children]
    if any(child.returncode for child in children):
        raise SystemExit("the bare loop failed")
    return max(walls) / count


def run(path: Path, out: Path, where: list[str]) -> dict[str, float]:
    """``nearopt batch`` on the table: wall time, the client's peak RSS, its report."""
    command = [sys.executable, "-m", "nearopt.cli", "batch", str(path), "--out", str(out)]
    t0 = time.perf_counter()
    process = subprocess.Popen(
        [*command, "--layout", "shards", "--quiet", *where],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    peak, cpu = [0], [0.0]

    def poll() -> None:
        client = psutil.Process(process.pid)
        while process.poll() is None:
            try:
                peak[0] = max(peak[0], client.memory_info().rss)
                times = client.cpu_times()
                cpu[0] = times.user + times.system
            except psutil.Error:
                return
            time.sleep(0.1)

    watcher = threading.Thread(target=poll, daemon=True)
    watcher.start()
    stdout, stderr = process.communicate()
    wall = time.perf_counter() - t0
    watcher.join()
    if process.returncode not in (0, 1):
        raise SystemExit(f"nearopt batch failed ({process.returncode}):\n{stderr[-2000:]}")
    tasks = int(stdout.split(" tasks)")[0].rsplit(", ", 1)[-1])
    return {"wall": wall, "rss": peak[0] / 2**20, "tasks": tasks, "cpu": cpu[0]}


def check(out: Path, count: int) -> int:
    """Each motion once in the summary and in the shards; the files written."""
    with (out / "summary.csv").open() as stream:
        ids = Counter(row["id"] for row in csv.DictReader(stream))
    lines = sum(p.read_bytes().count(b"\n") for p in (out / "shards").glob("*.jsonl"))
    if len(ids) != count or max(ids.values()) != 1 or lines != count:
        raise SystemExit(f"{out}: {len(ids)} ids, {lines} shard lines, {count} motions")
    return sum(1 for p in out.rglob("*") if p.is_file())


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_dask(folder: Path) -> tuple[str, list[subprocess.Popen]]:
    """A scheduler and two single-threaded workers on 127.0.0.1."""
    address = f"tcp://127.0.0.1:{free_port()}"
    port = address.rsplit(":", 1)[1]
    log = (folder / "dask.log").open("w")
    scheduler = [str(BIN / "dask"), "scheduler", "--host", "127.0.0.1", "--port", port]
    processes = [subprocess.Popen([*scheduler, "--no-dashboard"], stdout=log, stderr=log)]
    worker = [str(BIN / "dask"), "worker", address, "--nthreads", "1", "--nworkers", "1"]
    for _ in range(WORKERS):
        processes.append(
            subprocess.Popen(
                [*worker, "--no-dashboard", "--host", "127.0.0.1"], stdout=log, stderr=log
            )
        )
    import distributed

    with distributed.Client(address, timeout=60) as client:
        client.wait_for_workers(WORKERS, timeout=120)
    return address, processes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[10_000, 100_000])
    parser.add_argument("--pools", nargs="+", default=["local", "dask"], choices=["local", "dask"])
    parser.add_argument("--bare", type=int, default=1000)
    args = parser.parse_args()
    print(f"nearopt {head()}, {WORKERS} workers, quick two-link motions (stage 1, verified)")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        tables = {}
        for size in args.sizes:
            tables[size] = folder / f"motions-{size}.jsonl"
            write_motions(tables[size], size)
        per_motion = bare(tables[max(args.sizes)], args.bare)
        side_by_side = bare(tables[max(args.sizes)], args.bare, WORKERS)
        print(
            f"bare loop, one process: {per_motion * 1e3:.2f} ms per motion ({args.bare} motions); "
            f"{WORKERS} processes side by side: {side_by_side * 1e3:.2f} ms per motion per core "
            f"({side_by_side / per_motion - 1:+.1%}: the cores' own scaling)"
        )
        print(
            f"\n{'pool':6} {'motions':>8} {'wall [s]':>9} {'motions/s':>10} {'client RSS':>11} "
            f"{'client CPU':>10} {'tasks':>6} {'files':>6} {'per motion':>11} {'overhead':>9} "
            f"{'vs side by side':>15}"
        )
        for pool in args.pools:
            processes: list[subprocess.Popen] = []
            where = ["--workers", str(WORKERS)]
            if pool == "dask":
                address, processes = start_dask(folder)
                where = ["--scheduler", address]
            try:
                for size in args.sizes:
                    out = folder / f"out-{pool}-{size}"
                    result = run(tables[size], out, where)
                    files = check(out, size)
                    cost = result["wall"] * WORKERS / size
                    wall, rss, cpu, tasks = (result[k] for k in ("wall", "rss", "cpu", "tasks"))
                    print(
                        f"{pool:6} {size:8d} {wall:9.1f} {size / wall:10.1f} {rss:8.0f} MB "
                        f"{cpu:8.1f} s {tasks:6.0f} {files:6d} {cost * 1e3:8.2f} ms "
                        f"{cost / per_motion - 1:+9.1%} {cost / side_by_side - 1:+15.1%}",
                        flush=True,
                    )
            finally:
                for process in processes[::-1]:
                    process.terminate()
                for process in processes:
                    process.wait(timeout=30)


if __name__ == "__main__":
    main()
