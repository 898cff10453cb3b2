"""``OUT/batch.jsonl``: one JSON line per input a batch handled, appended atomically, and its summary.

A line is written in one ``write`` on a file opened with ``O_APPEND`` while holding an exclusive ``flock``,
so lines of concurrent runs (or engines) never interleave and a killed run leaves only whole lines (a torn
last line, e.g. from a full disk, is ignored when reading).

Statuses: ``done`` (fitted and written), ``failed`` (the error says why; a worker that died is
``failed`` with ``attempt`` 1 and is tried once more), ``skipped`` (its output was already finished).
An input's state is its last ``done``/``failed`` line; ``skipped`` lines count only for inputs that have
neither (outputs made before the record existed).
"""

from __future__ import annotations

import fcntl
import json
import os
import statistics
import time
from collections.abc import Iterable
from dataclasses import asdict, dataclass, field
from pathlib import Path

from deface.models.ita import ITA_GROUPS, ita_group

RECORD_FILE = "batch.jsonl"
STATUSES = ("done", "failed", "skipped")


@dataclass(frozen=True)
class BatchRecord:
    """One line of ``batch.jsonl``."""

    path: str  # the input file as given on the command line
    output: str  # the input's output folder name under OUT
    status: str  # one of STATUSES
    seconds: float  # wall time of this attempt (0 for skipped)
    lights_kept: list[int] | None  # indices of the lights ACE kept (None: not known)
    error: str | None  # one-line reason of a failure
    version: str  # deface version that ran it
    preset: str  # preset name of the run's config
    attempt: int = 1  # 2 = the retry after a worker died
    engine: str = "local"  # "inline" (this process), "local" (worker processes) or "ray"
    cpu_seconds: float | None = None  # CPU time of the fitting process during the attempt (load-independent)
    skin_tone: dict | None = None  # done: params.json skin_tone ({"texture_ita", "ita_interval", ...}; may lack keys)
    finished: str = field(default_factory=lambda: time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()))

    def __post_init__(self) -> None:
        if self.status not in STATUSES:
            raise ValueError(f"batch record status must be one of {STATUSES}, got {self.status!r}")


def record_path(output: Path) -> Path:
    return Path(output) / RECORD_FILE


def append_record(output: Path, record: BatchRecord) -> None:
    """Append ``record`` as one line of ``OUT/batch.jsonl`` (created when missing)."""
    line = (json.dumps(asdict(record), separators=(", ", ": ")) + "\n").encode()
    path = record_path(output)
    path.parent.mkdir(parents=True, exist_ok=True)
    descriptor = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o666)
    try:
        fcntl.flock(descriptor, fcntl.LOCK_EX)
        written = os.write(descriptor, line)
        if written != len(line):  # a full disk: never leave half a line that the next one would join
            os.ftruncate(descriptor, os.fstat(descriptor).st_size - written)
            raise OSError(f"{path}: short write ({written} of {len(line)} bytes; disk full?)")
    finally:
        os.close(descriptor)  # releases the lock


def read_records(output: Path) -> list[BatchRecord]:
    """Every whole, well-formed line of ``OUT/batch.jsonl`` in order ([] when it does not exist)."""
    path = record_path(output)
    if not path.is_file():
        return []
    known = set(BatchRecord.__dataclass_fields__)
    records = []
    for line in path.read_text(errors="replace").splitlines():
        try:
            data = json.loads(line)
            records.append(BatchRecord(**{key: value for key, value in data.items() if key in known}))
        except (ValueError, TypeError):
            continue  # a torn or foreign line
    return records


def latest_states(records: Iterable[BatchRecord]) -> dict[str, BatchRecord]:
    """Input path -> the record that gives its state (last done/failed, else last skipped)."""
    states: dict[str, BatchRecord] = {}
    for record in records:
        previous = states.get(record.path)
        if record.status != "skipped" or previous is None or previous.status == "skipped":
            states[record.path] = record
    return states


SURE_TONE_WIDTH = 20.0
"""An ITA interval this wide or narrower (degrees) pins the tone to about one skin category (:data:`ITA_GROUPS`
spans 13-18 degrees between its bounds): a white patch in the scene, a card or a given white level."""


def tone_text(tone: dict | None) -> str:
    """", skin ITA 42 (30 to 51)" for a done line (no range for a known light); "" without a tone."""
    if tone is None:
        return ""
    if tone.get("texture_ita") is None:
        return ", skin tone not shown (grayscale photo)" if tone.get("note") else ""
    interval = tone.get("ita_interval")
    open_range = interval is not None and interval[1] > interval[0]
    span = f" ({interval[0]:.0f} to {interval[1]:.0f})" if open_range else ""
    return f", skin ITA {tone['texture_ita']:.0f}{span}"


