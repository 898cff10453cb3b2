"""A pool of worker processes that survives its workers: each worker is a spawned process (no fork after
torch/MediaPipe/numba threads exist) that runs one job at a time, sent over its own pipe. The parent knows
which job each worker holds, so a worker that dies (segfault, OOM kill, ``kill -9``) fails only that job,
which is retried once in a fresh worker while the others go on.

Generic over the job: ``task(job, progress) -> result`` and ``warm(*args)`` are top-level functions (the
spawned interpreter imports them by name). ``warm`` runs once per worker before its first job (what every job
would otherwise load: models, MediaPipe, compiled kernels stay loaded for the worker's life).

Signals: workers ignore SIGINT (a terminal's Ctrl-C reaches the whole process group; the parent decides);
SIGTERM makes a worker raise :class:`Stopped` inside its job, so staged outputs are removed on the way out.
A worker also gets SIGTERM when the parent dies (Linux ``PR_SET_PDEATHSIG``).
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import sys
import threading
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from multiprocessing.connection import Connection, wait
from pathlib import Path
from typing import Any, Protocol

STOP_GRACE_SECONDS = 30.0  # how long a stopping worker may take to clean up before it is killed
MAX_FAILED_STARTS = 3  # workers dying before they are ready: the environment is broken, not one job


class Stopped(BaseException):
    """SIGTERM in a worker: raised inside the running job (not an ``Exception``: nothing catches it as a failure)."""


class Listener(Protocol):
    """What the pool tells its caller (all calls in the parent, in order)."""

    def started(self, worker: int, index: int, attempt: int) -> None: ...

    def progress(self, worker: int, index: int, message: Any) -> None: ...

    def finished(self, worker: int, index: int, result: Any, attempt: int) -> None: ...

    def died(self, worker: int, index: int, reason: str, attempt: int, retry: bool) -> None: ...


@dataclass
class _Worker:
    number: int
    process: multiprocessing.process.BaseProcess
    connection: Connection
    job: int | None = None  # index of the job it holds
    ready: bool = False  # warm-up done
    pid: int = 0

    @property
    def idle(self) -> bool:
        return self.ready and self.job is None


@dataclass
class LocalPool:
    """Run ``task`` on every job in ``workers`` spawned processes; see the module docstring."""

    task: Callable[[Any, Callable[[Any], None]], Any]
    workers: int
    warm: Callable[..., None] | None = None
    warm_args: tuple = ()
    retries: int = 1  # extra attempts for a job whose worker died
    stderr: Path | None = None  # workers' native stderr (MediaPipe/TFLite chatter, crash reports) appended here
    _context: Any = field(default_factory=lambda: multiprocessing.get_context("spawn"), repr=False)

    def run(self, jobs: Sequence[Any], listener: Listener) -> None:
        """Run every job; returns when each has a result or has died ``1 + retries`` times.

        Any exception in the parent (e.g. an interrupt) stops the workers (SIGTERM, then SIGKILL after
        :data:`STOP_GRACE_SECONDS`) before it propagates.
        """
        pending = deque((index, 1) for index in range(len(jobs)))
        attempts: dict[int, int] = {}
        workers: list[_Worker] = []
        numbers = iter(range(1, 1 << 30))
        unready = 0  # workers that died before their warm-up ended
        try:
            workers = [self._start(next(numbers)) for _ in range(min(self.workers, len(jobs)))]
            while pending or any(w.job is not None for w in workers):
                for worker in workers:
                    if worker.idle and pending:
                        index, attempt = pending.popleft()
                        attempts[index] = attempt
                        worker.job = index
                        worker.connection.send((index, jobs[index]))
                        listener.started(worker.number, index, attempt)
                for worker in list(workers):
                    if self._serve(worker, listener, attempts):
                        continue
                    workers.remove(worker)  # dead
                    unready += not worker.ready
                    if unready > MAX_FAILED_STARTS:
                        raise RuntimeError(f"worker processes cannot start ({_death(worker.process)})")
                    if worker.job is not None:
                        index, attempt = worker.job, attempts[worker.job]
                        retry = attempt <= self.retries
                        listener.died(worker.number, index, _death(worker.process), attempt, retry)
                        if retry:
                            pending.appendleft((index, attempt + 1))
                    if pending and len(workers) < self.workers:
                        workers.append(self._start(next(numbers)))
                if not workers and pending:
                    workers.append(self._start(next(numbers)))
                _wait_any(workers)
        finally:
            _stop(workers)

    def _start(self, number: int) -> _Worker:
        parent, child = self._context.Pipe()
        process = self._context.Process(target=_worker_main, args=(child, self.task, self.warm, self.warm_args,
                                                                       self.stderr),
                                        name=f"deface-worker-{number}", daemon=True)
        # Only the main thread may set handlers; a pool run from another thread (deface serve) starts its workers
        # with the caller's SIGINT handling until their first line ignores it.
        main = threading.current_thread() is threading.main_thread()
        previous = signal.getsignal(signal.SIGINT) if main else None
        if previous is not None:
            signal.signal(signal.SIGINT, signal.SIG_IGN)  # inherited through exec: Ctrl-C never hits bootstrap
        try:
            process.start()
        finally:
            if previous is not None:
                signal.signal(signal.SIGINT, previous)
        child.close()
        return _Worker(number, process, parent, pid=process.pid or 0)

    def _serve(self, worker: _Worker, listener: Listener, attempts: dict[int, int]) -> bool:
        """Handle what ``worker`` sent; False when it is dead (its pipe closed or its process ended)."""
        alive = worker.process.is_alive()  # first: whatever a dead worker sent is in the pipe already
        try:
            while worker.connection.poll():
                kind, index, payload = worker.connection.recv()
                if kind == "ready":
                    worker.ready = True
                elif kind == "progress":
                    listener.progress(worker.number, index, payload)
                elif kind == "result":
                    worker.job = None
                    listener.finished(worker.number, index, payload, attempts[index])
        except (EOFError, OSError):
            pass
        if alive:
            return True
        worker.process.join()
        worker.connection.close()
        return False


def _wait_any(workers: list[_Worker], timeout: float = 1.0) -> None:
    handles = [w.connection for w in workers] + [w.process.sentinel for w in workers]
    if handles:
        wait(handles, timeout)


def _death(process) -> str:
    """Why a worker ended, in words: the signal (SIGKILL is usually the kernel's out-of-memory killer)."""
    code = process.exitcode
    if code is not None and code < 0:
        name = signal.Signals(-code).name
        hint = {"SIGKILL": " (out of memory, or kill -9)", "SIGSEGV": " (a crash in native code)"}.get(name, "")
        return f"worker process died: {name}{hint}"
    return f"worker process exited unexpectedly with code {code}"


def _stop(workers: list[_Worker]) -> None:
    """End the workers: a polite stop when idle, SIGTERM when busy (their job cleans up), then SIGKILL."""
    for worker in workers:
        try:
            if worker.job is None and worker.process.is_alive():
                worker.connection.send(None)
            elif worker.process.is_alive():
                worker.process.terminate()
        except (OSError, ValueError):
            worker.process.terminate()
    for worker in workers:
        worker.process.join(STOP_GRACE_SECONDS)
        if worker.process.is_alive():
            worker.process.kill()
            worker.process.join()
        worker.connection.close()


def _worker_main(connection: Connection, task, warm, warm_args: tuple, stderr: Path | None) -> None:
    if stderr is not None:
        descriptor = os.open(stderr, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o666)
        os.dup2(descriptor, 2)
        os.close(descriptor)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _raise_stopped)
    _die_with_parent()
    try:
        if warm is not None:
            try:
                warm(*warm_args)
            except Exception:  # noqa: BLE001 - only a head start: the first job meets the same error and reports it
                pass
        connection.send(("ready", None, None))
        while True:
            message = connection.recv()
            if message is None:
                return
            index, job = message
            result = task(job, lambda payload, index=index: connection.send(("progress", index, payload)))
            connection.send(("result", index, result))
    except (Stopped, EOFError, BrokenPipeError):
        sys.exit(0)  # stopped by the parent, or the parent is gone: the job removed its staged outputs


def _raise_stopped(_signum, _frame) -> None:
    raise Stopped()


def _die_with_parent() -> None:
    """SIGTERM this process when its parent dies (Linux); elsewhere the closed pipe ends it at the next job."""
    if not sys.platform.startswith("linux"):
        return
    import ctypes

    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        return
    if os.getppid() == 1:  # the parent died before the call
        os.kill(os.getpid(), signal.SIGTERM)
