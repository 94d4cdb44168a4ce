"""Many motions (#13): ``nearopt batch`` and ``plan_many`` on this machine's processes and on a
real Dask scheduler with two workers on 127.0.0.1; failures recorded, killed workers survived,
interrupted batches resumed."""

from __future__ import annotations

import csv
import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import free_port, load

import nearopt
import nearopt.cli
from nearopt.api import PlanRequest
from nearopt.batch import (
    LocalPool,
    MotionRequest,
    OutcomeStatus,
    plan_many,
    probe_scheduler,
    read_requests,
    run_batch,
)

ARMS = ("two_link", "ur5", "panda")


def motions(count_per_arm: int = 7, seed: int = 3) -> list[dict]:
    """Seeded motions over three arms within 60 % of each range, and one the ur5 cannot lift."""
    rng = np.random.default_rng(seed)
    out = []
    for name in ARMS:
        robot = load(name)
        lo = np.maximum(robot.limits.position_lower, -np.pi)
        hi = np.minimum(robot.limits.position_upper, np.pi)
        mid, half = 0.5 * (lo + hi), 0.3 * (hi - lo)
        for k in range(count_per_arm):
            q0, qe = rng.uniform(mid - half, mid + half, (2, robot.n))
            out.append(
                {
                    "id": f"{name}-{k}",
                    "robot": name,
                    "q0": q0.round(4).tolist(),
                    "qe": qe.round(4).tolist(),
                    "beta": 0.001,
                    "max_iterations": 2,
                    "grid": 60,
                }
            )
    out.append(
        {
            "id": "too-weak",
            "robot": "ur5",
            "q0": [0, -1.2, 1.2, -1.5, -1.57, 0],
            "qe": [0.5, -1.2, 1.2, -1.5, -1.57, 0],
            "effort_limit": [1.0],
        }
    )
    return out


def write_motions(folder: Path, records: list[dict]) -> Path:
    path = folder / "motions.jsonl"
    path.write_text("# a motion table\n" + "\n".join(json.dumps(r) for r in records) + "\n")
    return path


def summary(folder: Path) -> list[dict[str, str]]:
    with (folder / "summary.csv").open() as stream:
        return list(csv.DictReader(stream))


def batch(*args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "nearopt.cli", "batch", *args, "--quiet"],
        capture_output=True,
        text=True,
        timeout=timeout,
    )


def without_wall_time(rows: list[dict[str, str]]) -> list[dict[str, str]]:
    return [{k: v for k, v in row.items() if k != "wall_time"} for row in rows]


@pytest.fixture(scope="module")
def local_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The batch on this machine's default pool (a process per core)."""
    folder = tmp_path_factory.mktemp("local")
    tasks = write_motions(folder, motions())
    run = batch(str(tasks), "--out", str(folder / "out"))
    assert run.returncode == 1, run.stderr  # the infeasible motion failed, the rest planned
    assert "22 motions: 21 planned, 1 failed" in run.stdout
    assert "motions/s, 22 tasks)" in run.stdout  # a motion each (it said 0)
    return tasks, folder / "out"


def test_a_local_batch_plans_every_motion_and_records_the_failure(
    local_run: tuple[Path, Path],
) -> None:
    tasks, out = local_run
    rows = summary(out)
    assert [r["id"] for r in rows] == [r["id"] for r in motions()]
    failed = [r for r in rows if r["status"] == "failed"]
    assert [r["id"] for r in failed] == ["too-weak"]
    assert (
        "InfeasiblePathError" in failed[0]["error"] and "shoulder_lift_joint" in failed[0]["error"]
    )
    assert json.loads((out / "failed" / "too-weak.json").read_text())["error"] == failed[0]["error"]
    requests = {r["id"]: r for r in motions()}
    for row in rows:
        if row["status"] == "failed":
            continue
        doc = json.loads((out / f"{row['id']}.json").read_text())
        assert doc["id"] == row["id"]
        assert doc["request"] == {**requests[row["id"]], "file_sha256": {}}  # at 1 kHz
        assert float(row["J"]) == doc["J"] and float(row["te"]) == doc["duration"]
        np.testing.assert_allclose(doc["q"][0], requests[row["id"]]["q0"], atol=1e-12)
        np.testing.assert_allclose(doc["q"][-1], requests[row["id"]]["qe"], atol=1e-9)
        np.testing.assert_allclose(doc["qd"][-1], 0.0, atol=1e-9)
        limits = load(doc["robot"]).limits
        assert np.all(
            np.abs(doc["tau"]) <= np.maximum(-limits.effort_lower, limits.effort_upper) * (1 + 1e-6)
        )


