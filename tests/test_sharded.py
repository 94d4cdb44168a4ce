"""Motion tables at scale (#28): ``nearopt batch --layout shards`` — chunks sized from the time
per motion, shards written by the workers, the summary appended and read back as the index;
killed workers and interrupted clients lose nothing and plan nothing twice, on this machine's
pool and on a real Dask scheduler with two workers on 127.0.0.1."""

from __future__ import annotations

import csv
import fcntl
import io
import json
import os
import signal
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from nearopt.batch import Layout, LocalPool, MotionRequest, progress_line, run_batch
from nearopt.batch.shards import (
    CHUNK_SECONDS,
    SHARD_FIELDS,
    Chunk,
    ChunkDone,
    MotionsFile,
    ShardIndex,
    _Chunking,
    plan_chunk,
    read_shard,
)
from nearopt.errors import ConfigurationError


def quick_motions(count: int, seed: int = 1, **options: object) -> list[dict]:
    """Seeded stage-1-only motions of the two-link arm (~40 ms each, verified), the last one
    out of the position limits (it fails)."""
    rng = np.random.default_rng(seed)
    out = [
        {
            "id": f"q{k:05d}",
            "robot": "two_link",
            "q0": rng.uniform(-2, 2, 2).round(4).tolist(),
            "qe": rng.uniform(-2, 2, 2).round(4).tolist(),
            "max_iterations": 0,
            "grid": 40,
            **options,
        }
        for k in range(count - 1)
    ]
    out.append({"id": "out-of-range", "robot": "two_link", "q0": [0, 0], "qe": [9.0, 0]})
    return out


def write(folder: Path, records: list[dict]) -> Path:
    path = folder / "motions.jsonl"
    path.write_text("\n".join(json.dumps(r) for r in records) + "\n")
    return path


def rows(folder: Path) -> list[dict[str, str]]:
    with (folder / "summary.csv").open() as stream:
        return list(csv.DictReader(stream))


def documents(folder: Path) -> list[dict]:
    """Every document of every shard (a motion twice would be listed twice)."""
    out = []
    for shard in sorted((folder / "shards").glob("*.jsonl")):
        out += [json.loads(line) for line in shard.read_text().splitlines()]
    return out


def cli(*args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "nearopt.cli", "batch", *args, "--quiet"],
        capture_output=True,
        text=True,
        timeout=timeout,
    )


@pytest.fixture(scope="module")
def table(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, list[dict]]:
    """60 motions planned in shards by the CLI on two local workers."""
    folder = tmp_path_factory.mktemp("table")
    records = quick_motions(60)
    tasks = write(folder, records)
    run = cli(str(tasks), "--out", str(folder / "out"), "--layout", "shards", "--workers", "2")
    assert run.returncode == 1, run.stderr  # the motion out of range failed
    assert "60 motions: 59 planned, 1 failed" in run.stdout
    assert "out-of-range: ConfigurationError: qe[0] = 9 rad" in run.stderr
    return tasks, folder / "out", records


def test_every_motion_is_in_one_shard_once_and_in_the_index(table: tuple) -> None:
    _, out, records = table
    docs = documents(out)
    assert sorted(d["id"] for d in docs) == sorted(r["id"] for r in records)
    table_rows = rows(out)
    assert tuple(table_rows[0]) == SHARD_FIELDS
    assert Counter(r["id"] for r in table_rows) == Counter(r["id"] for r in records)
    by_id = {d["id"]: d for d in docs}
    for row in table_rows:
        doc = by_id[row["id"]]
        assert (out / "shards" / row["shard"]).is_file()
        assert row["shard"] in {p.name for p in (out / "shards").glob("*.jsonl")}
        if row["status"] == "failed":
            assert row["error"] == doc["error"]
        else:
            assert float(row["J"]) == doc["J"] and float(row["te"]) == doc["duration"]
    assert not list(out.glob("shards/*.part")), "every chunk finished: no .part is left"


def test_a_shard_holds_what_the_files_layout_writes(table: tuple, tmp_path: Path) -> None:
    """The same motions in the files layout: the same documents, but for the wall times."""
    tasks, out, records = table
    chosen = [records[0], records[7], records[-1]]
    files = tmp_path / "files"
    summary = run_batch(
        [MotionRequest.from_dict(r, r["id"]) for r in chosen], files, workers=1, layout="files"
    )
    assert summary.layout == Layout.FILES and summary.failed == 1
    by_id = {d["id"]: d for d in documents(out)}
    for record in chosen[:2]:
        mine = json.loads((files / f"{record['id']}.json").read_text())
        theirs = by_id[record["id"]]
        for key in ("request", "J", "duration", "t", "q", "qd", "qdd", "tau", "history"):
            assert mine[key] == theirs[key], key


