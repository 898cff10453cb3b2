"""Time left of a running fit, from the stage events its worker sends (deface.batch.run.ProgressLog: a stage's
start, then its step every 0.5 s) and the pace of the fits this server finished with the same settings.

A fit runs the stages of :data:`STAGES` in order; stages 2 and 3 report steps (their counts come from the config;
stage 3 may stop early, so its estimate is an upper bound). The current stage's pace is measured as it runs; later
stages take the pace recorded for this configuration, or before any fit finished, a first guess relative to
stage 2's measured step (:data:`FIRST_GUESS`). Before stage 2 has taken a step nothing is known: None.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field

from deface.fit.config import FitConfig, to_dict

STAGES = ("landmarks", "stage 1", "stage 2", "stage 3", "textures", "writing")
STEPPED = ("stage 2", "stage 3")
FIRST_GUESS = {"landmarks": 0.0, "stage 1": 0.0, "stage 3": 0.7, "textures": 1.0, "writing": 8.0}
"""Before any fit finished: stage 3's step, the texture completion and the writing as multiples of stage 2's
measured step (a fast-preset fit on this project's 2-core test machine: 0.7, ~1 and ~8). The stages before stage 2
are over by the time it is known."""
MEASURED_AFTER = 2  # steps of a stage before its own pace is trusted over the recorded one


def pace_key(config: FitConfig) -> str:
    """Fits with equal keys run at the same pace (same preset, settings and schedule)."""
    return repr(sorted(to_dict(config).items()))


@dataclass
class PaceBook:
    """Seconds of each stage (per step for :data:`STEPPED`), from the latest finished fit of each configuration."""

    paces: dict[str, dict[str, float]] = field(default_factory=dict)
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

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


@dataclass
class FitClock:
    """Follows one fit: which stage, which step, since when; :meth:`seconds_left` estimates the rest."""

    totals: dict[str, int]  # steps of stage 2 and stage 3 (the config's)
    pace: dict[str, float] | None = None  # PaceBook entry of this configuration, if any
    stage: str | None = None
    step: int = 0
    starts: dict[str, float] = field(default_factory=dict)  # stage -> when its first event came
    steps: dict[str, int] = field(default_factory=dict)  # stepped stage -> the last step reported

    @classmethod
    def for_config(cls, config: FitConfig, pace: dict[str, float] | None = None) -> FitClock:
        return cls({"stage 2": config.iterations.stage2, "stage 3": config.iterations.stage3}, pace)

    def event(self, stage: str, step: int, now: float) -> None:
        """A progress message: ``stage`` started (step 0) or reached ``step``."""
        if stage != self.stage:
            self.stage, self.step = stage, 0
            self.starts.setdefault(stage, now)
        if step:
            self.step = step
            self.steps[stage] = step

    def durations(self, now: float) -> dict[str, float]:
        """Seconds each seen stage took (the last one until ``now``)."""
        seen = sorted(self.starts.items(), key=lambda item: item[1])
        ends = [start for _, start in seen[1:]] + [now]
        return {stage: end - start for (stage, start), end in zip(seen, ends, strict=True)}

    def seconds_left(self, now: float) -> float | None:
        """Estimated seconds until the fit is written, or None while nothing is known yet."""
        if self.stage not in STAGES:
            return None
        current = STAGES.index(self.stage)
        elapsed = now - self.starts[self.stage]
        rate = elapsed / self.step if self.stage in STEPPED and self.step >= MEASURED_AFTER else None
        pace = dict(self.pace or {})
        if not pace:
            stage2 = rate if self.stage == "stage 2" else self._stage2_rate()
            if stage2 is None:
                return None
            pace = {stage: factor * stage2 for stage, factor in FIRST_GUESS.items()} | {"stage 2": stage2}
        if rate is not None:
            pace[self.stage] = rate
        if any(stage not in pace for stage in STAGES[current:]):
            return None
        if self.stage in STEPPED:
            left = max(self.totals[self.stage] - self.step, 0) * pace[self.stage]
        else:
            left = max(pace[self.stage] - elapsed, 0.0)
        for stage in STAGES[current + 1:]:
            left += pace[stage] * (self.totals[stage] if stage in STEPPED else 1)
        return left

    def _stage2_rate(self) -> float | None:
        """Stage 2's seconds per step once it is over (stage 3 or later is running)."""
        if "stage 2" not in self.starts or "stage 3" not in self.starts or not self.steps.get("stage 2"):
            return None
        return (self.starts["stage 3"] - self.starts["stage 2"]) / self.steps["stage 2"]


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
