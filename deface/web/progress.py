"""Time left of a running fit, from the stage events its worker sends (deface.batch.run.ProgressLog: a stage's
start, then its step at most every 0.5 s) and the pace of the fits this server finished with the same settings.

A fit runs the stages of :data:`STAGES` in order; stages 2 and 3 report steps (their counts come from the config;
stage 3 may stop early, so its estimate is an upper bound). The running stage's pace is measured as it runs:
stage 2's first ``stage2_coarse_share`` of steps run at half size (deface/fit/coarse.py), each costing about
:data:`COARSE_COST` of a full step, so its rest is extrapolated from the full-size steps once there are some. Later
stages take the pace recorded for this configuration (:class:`PaceBook`, kept in the output folder across
restarts), or before any such fit finished, :data:`FIRST_GUESS` multiples of stage 2's full-size step. Before stage 2
has taken a few steps nothing is known: None.
"""

from __future__ import annotations

import hashlib
import json
import os
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

from deface.fit.config import FitConfig, to_dict

STAGES = ("landmarks", "stage 1", "stage 2", "stage 3", "textures", "writing")
STEPPED = ("stage 2", "stage 3")
COARSE_COST = 0.4  # a half-size stage-2 step against a full-size one (docs/design.md, "Stage 2 coarse-to-fine")
FIRST_GUESS = {"stage 3": 2.0, "textures": 2.0, "writing": 20.0}
"""Before any fit of a configuration finished: a stage-3 step, the texture completion and the writing of the outputs
as multiples of stage 2's full-size step (measured on a 2-core machine: stage 3 1.4 with the fast preset's 256-texel
maps, 2.6 with the default's 512; textures 1-3; writing about 20). The stages before stage 2 are over by the time
that step is known."""
MEASURED_AFTER = 3  # steps of a stage (or of its full-size part) before their own pace is trusted
PACE_FILE = ".deface-web-paces.json"


def pace_key(config: FitConfig) -> str:
    """Fits with equal keys run at the same pace: the same preset, settings and schedule (threads aside)."""
    settings = {key: value for key, value in to_dict(config).items() if key != "threads"}
    return hashlib.sha1(json.dumps(settings, sort_keys=True, default=str).encode()).hexdigest()[:16]


@dataclass
class PaceBook:
    """Seconds of each stage (per step for :data:`STEPPED`) of the latest finished fit of each configuration; kept
    in ``folder/PACE_FILE`` when a folder is given."""

    folder: Path | None = None
    paces: dict[str, dict[str, float]] = field(default_factory=dict)
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def __post_init__(self) -> None:
        if self.folder is not None:
            try:
                self.paces = {key: {stage: float(seconds) for stage, seconds in pace.items() if stage in STAGES}
                              for key, pace in json.loads((self.folder / PACE_FILE).read_text()).items()}
            except (OSError, ValueError, AttributeError, TypeError):
                self.paces = {}  # none yet, or unreadable: the first fits guess

    def get(self, key: str) -> dict[str, float] | None:
        with self._lock:
            return self.paces.get(key)

    def learn(self, key: str, clock: FitClock, now: float | None = None) -> None:
        """Record the stage times of a fit that just finished (``clock`` followed it; its ``steps`` are the steps
        each stepped stage ran)."""
        pace = {}
        for stage, seconds in clock.durations(time.monotonic() if now is None else now).items():
            if stage not in STEPPED:
                pace[stage] = seconds
            elif clock.steps.get(stage):
                pace[stage] = seconds / clock.steps[stage]
        with self._lock:
            self.paces[key] = {**self.paces.get(key, {}), **pace}
            text = json.dumps(self.paces, indent=1)
        if self.folder is not None:
            partial = self.folder / f".{PACE_FILE}.partial"
            try:
                partial.write_text(text)
                os.replace(partial, self.folder / PACE_FILE)
            except OSError:
                pass  # only a better first estimate after a restart is lost


