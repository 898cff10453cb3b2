"""The queue of `deface serve`. A job is the files of one submission; each job runs as a batch on the worker pool
of `deface fit --jobs` (deface.batch: :class:`~deface.batch.task.Job`, ``run_job``, ``LocalPool`` with its
per-worker warm-up, and ``BatchRun``'s ``batch.jsonl`` record and log lines), so a fit here is the same fit, in
the same kind of process, as on the command line. Jobs run one after another (a second job waits and its page
says how many are ahead); the files of one job share the ``workers`` processes.

Each job gets ``OUT/<job id>/``: ``inputs/`` (the uploads), one folder per input as `deface fit -o OUT/<job id>`
writes it, ``batch.jsonl``, ``index.html``, and ``<input name>.zip`` per finished input (plus ``all.zip`` for
several). The page reads the state under :attr:`FitService.lock`.
"""

from __future__ import annotations

import json
import queue
import secrets
import shutil
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

from deface.batch.display import BatchDisplay, Tally
from deface.batch.pool import LocalPool
from deface.batch.run import WORKER_LOG, BatchRun, ProgressLog, cpu_count, warm_worker
from deface.batch.task import Job, Outcome, error_message, run_job
from deface.fit.config import FitConfig
from deface.io.inputs import InputItem
from deface.report.html import write_index
from deface.web.progress import FitClock, PaceBook, pace_key
from deface.web.results import zip_folders

ALL_ZIP = "all.zip"
CLOSE_SECONDS = 40.0  # how long close() waits for a running job's workers to stop (the pool's grace is 30 s)


class ServiceClosed(Exception):
    """Raised in the job's thread when the server stops: the pool stops its workers (they leave nothing
    half-written)."""


@dataclass
class InputState:
    """One input of a job, as the page shows it."""

    file: str  # the name it was uploaded as
    item: InputItem  # the staged copy under OUT/<job>/inputs
    status: str = "queued"  # queued, running, done, failed
    clock: FitClock | None = None  # while running: stage, step, time left
    error: str | None = None  # failed: one line, naming the uploaded file
    seconds: float | None = None
    zip: Path | None = None  # done: the zip of its output folder
    retrying: bool = False  # its worker died; it is queued again in a new one

    @property
    def name(self) -> str:
        return self.item.name


@dataclass
class WebJob:
    """The files of one submission and what became of them."""

    id: str
    folder: Path  # OUT/<id>
    preset: str  # as chosen in the page ("default" is recorded in params.json under its real name)
    config: FitConfig
    inputs: list[InputState]
    refused: list[str] = field(default_factory=list)  # uploads that were not queued, one line each
    status: str = "queued"  # queued, running, finished, removed (keep_jobs)
    error: str | None = None  # the job as a whole could not run (e.g. worker processes cannot start)
    zip: Path | None = None  # every finished input of a job of several
    workers: int = 0  # worker processes of its pool, once running

    def output(self, state: InputState) -> Path:
        return self.folder / state.name

    def count(self, status: str) -> int:
        return sum(state.status == status for state in self.inputs)


class FitService:
    """The job queue and its thread; see the module docstring."""

    def __init__(self, output: Path, models: Path | None = None, workers: int = 0, keep_jobs: int | None = None):
        self.output, self.models = Path(output), models
        self.workers = workers or cpu_count()
        self.keep_jobs = keep_jobs
        self.lock = threading.Lock()
        self.paces = PaceBook(self.output)  # time left learnt from the fits done here, kept across restarts
        self._jobs: list[WebJob] = []
        self._queue: queue.Queue[WebJob | None] = queue.Queue()
        self._closing = False
        self._thread = threading.Thread(target=self._serve, name="deface-jobs", daemon=True)
        self._thread.start()

    def new_folder(self) -> tuple[str, Path]:
        """A fresh job id and its folder ``OUT/<id>`` (created)."""
        while True:
            job_id = f"{time.strftime('%Y%m%d-%H%M%S')}-{secrets.token_hex(8)}"  # unguessable: OUT is served
            folder = self.output / job_id
            try:
                folder.mkdir(parents=True)
                return job_id, folder
            except FileExistsError:
                continue

    def submit(self, job: WebJob) -> WebJob:
        """Queue ``job`` (its inputs staged in its folder); a job without inputs is finished at once."""
        with self.lock:
            self._jobs.append(job)
            if not job.inputs:
                job.status = "finished"
                return job
        self._queue.put(job)
        return job

    def jobs(self, ids: list[str]) -> list[WebJob]:
        """The jobs with these ids, in the given order (call under :attr:`lock`)."""
        by_id = {job.id: job for job in self._jobs}
        return [by_id[job_id] for job_id in ids if job_id in by_id]

    def ahead(self, job: WebJob) -> int:
        """Jobs queued or running before ``job`` (call under :attr:`lock`)."""
        index = self._jobs.index(job)
        return sum(other.status in ("queued", "running") for other in self._jobs[:index])

    def close(self) -> None:
        """Stop taking jobs; a running job's workers are stopped (SIGTERM: no half-written outputs)."""
        self._closing = True
        self._queue.put(None)
        self._thread.join(CLOSE_SECONDS)

    def _serve(self) -> None:
        while (job := self._queue.get()) is not None:
            if self._closing:
                break
            self._run(job)

    def _run(self, job: WebJob) -> None:
        jobs = [Job(state.item, job.folder, job.config, self.models) for state in job.inputs]
        with self.lock:
            job.status, job.workers = "running", min(self.workers, len(jobs))
        tally = Tally(len(jobs))
        listener = JobListener(job.folder, job.config, tally, False, "local", jobs=jobs,
                               display=BatchDisplay(tally, live=False), job=job, service=self)
        pool = LocalPool(fit_task, job.workers, warm_worker, (job.config.model, self.models),
                         stderr=job.folder / WORKER_LOG)
        try:
            pool.run(jobs, listener)
        except ServiceClosed:
            return
        except Exception as error:  # noqa: BLE001 - the job fails in one line; the server goes on serving
            with self.lock:
                job.error = error_message(error)
                for state in job.inputs:
                    if state.status in ("queued", "running"):
                        state.status, state.error, state.clock = "failed", job.error, None
        write_index(job.folder, [state.name for state in job.inputs])
        done = [job.output(state) for state in job.inputs if state.status == "done"]
        all_zip = zip_folders(done, job.folder / ALL_ZIP) if len(done) > 1 else None
        with self.lock:
            job.zip, job.status = all_zip, "finished"
        self._forget_old()

    def _forget_old(self) -> None:
        """Remove the folders of finished jobs beyond the newest ``keep_jobs`` (only folders this server made)."""
        if self.keep_jobs is None:
            return
        with self.lock:
            finished = [job for job in self._jobs if job.status == "finished"]
            old = finished[:max(len(finished) - self.keep_jobs, 0)]
            for job in old:
                job.status = "removed"
        for job in old:
            shutil.rmtree(job.folder, ignore_errors=True)