def tone_lines(states: Iterable[BatchRecord]) -> list[str]:
    """The skin tones of the done inputs by category, and how many the light level leaves open (for balancing a
    data set by tone; docs/skin-tone.md)."""
    tones = [r.skin_tone for r in states
             if r.status == "done" and r.skin_tone is not None and r.skin_tone.get("texture_ita") is not None]
    if not tones:
        return []
    counts = {name: 0 for name, _ in ITA_GROUPS}
    for tone in tones:
        counts[ita_group(tone["texture_ita"])] += 1
    widths = [tone["ita_interval"][1] - tone["ita_interval"][0] for tone in tones if tone.get("ita_interval")]
    line = (f"skin tones of {len(tones)} fit(s) (ITA categories of Del Bino et al. 2006): "
            + ", ".join(f"{name} {count}" for name, count in counts.items()))
    if not widths:
        return [line]
    sure = sum(width <= SURE_TONE_WIDTH for width in widths)
    lines = [line, f"{sure} of {len(widths)} within {SURE_TONE_WIDTH:.0f} degrees for the light level (one-sigma "
                   f"interval, median {statistics.median(widths):.0f}){_two_sigma(tones)}; the rest: a grey card "
                   "(--card), a colour checker or a known white level (--white) narrows them"]
    sources = [tone["light_level"] for tone in tones if tone.get("light_level")]
    if sources:
        lines.append("light level from: " + ", ".join(f"{name} {sources.count(name)}"
                                                      for name in sorted(set(sources), key=sources.index)))
    return lines


def _two_sigma(tones: list[dict]) -> str:
    """", two-sigma median 31" over the tones that record it ("" before they did)."""
    widths = [t["ita_interval_2sigma"][1] - t["ita_interval_2sigma"][0] for t in tones if t.get("ita_interval_2sigma")]
    return f", two-sigma median {statistics.median(widths):.0f}" if widths else ""


@dataclass(frozen=True)
class BatchSummary:
    """What ``deface batch status`` prints, from the records of one output folder."""

    inputs: int  # distinct input paths recorded
    done: int  # last state done
    skipped: int  # only ever found finished (made before the record, or by a run without one)
    failed: list[BatchRecord]  # last state failed
    retried: int  # inputs whose worker died at least once
    fit_seconds: float  # sum of the seconds of done attempts
    mean_seconds: float | None  # per done attempt
    mean_cpu_seconds: float | None  # CPU time per done attempt (where recorded)
    versions: list[str]
    presets: list[str]
    tones: list[str] = field(default_factory=list)  # the lines of tone_lines

    def lines(self) -> list[str]:
        if not self.inputs:
            return ["no inputs recorded"]
        mean = f", {self.mean_seconds:.1f} s per fitted input" if self.mean_seconds is not None else ""
        mean += f" ({self.mean_cpu_seconds:.1f} s of CPU)" if self.mean_cpu_seconds is not None else ""
        text = [f"{self.inputs} input(s): {self.done} done, {self.skipped} found finished, {len(self.failed)} failed"
                f" ({self.retried} retried after a worker died); {self.fit_seconds / 3600:.2f} h of fitting{mean}",
                f"preset(s): {', '.join(self.presets)}; deface version(s): {', '.join(self.versions)}"]
        if len(self.presets) > 1:
            text.append("warning: more than one preset in this folder (`deface fit` refuses to mix them unless "
                        "--overwrite redoes the finished outputs)")
        text += self.tones
        text += [f"failed: {record.path}: {record.error}" for record in self.failed]
        return text


def summarise(records: list[BatchRecord]) -> BatchSummary:
    states = latest_states(records)
    done = [r for r in records if r.status == "done"]
    return BatchSummary(
        inputs=len(states),
        done=sum(r.status == "done" for r in states.values()),
        skipped=sum(r.status == "skipped" for r in states.values()),
        failed=[r for r in states.values() if r.status == "failed"],
        retried=len({r.path for r in records if r.attempt > 1}),
        fit_seconds=sum(r.seconds for r in done),
        mean_seconds=sum(r.seconds for r in done) / len(done) if done else None,
        mean_cpu_seconds=sum(cpu) / len(cpu) if (cpu := [r.cpu_seconds for r in done if r.cpu_seconds]) else None,
        versions=sorted({r.version for r in records if r.status != "skipped"} or {r.version for r in records}),
        presets=sorted({r.preset for r in states.values()}),
        tones=tone_lines(states.values()),
    )
