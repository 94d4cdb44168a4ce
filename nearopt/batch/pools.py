"""Where a batch's motions run: this machine's processes or a Dask cluster."""

from __future__ import annotations

import ast
import concurrent.futures as cf
import contextlib
import multiprocessing
import os
import socket
import struct
import sys
import time
import uuid
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..errors import ConfigurationError

if TYPE_CHECKING:
    pass

from .motions import (
    MAX_ATTEMPTS,
    MotionOutcome,
    MotionRequest,
    plan_request,
    worker_died,
)


class Pool:
    """Where the motions of a batch run: submit motions, get their outcomes as they finish."""

    workers: int

    def run(
        self,
        requests: Sequence[MotionRequest],
        rate: float,
        keep_result: bool,
        ros_bag: bool = False,
    ) -> Iterator[MotionOutcome]:  # pragma: no cover - interface
        """Plan every request; yield the outcomes in the order they finish."""
        raise NotImplementedError

    retries_lost: bool = False
    """Whether the pool itself runs a task again when its worker dies (Dask does)."""

    def submit(self, fn: Callable[..., Any], *args: object) -> Any:  # pragma: no cover
        """Run ``fn(*args)`` on a worker; a future (``.result()``)."""
        raise NotImplementedError

    def wait(self, futures: Iterable[Any]) -> list[Any]:  # pragma: no cover - interface
        """Wait until one of ``futures`` is finished; all the finished ones."""
        raise NotImplementedError

    def lost(self, exc: BaseException) -> bool:
        """Whether a future's exception says its worker died (the pool is then ready for new
        tasks, and the dead worker's processes are gone)."""
        return False

    def cancel(self, futures: list[Any]) -> None:
        """Cancel what of ``futures`` has not run."""
        for future in futures:
            future.cancel()

    def close(self, abort: bool = False) -> None:
        """Release the workers (or the connection); ``abort``: stop what runs now."""

    def __enter__(self) -> Pool:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def check_main_guard() -> None:
    """Refuse to start worker processes from the top level of a script without
    ``if __name__ == "__main__":``: each spawned worker imports the script again, so it would run
    the script's top level (and start workers of its own, which Python refuses: every motion
    then failed as a dead worker).

    Raises
    ------
    ConfigurationError
        Naming the script and the line of the call.
    """
    import __main__

    script = getattr(__main__, "__file__", None)
    if script is None:  # an interactive session, python -c: nothing is imported again
        return
    frame = sys._getframe(1)  # noqa: SLF001 - the script's top level, where it runs now
    while frame is not None and not (
        frame.f_code.co_name == "<module>" and frame.f_globals is vars(__main__)
    ):
        frame = frame.f_back
    if frame is None:  # not under the script's top level (a thread, a callback)
        return
    try:
        tree = ast.parse(Path(script).read_text(encoding="utf-8"))
    except (OSError, SyntaxError, ValueError):
        return
    line = frame.f_lineno
    for node in ast.walk(tree):  # a guard anywhere (in a try, a with; `"__main__" == __name__`,
        if (  # `__name__ == "__main__" and …`), the call in its body
            isinstance(node, ast.If)
            and _tests_main(node.test)
            and node.body[0].lineno <= line <= (node.body[-1].end_lineno or node.lineno)
        ):
            return
    raise ConfigurationError(
        f"{script}, line {line}: plan_many and run_batch start worker processes that import "
        'this script again; put the call under `if __name__ == "__main__":` (see the README)'
    )


def _tests_main(test: ast.expr) -> bool:
    """Whether an ``if`` test compares ``__name__`` with ``"__main__"`` (in either order, alone or
    in a larger condition)."""
    for node in ast.walk(test):
        if isinstance(node, ast.Compare) and all(isinstance(op, ast.Eq) for op in node.ops):
            sides = [node.left, *node.comparators]
            if any(isinstance(s, ast.Name) and s.id == "__name__" for s in sides) and any(
                isinstance(s, ast.Constant) and s.value == "__main__" for s in sides
            ):
                return True
    return False


