"""A batch of `deface fit`: plan the (re)run, fit each input in this process or in worker processes, print one
line per input (or the live display), append ``OUT/batch.jsonl``, and stop cleanly on SIGINT/SIGTERM.
"""

from __future__ import annotations

import os
import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

from rich.markup import escape

from deface._version import __version__
from deface.batch.display import BatchDisplay, Tally, Throttle
from deface.batch.pool import LocalPool
from deface.batch.record import BatchRecord, append_record, tone_text
from deface.batch.resume import Plan, plan_batch
from deface.batch.task import Job, Outcome, run_job
from deface.fit.config import FitConfig
from deface.fit.log import FitLog
from deface.io.inputs import InputItem
from deface.report.html import write_index

PROGRESS_SECONDS = 0.5  # a worker reports its stage at most this often
WORKER_LOG = "batch-workers.log"  # the workers' stderr: native libraries' messages, crash reports


class Interrupted(BaseException):
    """SIGINT or SIGTERM arrived; raised in the main thread so staged outputs are removed on the way out."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def cpu_count() -> int:
    """Cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


@dataclass(frozen=True)
class BatchOptions:
    """How to run a batch (the command line's choices)."""

    jobs: int = 1  # worker processes; 0 = one per core; 1 = fit in this process
    overwrite: bool = False
    retry_failed: bool = False
    quiet: bool = False
    verbose: bool = False
    engine: str = "local"  # "local" or "ray"
    ray_address: str | None = None
    ray_outputs: str = "driver"  # "driver" (returned to the driver, which writes them) or "shared"


def run_batch(items: list[InputItem], output: Path, config: FitConfig, models: Path | None = None,
              options: BatchOptions = BatchOptions()) -> int:
    """Fit every input of ``items`` that needs it -> the number that failed.

    Raises :class:`deface.batch.resume.SettingsMismatch` before any work when finished outputs were made
    with other settings, and :class:`Interrupted` (after printing one line) on SIGINT/SIGTERM.
    """
    plan = plan_batch(items, output, config, options.overwrite, options.retry_failed)
    jobs = [Job(item, output, config, models, options.overwrite) for item in plan.todo]
    workers = min(options.jobs or cpu_count(), len(jobs))
    tally = Tally(len(items), left=len(plan.left))  # report_plan counts the finished ones
    engine = "ray" if options.engine == "ray" else "local" if workers > 1 else "inline"
    batch = BatchRun(output, config, tally, options.verbose, engine, jobs=jobs)
    with BatchDisplay(tally, live=not options.quiet and engine != "inline") as display:
        batch.display = display
        batch.report_plan(plan)
        try:
            with signals_raise():
                if engine == "ray":
                    from deface.batch.ray_engine import run_on_ray

                    run_on_ray(jobs, batch, options)
                elif engine == "local":
                    output.mkdir(parents=True, exist_ok=True)
                    LocalPool(pool_task, workers, warm_worker, (config.model, models),
                              stderr=output / WORKER_LOG).run(jobs, batch)
                else:
                    for index, job in enumerate(jobs):
                        batch.started(0, index, 1, job)
                        batch.finished(0, index, run_job(job, FitLog(name=job.item.name, quiet=options.quiet)), 1)
        except Interrupted as stop:
            display.__exit__(None, None, None)
            during = ", ".join(str(job.item.path) for job in batch.running.values()) or "the start"
            display.line(f"interrupted ({stop}) during {during}: {tally.summary()}, {tally.remaining} not done; "
                         "run the same command again to resume (finished inputs are skipped)")
            raise
    write_index(output, [item.name for item in items])
    display.line(f"{tally.summary()}; outputs in {output} (index.html)")
    return tally.failed


