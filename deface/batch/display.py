"""The progress of a batch on the terminal: one rich display (inputs done/failed/remaining, ETA, the stage of
each worker), or one line per input with ``--quiet`` or when stderr is not a terminal."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

from rich.console import Group
from rich.live import Live
from rich.markup import escape
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn
from rich.table import Table

from deface.fit.log import console


@dataclass
class Tally:
    """Counts of one run, for the display and the summary line."""

    total: int
    done: int = 0
    failed: int = 0
    busy: int = 0  # another run holds its output folder
    left: int = 0  # not attempted in this run (--retry-failed: never failed)

    @property
    def remaining(self) -> int:
        return self.total - self.done - self.failed - self.busy - self.left

    def summary(self) -> str:
        busy = f", {self.busy} left to another run" if self.busy else ""
        left = f", {self.left} not attempted (--retry-failed)" if self.left else ""
        return f"{self.done} of {self.total} input(s) done, {self.failed} failed{busy}{left}"


@dataclass
class BatchDisplay:
    """Live view of a batch; ``line`` prints a message above it (or alone when the view is off)."""

    tally: Tally
    live: bool  # False: lines only (--quiet, or not a terminal)
    stages: dict[int, str] = field(default_factory=dict)  # worker -> "input: stage step/total"
    _progress: Progress | None = None
    _task: int | None = None
    _view: Live | None = None

    def __enter__(self) -> BatchDisplay:
        if self.live and console.is_terminal:
            self._progress = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                                      TextColumn("{task.fields[counts]}"), TimeElapsedColumn(), TextColumn("ETA"),
                                      TimeRemainingColumn(), console=console)
            self._task = self._progress.add_task("inputs", total=self.tally.total, counts=self._counts())
            self._view = Live(self._render(), console=console, refresh_per_second=4, transient=True)
            self._view.__enter__()
        return self

    def __exit__(self, *exc) -> None:
        if self._view is not None:
            self._view.__exit__(*exc)
            self._view = None

    def line(self, text: str) -> None:
        console.print(text)

    def stage(self, worker: int, text: str | None) -> None:
        if text is None:
            self.stages.pop(worker, None)
        else:
            self.stages[worker] = text
        self.refresh()

    def refresh(self) -> None:
        if self._view is not None:
            self._progress.update(self._task, completed=self.tally.total - self.tally.remaining,
                                  counts=self._counts())
            self._view.update(self._render())

    def _counts(self) -> str:
        return f"done {self.tally.done}  failed {self.tally.failed}  remaining {self.tally.remaining}"

    def _render(self):
        table = Table.grid(padding=(0, 2))
        for worker in sorted(self.stages):
            table.add_row(f"[dim]worker {worker}[/dim]", escape(self.stages[worker]))
        return Group(self._progress, table)


class Throttle:
    """True at most once per ``seconds`` (progress messages from a worker's every step)."""

    def __init__(self, seconds: float):
        self.seconds, self._last = seconds, 0.0

    def __call__(self) -> bool:
        now = time.monotonic()
        if now - self._last < self.seconds:
            return False
        self._last = now
        return True