@pytest.mark.slow
def test_a_dask_cluster_gives_the_same_summary(cluster: dict, local_run: tuple[Path, Path]) -> None:
    tasks, local_out = local_run
    out = tasks.parent / "dask-out"
    run = batch(str(tasks), "--out", str(out), "--scheduler", cluster["address"])
    assert run.returncode == 1, run.stderr
    assert without_wall_time(summary(out)) == without_wall_time(summary(local_out))
    same = json.loads((out / "ur5-3.json").read_text())
    assert same["q"] == json.loads((local_out / "ur5-3.json").read_text())["q"]


@pytest.mark.slow
def test_a_worker_killed_mid_batch_loses_no_motion(cluster: dict, tmp_path: Path) -> None:
    """SIGKILL to a Dask worker process while it plans: the scheduler runs its task elsewhere;
    every motion is written once."""
    psutil = pytest.importorskip("psutil")
    requests = [MotionRequest.from_dict(r, r["id"]) for r in motions(5, seed=5)]
    killed = []

    def kill_once(done: int, failed: int, running: int, total: int, eta: float) -> None:
        if killed:
            return
        nanny = psutil.Process(cluster["workers"][0].pid)
        for child in nanny.children(recursive=True):
            try:
                child.send_signal(signal.SIGKILL)
            except psutil.NoSuchProcess:  # a plan's forked child, ended with its worker
                continue
            killed.append(child.pid)

    result = run_batch(requests, tmp_path, cluster["client"], progress=kill_once)
    assert killed
    rows = summary(tmp_path)
    assert [r["id"] for r in rows] == [r.id for r in requests]
    assert [r["id"] for r in rows if r["status"] == "failed"] == ["too-weak"]
    assert result.failed == 1 and len(result.outcomes) == len(requests)
    for request in requests[:-1]:
        assert json.loads((tmp_path / f"{request.id}.json").read_text())["id"] == request.id


def test_a_dead_local_worker_is_replaced_and_its_motions_rerun(tmp_path: Path) -> None:
    requests = [MotionRequest.from_dict(r, r["id"]) for r in motions(2, seed=7)[:-1]]
    pool = LocalPool(2)
    killed = []

    def kill_once(done: int, failed: int, running: int, total: int, eta: float) -> None:
        if not killed:
            pid = pool.processes()[0]
            os.kill(pid, signal.SIGKILL)
            killed.append(pid)

    with pool:
        result = run_batch(requests, tmp_path, pool, progress=kill_once)
    assert killed and result.failed == 0
    assert sorted(p.name for p in tmp_path.glob("*.json")) == sorted(
        f"{r.id}.json" for r in requests
    )


@pytest.mark.slow
def test_an_interrupted_batch_resumes_without_replanning(tmp_path: Path) -> None:
    records = [dict(r, max_iterations=20) for r in motions(3, seed=11)]  # slower: time to stop
    tasks = write_motions(tmp_path, records)
    out = tmp_path / "out"
    process = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "nearopt.cli",
            "batch",
            str(tasks),
            "--out",
            str(out),
            "--workers",
            "2",
            "--quiet",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.time() + 300
    while time.time() < deadline and not list(out.glob("*.json")):
        time.sleep(0.02)
    process.send_signal(signal.SIGINT)
    _, stderr = process.communicate(timeout=120)
    assert process.returncode == 130, stderr
    assert "interrupted" in stderr and "Traceback" not in stderr
    first = {p.relative_to(out): p.stat().st_mtime_ns for p in out.glob("**/*.json")}
    assert 1 <= len(first) < len(records)
    assert not list(out.glob("**/.*")), "no half-written file is left"
    rows = summary(out)  # the files and the summary are written together: they agree
    written = {
        Path(r["id"] + ".json") if r["status"] != "failed" else Path("failed", r["id"] + ".json")
        for r in rows
    }
    assert written == set(first)
    run = batch(str(tasks), "--out", str(out))
    assert f"({len(first)} done before, skipped)" in run.stdout
    assert {
        p.relative_to(out): p.stat().st_mtime_ns
        for p in out.glob("**/*.json")
        if p.relative_to(out) in first
    } == first
    assert [r["id"] for r in summary(out)] == [r["id"] for r in records]