def test_a_resumed_batch_reads_the_index_not_the_shards(table: tuple, tmp_path: Path) -> None:
    """Run again: every motion is found done from summary.csv alone (the shards' contents
    replaced by garbage are never read); a changed motion is planned again and indexed anew."""
    tasks, out, records = table
    copy = tmp_path / "out"
    subprocess.run(["cp", "-a", str(out), str(copy)], check=True)
    for shard in (copy / "shards").glob("*.jsonl"):
        shard.write_text("not json\n")
    changed = [dict(r) for r in records]
    changed[3]["qe"] = [0.25, -0.5]
    summary = run_batch(write(tmp_path, changed), copy, workers=1)
    assert summary.layout == Layout.SHARDS  # the folder's own layout
    assert summary.skipped == len(records) - 1 and summary.tasks == 1
    assert summary.planned == len(records) - 1 and summary.failed == 1
    last = rows(copy)[-1]
    assert last["id"] == changed[3]["id"] and last["shard"] not in {r["shard"] for r in rows(out)}
    doc = json.loads((copy / "shards" / last["shard"]).read_text())
    assert doc["request"]["qe"] == [0.25, -0.5]
    again = run_batch(write(tmp_path, changed), copy, workers=1, retry_failed=True)
    assert again.skipped == len(records) - 1 and again.failed == 1  # the failure planned again