class LocalPool(Pool):
    """One worker process per core of this machine (:mod:`concurrent.futures`, spawned fresh,
    one BLAS thread each). A worker that dies (killed, out of memory) is replaced and the motions
    it held are run again, up to :data:`MAX_ATTEMPTS` times each.

    Parameters
    ----------
    workers
        Worker processes (default: the number of cores).
    """

    def __init__(self, workers: int | None = None) -> None:
        count = (os.cpu_count() or 1) if workers is None else workers
        if not isinstance(count, int) or isinstance(count, bool) or count < 1:
            raise ConfigurationError(f"workers must be a positive integer, got {workers!r}")
        check_main_guard()
        self.workers = count
        self._executor: cf.ProcessPoolExecutor | None = None

    def _start(self) -> cf.ProcessPoolExecutor:
        if self._executor is None:
            self._executor = cf.ProcessPoolExecutor(
                self.workers,
                mp_context=multiprocessing.get_context("spawn"),
                initializer=_worker_start,
            )
        return self._executor

    def processes(self) -> list[int]:
        """The worker processes' ids (those started so far)."""
        executor = self._executor
        return [] if executor is None else list(executor._processes)  # noqa: SLF001

    def run(
        self,
        requests: Sequence[MotionRequest],
        rate: float,
        keep_result: bool,
        ros_bag: bool = False,
    ) -> Iterator[MotionOutcome]:
        attempts = dict.fromkeys((r.id for r in requests), 0)
        order = {r.id: k for k, r in enumerate(requests)}
        pending = list(requests)
        while pending:
            executor = self._start()
            futures = {
                executor.submit(plan_request, r, rate, keep_result, ros_bag): r for r in pending
            }
            for r in pending:
                attempts[r.id] += 1
            pending = []
            broken = False
            for future in cf.as_completed(futures):
                request = futures[future]
                try:
                    yield future.result()
                except cf.process.BrokenProcessPool:
                    broken = True
                    if attempts[request.id] >= MAX_ATTEMPTS:
                        yield worker_died(request, attempts[request.id])
                    else:
                        pending.append(request)
            if broken:  # a worker died: a fresh pool runs what was lost
                self._executor.shutdown(wait=False, cancel_futures=True)
                self._executor = None
            pending.sort(key=lambda r: order[r.id])

    def submit(self, fn: Callable[..., Any], *args: object) -> Any:
        return self._start().submit(fn, *args)

    def wait(self, futures: Iterable[Any]) -> list[Any]:
        return list(cf.wait(list(futures), return_when=cf.FIRST_COMPLETED).done)

    def lost(self, exc: BaseException) -> bool:
        if not isinstance(exc, cf.process.BrokenProcessPool):
            return False
        executor = self._executor
        if executor is not None and executor._broken:  # noqa: SLF001
            # the pool fails its futures before it stops its other workers: stop them first,
            # so that none writes on after the caller looks at what they wrote
            processes = list(executor._processes.values())  # noqa: SLF001
            for process in processes:
                process.terminate()
            for process in processes:
                process.join(10.0)
            executor.shutdown(wait=False, cancel_futures=True)
            self._executor = None
        return True

    def close(self, abort: bool = False) -> None:
        executor, self._executor = self._executor, None
        if executor is None:
            return
        if abort:  # Ctrl-C: the workers go now, not after their motions
            for process in list(executor._processes.values()):  # noqa: SLF001
                process.terminate()
        executor.shutdown(wait=True, cancel_futures=True)


def _worker_start() -> None:
    """A local worker: Ctrl-C is the parent's to handle (it cancels what is left)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)


PROBE_SECONDS = 3.0
"""How long :func:`probe_scheduler` waits for a connection and for the scheduler's greeting."""


def probe_scheduler(address: str, wait: float = PROBE_SECONDS) -> None:
    """Check that a Dask scheduler answers at ``address`` (``tcp://host:port`` or
    ``host:port``; inproc:// and ucx:// are left to Dask), within ``wait`` seconds twice at
    most.

    A scheduler speaks first: on a new connection it sends its handshake, a message whose
    first 8 bytes are its length (over tcp://; over tls://, ws:// and wss:// the connection
    alone is checked). Anything else is named: nothing listening, no answer, an
    HTTP server (the dashboard, port 8787, is the commonest slip), another kind of server.

    Raises
    ------
    ConfigurationError
        Naming the address and what answered there.
    """
    text = str(address)
    scheme, _, rest = text.rpartition("://")
    if scheme in ("inproc", "ucx", "ucxx"):  # no socket to probe: Dask's own connection decides
        return
    if scheme not in ("", "tcp", "tls", "ws", "wss"):
        raise ConfigurationError(
            f"--scheduler {text}: {scheme}:// is not a Dask protocol; a scheduler's address is "
            "tcp://HOST:8786 (or tls://, ws://, wss://, inproc://, ucx://)"
        )
    host, colon, port = rest.rpartition(":")
    if not colon or not port.isdigit() or not 0 < int(port) < 65536:
        raise ConfigurationError(
            f"--scheduler {text}: give the scheduler's host and port, e.g. tcp://10.0.0.5:8786"
        )
    where = f"the Dask scheduler at {text}"
    try:
        sock = socket.create_connection((host.strip("[]") or "127.0.0.1", int(port)), wait)
    except TimeoutError:
        raise ConfigurationError(f"cannot connect to {where}: no answer in {wait:g} s") from None
    except OSError as exc:
        raise ConfigurationError(f"cannot connect to {where}: {exc.strerror or exc}") from None
    with sock:
        if scheme not in ("", "tcp"):  # encrypted or framed: Dask's own handshake decides
            return
        greeting = _received(sock, 8, wait)
        if len(greeting) == 8 and struct.unpack("<Q", greeting)[0] < 2**24:
            return  # a Dask message: its length, then the handshake
        reply = b""
        if not greeting:  # silent: an HTTP server waits for a request
            with contextlib.suppress(OSError):
                sock.sendall(b"GET / HTTP/1.0\r\n\r\n")
            reply = _received(sock, 5, wait)
    if (greeting or reply).startswith(b"HTTP/"):
        raise ConfigurationError(
            f"{text} is an HTTP server, not a Dask scheduler — the dashboard? the scheduler "
            "listens on port 8786 unless it was told otherwise"
        )
    if greeting:
        raise ConfigurationError(
            f"{text} answered, but not as a Dask scheduler (it sent {greeting!r:.40})"
        )
    raise ConfigurationError(
        f"{text} accepted the connection but said nothing in {wait:g} s: not a Dask scheduler"
    )