@dataclass
class JobListener(BatchRun):
    """The pool's listener for one job: ``BatchRun``'s record and lines, plus the page's state."""

    job: WebJob | None = None
    service: FitService | None = None

    def started(self, worker: int, index: int, attempt: int, job: Job | None = None) -> None:
        self._check_open()
        super().started(worker, index, attempt, job)
        pace = self.service.paces.get(pace_key(self.config))
        with self.service.lock:
            state = self.job.inputs[index]
            state.status, state.clock = "running", FitClock.for_config(self.config, pace)

    def progress(self, worker: int, index: int, message) -> None:
        self._check_open()
        super().progress(worker, index, message)
        stage, step, _total = message
        with self.service.lock:
            clock = self.job.inputs[index].clock
            if clock is not None:
                clock.event(stage, step, time.monotonic())

    def finished(self, worker: int, index: int, outcome: Outcome, attempt: int) -> None:
        super().finished(worker, index, outcome, attempt)
        state = self.job.inputs[index]
        folder = self.job.output(state)
        zipped, error = None, None
        if outcome.status == "done":
            self._learn_pace(state, folder)
            try:
                zipped = zip_folders([folder], self.job.folder / f"{state.name}.zip")
            except OSError as failure:
                error = f"{state.file}: fitted, but its zip cannot be written ({failure.strerror or failure})"
        with self.service.lock:
            state.seconds, state.clock, state.zip = outcome.seconds, None, zipped
            state.status = "done" if outcome.status == "done" else "failed"
            state.error = error or (page_error(outcome.error, state) if outcome.status != "done" else None)

    def died(self, worker: int, index: int, reason: str, attempt: int, retry: bool) -> None:
        super().died(worker, index, reason, attempt, retry)
        with self.service.lock:
            state = self.job.inputs[index]
            state.clock, state.retrying = None, retry
            state.status = "queued" if retry else "failed"
            state.error = None if retry else f"{state.file}: {reason}"

    def _learn_pace(self, state: InputState, folder: Path) -> None:
        """The finished fit's stage times, with the steps its stages ran (params.json ``iterations_run``)."""
        clock = state.clock
        if clock is None:
            return
        try:
            run = json.loads((folder / "params.json").read_text()).get("iterations_run", {})
        except (OSError, ValueError):
            run = {}
        clock.steps.update({stage: int(steps) for stage, steps in run.items() if steps})
        self.service.paces.learn(pace_key(self.config), clock)

    def _check_open(self) -> None:
        if self.service._closing:
            raise ServiceClosed()


def page_error(error: str | None, state: InputState) -> str:
    """A failure's one line naming the file as uploaded instead of its staged copy on the server."""
    error = error or "failed"
    staged = str(state.item.path)
    return error.replace(staged, state.file) if staged in error else f"{state.file}: {error}"


class WebProgressLog(ProgressLog):
    """The worker's progress messages (stage starts and steps), and the start of the writing after the textures."""

    def stop(self, stage: str) -> float:
        elapsed = super().stop(stage)
        if stage == "textures":  # write_fit follows: the export, renders and report
            self._report(("writing", 0, 0))
        return elapsed


def fit_task(job: Job, report) -> Outcome:
    """One input in a worker process (the pool's task; top-level so the spawned worker imports it by name)."""
    return run_job(job, WebProgressLog(job.item.name, report))