@dataclass
class BatchRun:
    """Listens to an engine (:class:`deface.batch.pool.Listener`): records, lines and the display."""

    output: Path
    config: FitConfig
    tally: Tally
    verbose: bool
    engine: str
    jobs: list[Job] = field(default_factory=list)
    display: BatchDisplay | None = None
    running: dict[int, Job] = field(default_factory=dict)  # worker -> job

    def report_plan(self, plan: Plan) -> None:
        for item in plan.finished:
            self.record(item, Outcome("skipped", 0.0), 1)
        if plan.left:
            self.display.line(f"--retry-failed: {len(plan.left)} unfinished input(s) that never failed are left "
                              "(run without --retry-failed to fit them)")

    def started(self, worker: int, index: int, attempt: int, job: Job | None = None) -> None:
        job = job or self.jobs[index]
        self.running[worker] = job
        again = " (retry)" if attempt > 1 else ""
        self.display.stage(worker, f"{job.item.path.name}{again}: starting")

    def progress(self, worker: int, index: int, message) -> None:
        stage, step, total = message
        job = self.running.get(worker)
        if job is not None:
            where = f" {step}/{total}" if total else ""
            self.display.stage(worker, f"{job.item.path.name}: {stage}{where}")

    def finished(self, worker: int, index: int, outcome: Outcome, attempt: int) -> None:
        job = self.running.pop(worker)
        self.display.stage(worker, None)
        self.record(job.item, outcome, attempt)

    def died(self, worker: int, index: int, reason: str, attempt: int, retry: bool) -> None:
        job = self.running.pop(worker)
        self.display.stage(worker, None)
        self.record(job.item, Outcome("failed", 0.0, error=reason), attempt, final=not retry)
        if retry:
            self.display.line(f"{job.item.path}: retrying once in a new worker")

    def record(self, item: InputItem, outcome: Outcome, attempt: int, final: bool = True) -> None:
        """Print the input's line, count it (``final``) and append its record (not for "busy")."""
        folder = self.output / item.name
        if outcome.status == "done":
            kept = f", lights kept {list(outcome.lights_kept)}" if outcome.lights_kept is not None else ""
            self.display.line(escape(f"{item.path}: done in {outcome.seconds:.1f} s{kept}{tone_text(outcome.skin_tone)}"
                                     f" -> {folder}"))
        elif outcome.status == "skipped":
            self.display.line(escape(f"{item.path}: already done in {folder} (use --overwrite to redo)"))
        elif outcome.status == "busy":
            self.display.line(escape(outcome.error))
        else:
            if self.verbose and outcome.detail:
                self.display.line(escape(outcome.detail))
            message = outcome.error if str(item.path) in outcome.error else f"{item.path}: {outcome.error}"
            self.display.line(f"[red]error:[/red] {escape(message)}")
        if final:
            counter = {"skipped": "done"}.get(outcome.status, outcome.status)
            setattr(self.tally, counter, getattr(self.tally, counter) + 1)
            self.display.refresh()
        if outcome.status != "busy":
            self._append(item, outcome, attempt)

    def _append(self, item: InputItem, outcome: Outcome, attempt: int) -> None:
        record = BatchRecord(
            path=str(item.path), output=item.name, status=outcome.status, seconds=round(outcome.seconds, 3),
            lights_kept=list(outcome.lights_kept) if outcome.lights_kept is not None else None,
            error=outcome.error, version=__version__, preset=self.config.preset, attempt=attempt,
            engine=self.engine,
            cpu_seconds=round(outcome.cpu_seconds, 3) if outcome.cpu_seconds is not None else None,
            skin_tone=outcome.skin_tone)
        try:
            append_record(self.output, record)
        except OSError as error:
            self.display.line(f"[red]error:[/red] {escape(str(self.output))}: cannot append to batch.jsonl ({error})")


# --- what runs in each worker process -------------------------------------------------------------------


class ProgressLog(FitLog):
    """A quiet :class:`FitLog` that reports the stage and step to the parent, at most every 0.5 s."""

    def __init__(self, name: str, report):
        super().__init__(name=name, quiet=True)
        self._report, self._throttle = report, Throttle(PROGRESS_SECONDS)

    def start(self, stage: str) -> None:
        super().start(stage)
        self._report((stage, 0, 0))

    def step(self, stage: str, step: int, total: int, loss: float, terms: dict[str, float] | None = None) -> None:
        super().step(stage, step, total, loss, terms)
        if self._throttle():
            self._report((stage, step + 1, total))


def pool_task(job: Job, report) -> Outcome:
    """One input in a worker (1 torch thread unless the config asks for more)."""
    return run_job(job, ProgressLog(job.item.name, report))


def warm_worker(model: str, models: Path | None) -> None:
    """Load once per worker what every fit needs: torch with one thread, the face model and its
    correspondences, MediaPipe's face mesh. Compiled kernels load at the first fit and stay."""
    import torch

    from deface.landmarks.correspondence import correspondence_for
    from deface.landmarks.detect import FaceMeshDetector
    from deface.models.registry import load_face_model

    torch.set_num_threads(1)
    correspondence_for(load_face_model(model, models), models_dir=models)
    FaceMeshDetector().close()


@contextmanager
def signals_raise() -> Iterator[None]:
    """Turn SIGINT and SIGTERM into :class:`Interrupted` (main thread only), restoring the handlers after."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {number: signal.getsignal(number) for number in (signal.SIGINT, signal.SIGTERM)}

    def interrupt(signum, _frame):
        raise Interrupted(signum)

    for number in previous:
        signal.signal(number, interrupt)
    try:
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)