def test_plan_many_returns_the_plans_in_request_order() -> None:
    records = [
        {"robot": "two_link", "q0": np.array([0.7, -1.5]), "qe": qe, "max_iterations": 1}
        for qe in ([-1.5, 0.0], (0.3, 0.2), np.array([1.0, -0.5]))
    ]
    records.insert(1, {"id": "wrong", "robot": "two_link", "q0": [0, 0], "qe": [1, 2, 3]})
    # the one request model too, with arrays as a script holds them and the URDF as a Path
    request = PlanRequest(
        urdf=nearopt.catalog.robot_entry("two_link").urdf,
        q0=np.array([0.7, -1.5]),
        qe=np.array([0.2, 0.1]),
        max_iterations=np.int64(1),
    )
    assert request == PlanRequest(
        urdf=str(request.urdf), q0=(0.7, -1.5), qe=(0.2, 0.1), max_iterations=1
    )
    outcomes = plan_many([*records, request], workers=2)
    assert [o.id for o in outcomes] == ["m0", "wrong", "m2", "m3", "m4"]
    last = outcomes.pop()
    assert last.status == OutcomeStatus.PLANNED and last.te > 0, last.error
    assert outcomes[1].status == OutcomeStatus.FAILED and "qe" in outcomes[1].error
    robot = load("two_link")
    for outcome, record in zip(
        outcomes[::2] + outcomes[3:], records[::2] + records[3:], strict=True
    ):
        assert outcome.status == OutcomeStatus.PLANNED
        assert isinstance(outcome.result, nearopt.PlanResult)
        np.testing.assert_allclose(
            outcome.result.trajectory(outcome.te, 0)[0], np.asarray(record["qe"]), atol=1e-9
        )
        report = nearopt.verify(
            outcome.result.trajectory,
            robot,
            q0=record["q0"],
            qe=record["qe"],
            cost=outcome.result.cost,
            J=outcome.J,
        )
        assert report.passed, str(report)


def test_bad_motion_files_are_one_line_errors(tmp_path: Path) -> None:
    cases = {
        '{"id": "a", "robot": "ur5"}\n{"id": "a", "robot": "ur5"}\n': "id 'a' repeats line 1",
        '{"id": "../x"}\n': "ids are",
        "[1, 2]\n": "a motion is a JSON object",
        "{oops\n": "line 1: not JSON",
        '{"id": "abc\\n", "robot": "two_link"}\n': "ids are",  # a newline in a file name
        '{"id": 7, "robot": "two_link"}\n': "an id is a JSON string",
        '{"id": "a", "q0": [0, 0], "q0": [0.1, 0]}\n': "line 1: option 'q0' is given twice",
        "\n# nothing\n": "no motions",
    }
    for text, message in cases.items():
        (tmp_path / "m.jsonl").write_text(text)
        with pytest.raises(nearopt.ConfigurationError, match=message.replace("(", r"\(")):
            read_requests(tmp_path / "m.jsonl")
        if "id" not in message:  # the command line: once per kind of slip (not per id rule)
            run = batch(str(tmp_path / "m.jsonl"), "--out", str(tmp_path / "out"), timeout=120)
            assert run.returncode == 2 and "Traceback" not in run.stderr
            assert message in run.stderr and len(run.stderr.strip().splitlines()) == 1
    for options, message in (
        ({"json": "x.json"}, "writes every motion"),
        ({"colour": 1}, "unknown option 'colour'"),
        ({"q0": {"a": 1}}, "option values"),
        ({"via": [0.1, 0.2]}, "list of lists"),
    ):
        with pytest.raises(nearopt.ConfigurationError, match=message):
            MotionRequest("m", options).plan_request()
    with pytest.raises(nearopt.ConfigurationError, match="option values"):  # not repeatable
        MotionRequest("m", {"q0": [[0, 0], [0.3, 0.3]]}).plan_request()
    with pytest.raises(nearopt.ConfigurationError, match="--q0 is given twice"):
        nearopt.cli.parse_plan(
            [
                "plan",
                "--robot",
                "two_link",
                "--q0",
                "0",
                "0",
                "--q0",
                "0.3",
                "0.3",
                "--qe",
                "1",
                "1",
            ]
        )
    (tmp_path / "file").write_text("")
    with pytest.raises(nearopt.ConfigurationError, match="not a folder"):
        run_batch([MotionRequest("m", {})], tmp_path / "file")