@dataclass
class FitClock:
    """Follows one fit: which stage, which step, since when; :meth:`seconds_left` estimates the rest."""

    totals: dict[str, int]  # steps of stage 2 and stage 3 (the config's)
    pace: dict[str, float] | None = None  # PaceBook entry of this configuration, if any
    coarse_steps: int = 0  # stage 2's first steps at half size
    stage: str | None = None
    step: int = 0
    starts: dict[str, float] = field(default_factory=dict)  # stage -> when its first event came
    steps: dict[str, int] = field(default_factory=dict)  # stepped stage -> the last step reported
    full_from: tuple[float, int] | None = None  # (time, step) of stage 2's first report past its coarse steps
    full_rate: float | None = None  # stage 2's latest estimate of a full-size step (seconds)

    @classmethod
    def for_config(cls, config: FitConfig, pace: dict[str, float] | None = None) -> FitClock:
        iterations = config.iterations
        return cls({"stage 2": iterations.stage2, "stage 3": iterations.stage3}, pace,
                   int(iterations.stage2 * iterations.stage2_coarse_share))

    def event(self, stage: str, step: int, now: float) -> None:
        """A progress message: ``stage`` started (step 0) or reached ``step``."""
        if stage != self.stage:
            if self.stage == "stage 2" and self.full_from is not None and self.step > self.full_from[1]:
                self.full_rate = (now - self.full_from[0]) / (self.step - self.full_from[1])  # its full-size steps
            self.stage, self.step = stage, 0
            self.starts.setdefault(stage, now)
        if step:
            self.step = step
            self.steps[stage] = step
            if stage == "stage 2" and step > self.coarse_steps and self.full_from is None:
                self.full_from = (now, step)

    def durations(self, now: float) -> dict[str, float]:
        """Seconds each seen stage took (the last one until ``now``)."""
        seen = sorted(self.starts.items(), key=lambda item: item[1])
        ends = [start for _, start in seen[1:]] + [now]
        return {stage: end - start for (stage, start), end in zip(seen, ends, strict=True)}

    def seconds_left(self, now: float) -> float | None:
        """Estimated seconds until the fit is written, or None while nothing is known yet."""
        if self.stage not in STAGES:
            return None
        current = self._current_left(now)
        if current is None:
            return None
        later = STAGES[STAGES.index(self.stage) + 1:]
        pace = self._expected_pace()
        if any(stage not in pace for stage in later):
            return None
        return current + sum(pace[stage] * (self.totals[stage] if stage in STEPPED else 1) for stage in later)

    def _expected_pace(self) -> dict[str, float]:
        """The recorded pace of this configuration, else the first guess from stage 2's full-size step."""
        if self.pace:
            return self.pace
        if self.full_rate is None:
            return {}
        return {stage: factor * self.full_rate for stage, factor in FIRST_GUESS.items()}

    def _current_left(self, now: float) -> float | None:
        """Seconds left in the running stage: its measured pace, else the expected one."""
        stage, step = self.stage, self.step
        elapsed = now - self.starts[stage]
        if stage == "stage 2":
            measured = self._stage2_left(now, elapsed)
            if measured is not None:
                return measured
        elif stage == "stage 3" and step >= MEASURED_AFTER:
            return (self.totals[stage] - step) * elapsed / step
        pace = self._expected_pace()
        if stage not in pace:
            return None
        planned = pace[stage] * (self.totals[stage] if stage in STEPPED else 1)
        return max(planned - elapsed, 0.0)

    def _stage2_left(self, now: float, elapsed: float) -> float | None:
        step, total, coarse = self.step, self.totals["stage 2"], self.coarse_steps
        if self.full_from is not None and step - self.full_from[1] >= MEASURED_AFTER:
            self.full_rate = (now - self.full_from[0]) / (step - self.full_from[1])
            return (total - step) * self.full_rate
        if self.full_from is None and step >= MEASURED_AFTER:  # still in the half-size steps
            rate = elapsed / step
            self.full_rate = rate / COARSE_COST if coarse else rate
            return max(coarse - step, 0) * rate + (total - max(step, coarse)) * self.full_rate
        if self.full_rate is not None:  # just past the half-size steps: their estimate until full ones are timed
            return (total - step) * self.full_rate
        return None


def duration_text(seconds: float | None) -> str:
    """``about 2 min 10 s`` / ``about 40 s`` / ``estimating`` (None)."""
    if seconds is None:
        return "estimating"
    seconds = max(0, round(seconds))
    if seconds < 60:
        return f"about {max(seconds, 1)} s"
    minutes, rest = divmod(seconds, 60)
    if minutes >= 60:
        return f"about {minutes // 60} h {minutes % 60} min"
    return f"about {minutes} min {rest} s" if minutes < 10 else f"about {minutes} min"
