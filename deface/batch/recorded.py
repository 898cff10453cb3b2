"""Tasks that record their result, with the configuration they ran with, in one JSON file: the benchmarks' fits
(deface/eval: a variant on a shadow pair, a photo of a skin-tone set, a render of a truth set). They run on the
batch's machinery: a rerun skips every task whose record holds this very configuration
(:func:`deface.batch.resume.finished_record`; another configuration is redone), and the rest run in this process
(one job) or in the batch's worker pool (:class:`deface.batch.pool.LocalPool`: spawned workers warmed once with the
face model and MediaPipe, 1 torch thread each; a dead worker's task is tried once more in a fresh one).
"""

from __future__ import annotations

import json
import os
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from deface.batch.pool import LocalPool
from deface.batch.resume import config_record, finished_record
from deface.batch.run import warm_worker
from deface.fit.config import FitConfig


@dataclass(frozen=True)
class RecordedTask:
    """One task (picklable: ``work`` is a top-level function or a ``functools.partial`` of one)."""

    name: str  # for the log and errors, e.g. "ours / 000031-00"
    record: Path  # the JSON file written last; the task is finished when it holds ``config``
    config: FitConfig
    work: Callable[[], dict]  # fits and writes its outputs beside ``record`` -> the record's fields


class TaskFailed(RuntimeError):
    """A task failed in a worker process (its name and the worker's traceback), or its worker died twice."""


def run_recorded(tasks: list[RecordedTask], jobs: int = 1, models_dir=None,
                 on_record: Callable[[int, dict], None] | None = None) -> list[dict]:
    """Every task's record, in order: the finished ones read back, the others run (``jobs`` at a time) and
    written. ``on_record(index, record)`` is called in task order as the records become available. Raises
    :class:`TaskFailed` when a task failed in a worker, after the others have run (one job: its exception)."""
    records: list[dict | None] = [finished_record(task.record, task.config) for task in tasks]
    todo = [index for index, record in enumerate(records) if record is None]
    reported = _InOrder(records, on_record)
    reported()
    workers = min(jobs, len(todo))
    if workers <= 1:
        for index in todo:
            records[index] = run_task(tasks[index])
            reported()
        return records
    listener = _Listener(tasks, todo, records, reported)
    LocalPool(_pool_task, workers, warm_worker, (tasks[todo[0]].config.model, models_dir)).run(
        [tasks[index] for index in todo], listener)
    if listener.failures:
        index, detail = min(listener.failures)
        others = f" (and {len(listener.failures) - 1} more)" if len(listener.failures) > 1 else ""
        raise TaskFailed(f"{tasks[index].name} failed{others}: {detail}")
    return records


def run_task(task: RecordedTask) -> dict:
    """Run one task and write its record (its fields, then its configuration), atomically."""
    record = {**task.work(), "config": config_record(task.config)}
    task.record.parent.mkdir(parents=True, exist_ok=True)
    partial = task.record.with_name(f".{task.record.name}.partial")
    partial.write_text(json.dumps(record, indent=1))
    os.replace(partial, task.record)  # whole or absent: a kill mid-write leaves the task to be redone
    return record


def _pool_task(task: RecordedTask, _progress) -> tuple[str, object]:
    """In a worker: ("done", record) or ("failed", traceback); a failure does not end the worker."""
    try:
        return "done", run_task(task)
    except Exception:  # noqa: BLE001 - the parent raises it with the task's name once the others have run
        return "failed", traceback.format_exc().rstrip()


@dataclass
class _InOrder:
    """Calls ``on_record`` for each record in task order, as far as the records are there."""

    records: list[dict | None]
    on_record: Callable[[int, dict], None] | None
    next: int = 0

    def __call__(self) -> None:
        while self.next < len(self.records) and self.records[self.next] is not None:
            if self.on_record is not None:
                self.on_record(self.next, self.records[self.next])
            self.next += 1


@dataclass
class _Listener:
    """What the pool reports (:class:`deface.batch.pool.Listener`): records in place, failures kept."""

    tasks: list[RecordedTask]
    todo: list[int]  # the pool's job index -> the task's index
    records: list[dict | None]
    reported: _InOrder
    failures: list[tuple[int, str]] = field(default_factory=list)  # (task index, traceback or reason)

    def started(self, worker: int, index: int, attempt: int) -> None:
        pass

    def progress(self, worker: int, index: int, message) -> None:
        pass

    def finished(self, worker: int, index: int, result: tuple[str, object], attempt: int) -> None:
        status, value = result
        if status == "failed":
            self.failures.append((self.todo[index], value))
            return
        self.records[self.todo[index]] = value
        self.reported()

    def died(self, worker: int, index: int, reason: str, attempt: int, retry: bool) -> None:
        if not retry:
            self.failures.append((self.todo[index], reason))