def _received(sock: socket.socket, count: int, wait: float) -> bytes:
    """Up to ``count`` bytes from ``sock``, waiting at most ``wait`` seconds in all."""
    data, deadline = b"", time.monotonic() + wait
    while len(data) < count:
        left = deadline - time.monotonic()
        if left <= 0:
            break
        sock.settimeout(left)
        try:
            chunk = sock.recv(count - len(data))
        except OSError:  # a timeout or a reset: what came so far
            break
        if not chunk:
            break
        data += chunk
    return data


class DaskPool(Pool):
    """The workers of a ``dask.distributed`` scheduler (``pip install 'nearopt[batch]'``;
    the workers need nearopt installed, and any URDF, scene or task file at the same path).

    The scheduler re-runs the tasks of a worker that dies (up to its ``allowed-failures``,
    then the motion is recorded as failed).

    Parameters
    ----------
    address
        The scheduler, e.g. ``tcp://10.0.0.5:8786``; or a ready ``distributed.Client``.
    timeout
        Seconds to wait for the connection.
    """

    def __init__(self, address: str | object, timeout: float = 30.0) -> None:
        try:
            import distributed
        except ImportError:
            raise ConfigurationError(
                "--scheduler needs Dask: pip install 'nearopt[batch]' (dask[distributed])"
            ) from None
        self._distributed = distributed
        if isinstance(address, distributed.Client):
            self.client, self._own = address, False
        else:
            probe_scheduler(str(address))
            try:
                self.client = distributed.Client(address, timeout=timeout)
            except (OSError, TimeoutError, ValueError) as exc:
                raise ConfigurationError(
                    f"cannot connect to the Dask scheduler at {address}: {exc}"
                ) from None
            self._own = True
        self.workers = max(
            1, sum(w.get("nthreads", 1) for w in self.client.scheduler_info()["workers"].values())
        )

    def run(
        self,
        requests: Sequence[MotionRequest],
        rate: float,
        keep_result: bool,
        ros_bag: bool = False,
    ) -> Iterator[MotionOutcome]:
        distributed = self._distributed
        futures = {
            self.client.submit(
                plan_request,
                r,
                rate,
                keep_result,
                ros_bag,
                pure=False,
                key=f"nearopt-{r.id}-{time.time_ns()}",
            ): r
            for r in requests
        }
        try:
            for future in distributed.as_completed(futures):
                request = futures[future]
                try:
                    yield future.result()
                except distributed.KilledWorker:
                    yield worker_died(request, MAX_ATTEMPTS)
        finally:
            self.client.cancel(list(futures))

    retries_lost = True

    def submit(self, fn: Callable[..., Any], *args: object) -> Any:
        return self.client.submit(fn, *args, pure=False, key=f"nearopt-{uuid.uuid4().hex}")

    def wait(self, futures: Iterable[Any]) -> list[Any]:
        return list(self._distributed.wait(list(futures), return_when="FIRST_COMPLETED").done)

    def lost(self, exc: BaseException) -> bool:
        return isinstance(exc, self._distributed.KilledWorker)

    def cancel(self, futures: list[Any]) -> None:
        if futures:
            self.client.cancel(futures)

    def close(self, abort: bool = False) -> None:
        if self._own:
            self.client.close()


def pool_for(client: object | None, workers: int | None) -> Pool:
    if client is None:
        return LocalPool(workers)
    if isinstance(client, Pool):
        return client
    if workers is not None:
        raise ConfigurationError("workers applies to this machine's pool, not to a Dask client")
    if not isinstance(client, str) and type(client).__name__ != "Client":
        raise ConfigurationError(
            "client must be None (this machine), a scheduler address such as "
            f"'tcp://10.0.0.5:8786', a distributed.Client or a Pool, got "
            f"{type(client).__name__} {client!r:.60}"
        )
    return DaskPool(client)


@contextlib.contextmanager
def pool_in_use(client: object | None, workers: int | None) -> Iterator[Pool]:
    """:func:`pool_for` for a block; a pool made here is closed after it: at once, its workers
    stopped, if the block ends by an exception (Ctrl-C), else when its tasks are done."""
    pool = pool_for(client, workers)
    if pool is client:
        yield pool
        return
    aborted = True
    try:
        yield pool
        aborted = False
    finally:
        pool.close(abort=aborted)