def test_a_chunk_run_again_plans_only_what_its_part_file_lacks(tmp_path: Path) -> None:
    """A worker killed mid-chunk leaves ``<chunk>.part`` with the motions it finished (the last
    line cut short); the chunk run again plans the rest only, and the shard holds each once."""
    requests = tuple(MotionRequest.from_dict(r, r["id"]) for r in quick_motions(4)[:3])
    (tmp_path / "shards").mkdir()
    first = plan_chunk(Chunk("c1", requests[:2]), str(tmp_path), 1000.0)
    assert first.planned == 2 and len(first.rows) == 2
    lines = (tmp_path / "shards" / "c1.jsonl").read_text().splitlines(keepends=True)
    part = tmp_path / "shards" / "c2.part"
    part.write_text(lines[0] + lines[1][: len(lines[1]) // 2])  # killed while writing line 2
    again = plan_chunk(Chunk("c2", requests), str(tmp_path), 1000.0)
    assert isinstance(again, ChunkDone) and again.planned == 2  # the cut line's and the third
    assert [row[0] for row in again.rows] == [r.id for r in requests]
    shard = tmp_path / "shards" / "c2.jsonl"
    assert not part.exists()
    assert [json.loads(line)["id"] for line in shard.read_text().splitlines()] == [
        r.id for r in requests
    ]
    assert plan_chunk(Chunk("c2", requests), str(tmp_path), 1000.0).planned == 0  # done
    assert [row[0] for row in read_shard(shard)] == [r.id for r in requests]


def test_the_index_cuts_a_torn_row_keeps_the_last_of_an_id_and_recovers_shards(
    tmp_path: Path,
) -> None:
    """summary.csv read back: a row cut short (the client killed amid a write) is cut off; the
    last row of an id decides; a shard or .part no row names is indexed once."""
    a = MotionRequest.from_dict({"robot": "two_link", "q0": [0, 0], "qe": [1, 0]}, "a")
    b = MotionRequest.from_dict({"robot": "two_link", "q0": [0, 0], "qe": [0, 1]}, "b")
    c = MotionRequest.from_dict({"robot": "two_link", "q0": [1, 0], "qe": [0, 1]}, "c")

    def document(request: MotionRequest, **fields: object) -> str:
        request_json = json.loads(request.fingerprint(1000.0))
        return json.dumps({"id": request.id, "request": request_json, **fields}) + "\n"

    shards = tmp_path / "shards"
    shards.mkdir()
    (shards / "s1.jsonl").write_text(document(a, error="Boom: no") + document(b, J=1.0))
    (shards / "s2.part").write_text(document(c, J=2.0) + document(a, J=3.0)[:30])
    index = ShardIndex.open(tmp_path)  # no summary yet: both shards recovered
    assert len(index) == 3 and not (shards / "s2.part").exists()
    assert (shards / "s2.jsonl").read_text() == document(c, J=2.0)  # the torn line cut
    assert index.is_done(a, 1000.0, retry_failed=False) is None  # failed: skipped
    assert index.is_done(a, 1000.0, retry_failed=True) is False
    assert index.is_done(b, 1000.0, retry_failed=False) is True
    assert index.is_done(b, 500.0, retry_failed=False) is False  # another rate: planned again
    (shards / "s3.jsonl").write_text(document(a, J=4.0, batch={"status": "converged"}))
    with (tmp_path / "summary.csv").open("a") as stream:
        stream.write("b,converged,1.0,")  # torn
    again = ShardIndex.open(tmp_path)
    assert len(again) == 3 and again.is_done(a, 1000.0, retry_failed=False) is True
    text = (tmp_path / "summary.csv").read_text()
    assert text.endswith("\n") and "b,converged,1.0,\n" not in text + "\n"
    assert [line.split(",")[0] for line in text.splitlines()[1:]] == ["a", "b", "c", "a"]
    assert len(ShardIndex.open(tmp_path)) == 3  # nothing more to recover


def test_chunks_are_sized_from_the_time_per_motion() -> None:
    chunking = _Chunking(workers=2)
    assert chunking.size(10_000) == 4  # before anything is measured
    chunking.measured(ChunkDone("c", (), seconds=0.4, planned=10))  # 40 ms per motion
    assert chunking.size(10_000) == round(CHUNK_SECONDS / 0.04)
    assert chunking.size(40) == 10  # the last motions spread over the workers
    chunking.measured(ChunkDone("c", (), seconds=1e-3 * 10**4, planned=10**4))
    assert chunking.size(10**6) == 500  # at most MAX_CHUNK


def test_a_motions_file_is_checked_whole_before_anything_is_planned(tmp_path: Path) -> None:
    records = quick_motions(30)
    records[20]["id"] = records[5]["id"]
    path = write(tmp_path, records)
    with pytest.raises(ConfigurationError, match=r"line 21: id 'q00005' repeats line 6"):
        MotionsFile.scan(path)
    with pytest.raises(ConfigurationError, match=r"line 21: id 'q00005' repeats line 6"):
        run_batch(path, tmp_path / "out", workers=1, layout="shards")
    assert not (tmp_path / "out").exists()
    records[20]["id"] = "q-new"
    path = write(tmp_path, records)
    assert MotionsFile.scan(path).count == 30
    path.write_text(path.read_text() + "{not json\n")
    with pytest.raises(ConfigurationError, match=r"line 31: not JSON"):
        MotionsFile.scan(path)


def test_a_folder_of_the_other_layout_or_in_use_is_refused(table: tuple, tmp_path: Path) -> None:
    tasks, out, _ = table
    files = tmp_path / "files"
    run_batch([MotionRequest.from_dict(quick_motions(2)[0], "a")], files, workers=1)
    with pytest.raises(ConfigurationError, match=r"holds a batch in the files layout"):
        run_batch(tasks, files, workers=1, layout="shards")
    with pytest.raises(ConfigurationError, match=r"holds a batch in the shards layout"):
        run_batch(tasks, out, workers=1, layout="files")
    with pytest.raises(ConfigurationError, match=r"layout 'rows': one of"):
        run_batch(tasks, out, workers=1, layout="rows")
    with (out / "batch.lock").open("a") as lock:  # another batch writes the folder
        fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        with pytest.raises(ConfigurationError, match=r"another nearopt batch is writing"):
            run_batch(tasks, out, workers=1)


def test_the_progress_line_says_rate_and_eta_and_throttles_when_not_a_terminal() -> None:
    stream = io.StringIO()
    report = progress_line(stream, every=3600.0)
    report(10, 0, 2, 100, float("nan"))
    time.sleep(0.05)
    report(20, 1, 2, 100, 45.0)  # within the hour: not printed
    report(100, 1, 0, 100, 0.0)  # the last always is
    lines = stream.getvalue().splitlines()
    assert len(lines) == 2
    assert lines[0].endswith("ETA -") and "10/100 done, 0 failed" in lines[0]
    assert "100/100 done, 1 failed, 0 running" in lines[1] and "/s, ETA 0m00s" in lines[1]
    assert float(lines[1].split(", ")[-2].removesuffix("/s")) > 100  # 90 motions in ~0.05 s


def test_killed_local_workers_lose_nothing_and_plan_nothing_twice(tmp_path: Path) -> None:
    """SIGKILL to every worker while a chunk is half done: the pool is started again, the
    motions of the .part files are kept, each motion is in the table once."""
    records = quick_motions(40, seed=4)
    out = tmp_path / "out"
    pool = LocalPool(2)
    halfway: list[int] = []

    def kill_once(done: int, failed: int, running: int, total: int, eta: float) -> None:
        deadline = time.time() + 30
        while not halfway and time.time() < deadline:
            parts = [p.read_text().count("\n") for p in (out / "shards").glob("*.part")]
            if any(parts):
                for pid in pool.processes():
                    os.kill(pid, signal.SIGKILL)
                halfway.append(max(parts))
            time.sleep(0.002)

    with pool:
        summary = run_batch(
            write(tmp_path, records), out, pool, progress=kill_once, layout="shards"
        )
    assert halfway and summary.planned == 39 and summary.failed == 1
    assert sorted(d["id"] for d in documents(out)) == sorted(r["id"] for r in records)
    assert Counter(r["id"] for r in rows(out)) == Counter(r["id"] for r in records)


@pytest.mark.slow
def test_an_interrupted_client_loses_nothing_and_plans_nothing_twice(tmp_path: Path) -> None:
    """Ctrl-C to ``nearopt batch`` mid-table: what its workers had finished is kept (shards,
    the index, or .part files the next run indexes); the next run plans only the rest."""
    records = quick_motions(80, seed=5)
    tasks = write(tmp_path, records)
    out = tmp_path / "out"
    command = [sys.executable, "-m", "nearopt.cli", "batch", str(tasks), "--out", str(out)]
    process = subprocess.Popen(
        [*command, "--workers", "2", "--layout", "shards", "--quiet"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.time() + 300
    while time.time() < deadline and len(rows(out) if (out / "summary.csv").exists() else []) < 10:
        time.sleep(0.05)
    process.send_signal(signal.SIGINT)
    _, stderr = process.communicate(timeout=120)
    assert process.returncode == 130, stderr
    assert "interrupted" in stderr and "Traceback" not in stderr
    indexed = {r["id"] for r in rows(out)}
    kept = {
        json.loads(line)["id"]
        for shard in (out / "shards").glob("*.*")
        for line in shard.read_text().splitlines()
        if line.endswith("}")
    }
    assert 10 <= len(indexed) < len(records) and indexed <= kept
    run = subprocess.run([*command, "--quiet"], capture_output=True, text=True, timeout=600)
    assert run.returncode == 1, run.stderr
    assert f"({len(kept)} done before, skipped)" in run.stdout  # .part files' motions too
    assert sorted(d["id"] for d in documents(out)) == sorted(r["id"] for r in records)
    assert Counter(r["id"] for r in rows(out)) == Counter(r["id"] for r in records)


@pytest.mark.slow
def test_a_killed_dask_worker_loses_nothing_and_plans_nothing_twice(
    cluster: dict, table: tuple, tmp_path: Path
) -> None:
    """SIGKILL to both Dask workers while a chunk is half done: the scheduler runs the chunks
    again on the restarted workers, which plan only what the .part files lack; the same table
    as on the local pool."""
    psutil = pytest.importorskip("psutil")
    tasks, local, records = table
    killed: list[int] = []

    out = tmp_path / "dask"

    def kill_once(done: int, failed: int, running: int, total: int, eta: float) -> None:
        deadline = time.time() + 30
        while not killed and time.time() < deadline:
            if any(p.read_text().count("\n") for p in (out / "shards").glob("*.part")):
                for worker in cluster["workers"]:  # both: the .part may be either's
                    for child in psutil.Process(worker.pid).children(recursive=True):
                        child.send_signal(signal.SIGKILL)
                        killed.append(child.pid)
            time.sleep(0.002)

    summary = run_batch(tasks, out, cluster["client"], progress=kill_once, layout="shards")
    assert killed and summary.planned == len(records) - 1 and summary.failed == 1
    assert sorted(d["id"] for d in documents(out)) == sorted(r["id"] for r in records)
    assert Counter(r["id"] for r in rows(out)) == Counter(r["id"] for r in records)
    mine = {r["id"]: (r["status"], r["J"], r["te"], r["request"]) for r in rows(out)}
    theirs = {r["id"]: (r["status"], r["J"], r["te"], r["request"]) for r in rows(local)}
    assert mine == theirs  # the same table as on the local pool


def test_two_runs_in_one_second_name_their_chunks_apart(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The CI failure of 2026-12-05: two sharded runs of one process within a second named
    their chunks alike, and the second took the first's shard for its own chunk, done: the
    failure it was to retry was never planned again. The clock stopped, the second run's chunk
    is its own."""
    import nearopt.batch.shards as shards

    monkeypatch.setattr(shards.time, "strftime", lambda *_: "20261205T000000")
    records = quick_motions(3)
    tasks = write(tmp_path, records)
    first = run_batch(tasks, tmp_path / "out", workers=1, layout="shards")
    assert first.planned == 2 and first.failed == 1  # the motion out of range fails
    before = set((tmp_path / "out" / "shards").glob("*.jsonl"))
    again = run_batch(tasks, tmp_path / "out", workers=1, retry_failed=True)
    assert again.skipped == 2 and again.failed == 1  # planned again, failed again
    assert len(set((tmp_path / "out" / "shards").glob("*.jsonl")) - before) == 1  # its own