def test_a_changed_input_file_or_rate_is_planned_again(tmp_path: Path) -> None:
    """Resume counts a motion as done only for the same options, the same contents of the files
    it names and the same rate; a failure and a planned motion whose ids look alike keep their
    own files."""
    task = tmp_path / "t.toml"
    task.write_text("[[target]]\nq = [0.2, -0.3]\n")
    records = [
        {
            "id": "t1",
            "robot": "two_link",
            "q0": [0, 0],
            "task": "t.toml",
            "max_iterations": 1,
            "grid": 60,
        },
        {"id": "m", "robot": "two_link", "q0": [0, 0], "qe": [0.5, 0.5, 9]},
        {
            "id": "m.failed",
            "robot": "two_link",
            "q0": [0, 0],
            "qe": [0.5, 0.5],
            "max_iterations": 1,
            "grid": 60,
        },
    ]
    requests = read_requests(write_motions(tmp_path, records))
    out = tmp_path / "out"
    with LocalPool(1) as pool:
        first = run_batch(requests, out, pool)
        assert first.failed == 1 and (out / "m.failed.json").exists()
        assert (out / "failed" / "m.json").exists()
        assert run_batch(requests, out, pool).skipped == 3
        task.write_text("[[target]]\nq = [-0.8, -0.9]\n")
        again = run_batch(requests, out, pool)
        assert again.skipped == 2
        np.testing.assert_allclose(
            json.loads((out / "t1.json").read_text())["q"][-1], [-0.8, -0.9], atol=1e-9
        )
        assert run_batch(requests, out, pool, rate=500.0).skipped == 0
        assert run_batch(requests, out, pool, rate=500.0).skipped == 3  # now done at 500 Hz
    doc = json.loads((out / "t1.json").read_text())
    assert doc["t"][1] == pytest.approx(1 / 500)


def test_a_batch_never_writes_over_its_inputs(tmp_path: Path) -> None:
    """A motion whose id is the motions file's stem, with --out at the file's folder, would
    write <id>.json over the motions file; one whose id names its own task file likewise:
    both refused in one line before anything is planned, the inputs as they were."""
    motions = tmp_path / "cycle.json"
    text = json.dumps({"id": "cycle", "robot": "two_link", "q0": [0, 0], "qe": [0.3, 0.3]})
    motions.write_text(text + "\n")
    run = batch(str(motions), "--out", str(tmp_path), timeout=120)
    assert run.returncode == 2, run.stderr
    assert "its output" in run.stderr and "is the motions file" in run.stderr
    assert motions.read_text() == text + "\n"
    assert not (tmp_path / "summary.csv").exists()
    task = tmp_path / "out" / "t.json"
    task.parent.mkdir()
    task.write_text("[[target]]\nq = [0.2, -0.3]\n")
    with pytest.raises(nearopt.ConfigurationError, match="is its task"):
        run_batch(
            [MotionRequest("t", {"robot": "two_link", "q0": [0, 0], "task": str(task)})],
            tmp_path / "out",
        )
    assert task.read_text() == "[[target]]\nq = [0.2, -0.3]\n"
    table = tmp_path / "s" / "summary.csv"  # a motions file named like the summary
    table.parent.mkdir()
    table.write_text(text + "\n")
    only_folder = "is the motions file .*; give --out another folder$"  # an id cannot help
    with pytest.raises(nearopt.ConfigurationError, match=only_folder):
        run_batch(read_requests(table), table.parent)
    with pytest.raises(nearopt.ConfigurationError, match="is an empty path"):
        run_batch(read_requests(motions), "")


def test_a_scheduler_address_that_is_not_a_scheduler_is_named_at_once(tmp_path: Path) -> None:
    """--scheduler at a port where nothing listens, at one that accepts and stays silent, at an
    HTTP server (the dashboard's port is the commonest slip) and at a server that greets in
    another protocol: one line each naming what answered, nothing written, and no hang (the
    probe waits 3 s at most twice, 0.5 s here; the run's timeout guards against a hang)."""
    import http.server
    import threading

    table = write_motions(tmp_path, motions(1)[:1])
    silent = socket.socket()
    silent.bind(("127.0.0.1", 0))
    silent.listen()
    http_server = http.server.HTTPServer(("127.0.0.1", 0), http.server.SimpleHTTPRequestHandler)
    threading.Thread(target=http_server.serve_forever, daemon=True).start()
    greeter = socket.socket()
    greeter.bind(("127.0.0.1", 0))
    greeter.listen()

    def greet() -> None:
        connection, _ = greeter.accept()
        connection.sendall(b"SSH-2.0-OpenSSH_9.2\r\n")

    threading.Thread(target=greet, daemon=True).start()
    cases = {
        f"tcp://127.0.0.1:{free_port()}": "Connection refused",
        f"tcp://127.0.0.1:{silent.getsockname()[1]}": "said nothing in 0.5 s",
        f"127.0.0.1:{http_server.server_address[1]}": "is an HTTP server, not a Dask scheduler",
        f"tcp://127.0.0.1:{greeter.getsockname()[1]}": "not as a Dask scheduler (it sent b'SSH",
        "tcp://127.0.0.1": "give the scheduler's host and port",
        "http://127.0.0.1:9": "http:// is not a Dask protocol",
    }
    try:
        # through the command line once (one line, nothing made, no hang), the others in process
        http_address = f"127.0.0.1:{http_server.server_address[1]}"
        out = tmp_path / "out"
        run = batch(str(table), "--out", str(out), "--scheduler", http_address, timeout=60)
        assert run.returncode == 2, run.stderr
        lines = run.stderr.strip().splitlines()
        assert len(lines) == 1 and cases[http_address] in lines[0], lines
        assert not out.exists()  # nothing made, not even the folder
        for address, says in cases.items():
            with pytest.raises(nearopt.ConfigurationError) as caught:
                probe_scheduler(address, wait=0.5)
            assert says in str(caught.value) and "\n" not in str(caught.value), address
    finally:
        http_server.shutdown()
        silent.close()
        greeter.close()


def test_plan_many_at_a_scripts_top_level_asks_for_the_main_guard(tmp_path: Path) -> None:
    """A script that calls plan_many at its top level, or a function that does from its top
    level, without `if __name__ == "__main__":`: each spawned worker would import the script
    again (every motion failed as a dead worker, the script's top level ran in each). One
    error naming the script and the line, before any worker starts."""
    call = 'nearopt.plan_many([{"robot": "two_link", "q0": [0, 0], "qe": [0.3, 0.3]}])'
    for name, text, line in (
        ("top.py", f"import nearopt\n{call}\n", 2),
        ("function.py", f"import nearopt\n\n\ndef main():\n    {call}\n\n\nmain()\n", 8),
    ):
        script = tmp_path / name
        script.write_text(text)
        run = subprocess.run(
            [sys.executable, str(script)], capture_output=True, text=True, timeout=120
        )
        assert run.returncode != 0
        assert f"{script}, line {line}: plan_many and run_batch start worker" in run.stderr
        assert 'if __name__ == "__main__":' in run.stderr and "WorkerDied" not in run.stderr


def test_the_main_guard_is_found_in_any_form_and_run_batch_asks_before_its_folder(
    tmp_path: Path,
) -> None:
    """A guard written the other way round, in a larger condition or inside a ``try`` is a guard
    (the plans run); run_batch without one makes no folder."""
    motions = '[{"robot": "two_link", "q0": [0, 0], "qe": [0.3, 0.3], "stage1_only": True}]'
    guarded = tmp_path / "guarded.py"
    guarded.write_text(
        f"import nearopt\nM = {motions}\n"
        'if "__main__" == __name__:\n    a = nearopt.plan_many(M, workers=1)\n'
        'try:\n    if __name__ == "__main__" and M:\n        b = nearopt.plan_many(M, workers=1)\n'
        "finally:\n    pass\n"
        'if __name__ == "__main__":\n    print(a[0].status.value, b[0].status.value)\n'
    )
    run = subprocess.run(
        [sys.executable, str(guarded)], capture_output=True, text=True, timeout=120
    )
    assert run.returncode == 0, run.stderr
    assert run.stdout.split() == ["planned", "planned"]
    bare = tmp_path / "bare.py"
    out = tmp_path / "out"
    bare.write_text(
        "from nearopt.batch import MotionRequest, run_batch\n"
        f"run_batch([MotionRequest.from_dict({motions}[0], 'm0')], {str(out)!r})\n"
    )
    run = subprocess.run([sys.executable, str(bare)], capture_output=True, text=True, timeout=120)
    assert f"{bare}, line 2: plan_many and run_batch start worker" in run.stderr
    assert not out.exists()


def test_an_in_process_scheduler_address_is_left_to_dask() -> None:
    """inproc:// (a cluster of threads in this process) has no socket to probe: Dask connects."""
    import distributed

    with distributed.LocalCluster(
        processes=False, n_workers=1, threads_per_worker=1, dashboard_address=None
    ) as cluster:
        assert cluster.scheduler_address.startswith("inproc://")
        (outcome,) = plan_many(
            [{"robot": "two_link", "q0": [0, 0], "qe": [0.3, 0.3], "stage1_only": True}],
            client=cluster.scheduler_address,
        )
    assert outcome.status == OutcomeStatus.PLANNED, outcome.error
    np.testing.assert_allclose(outcome.result.trajectory(outcome.te, 0)[0], [0.3, 0.3], atol=1e-9)


def test_an_option_of_the_wrong_kind_fails_its_motion_not_the_batch(tmp_path: Path) -> None:
    """A JSON object where a number is asked for (``"jerk_limit": {"joint1": 5}``) is a JSON
    value: the file is read, that motion fails with the option named, the others are planned
    (it aborted the whole batch, nothing planned)."""
    motions = tmp_path / "m.jsonl"
    motions.write_text(
        '{"id": "bad", "robot": "two_link", "q0": [0, 0], "qe": [1, 0.5], '
        '"jerk_limit": {"joint1": 5}}\n'
        '{"id": "good", "robot": "two_link", "q0": [0, 0], "qe": [1, 0.5], "stage1_only": true}\n'
    )
    assert [r.id for r in read_requests(motions)] == ["bad", "good"]
    run = batch(str(motions), "--out", str(tmp_path / "out"), "--workers", "1", timeout=300)
    assert run.returncode == 1 and "Traceback" not in run.stderr, run.stderr
    error = json.loads((tmp_path / "out" / "failed" / "bad.json").read_text())["error"]
    assert "jerk_limit" in error
    assert (tmp_path / "out" / "good.json").is_file()


def test_files_no_batch_wrote_are_refused_and_kept(tmp_path: Path) -> None:
    """``--out`` a folder of the user's: a ``summary.csv`` or a ``<id>.json`` that no batch
    wrote was silently replaced; now the batch refuses before planning and keeps them. A
    second run over its own outputs resumes as before."""
    motion = {"id": "a", "robot": "two_link", "q0": [0, 0], "qe": [0.4, 0.2], "grid": 40}
    tasks = write_motions(tmp_path, [motion])
    out = tmp_path / "out"
    out.mkdir()
    (out / "summary.csv").write_text("my,own,table\n")
    run = batch(str(tasks), "--out", str(out))
    assert run.returncode == 2 and "is not a batch's summary" in run.stderr, run.stderr
    (out / "summary.csv").unlink()
    (out / "a.json").write_text('{"mine": true}')
    run = batch(str(tasks), "--out", str(out))
    assert run.returncode == 2 and "is not the outcome of a motion" in run.stderr, run.stderr
    assert (out / "a.json").read_text() == '{"mine": true}'
    assert sorted(p.name for p in out.iterdir()) == ["a.json"]
    (out / "a.json").unlink()
    assert batch(str(tasks), "--out", str(out)).returncode == 0
    again = batch(str(tasks), "--out", str(out))
    assert again.returncode == 0 and "done before, skipped" in again.stdout, again.stdout
