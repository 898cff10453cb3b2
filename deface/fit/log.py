"""Progress and run records: one rich console for all output; losses and stage times kept for params.json."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

from rich.console import Console

console = Console(stderr=True, highlight=False, soft_wrap=True)  # one-line errors stay one line


@dataclass
class FitLog:
    """Collects per-stage loss curves, times and notes; prints progress every ``every`` steps."""

    name: str = ""
    every: int = 50
    quiet: bool = False
    losses: dict[str, list[float]] = field(default_factory=dict)
    terms: dict[str, list[dict[str, float]]] = field(default_factory=dict)  # stage -> per step named terms
    seconds: dict[str, float] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    _started: dict[str, float] = field(default_factory=dict)

    def start(self, stage: str) -> None:
        self._started[stage] = time.perf_counter()

    def stop(self, stage: str) -> float:
        elapsed = time.perf_counter() - self._started.pop(stage)
        self.seconds[stage] = round(self.seconds.get(stage, 0.0) + elapsed, 3)
        self.info(f"{stage} done in {elapsed:.1f} s")
        return elapsed

    def step(self, stage: str, step: int, total: int, loss: float, terms: dict[str, float] | None = None) -> None:
        """Record a step's loss (and its named terms); print it with the largest terms every ``every`` steps."""
        self.losses.setdefault(stage, []).append(loss)
        self.terms.setdefault(stage, []).append(dict(terms or {}))
        if not self.quiet and (step % self.every == 0 or step == total - 1):
            console.print(f"[dim]{self.name}[/dim] {stage} {step + 1:>4}/{total} loss {loss:.5g}"
                          f"{largest_terms(terms or {})}")

    def info(self, message: str) -> None:
        self.notes.append(message)
        if not self.quiet:
            console.print(f"[dim]{self.name}[/dim] {message}")


def largest_terms(terms: dict[str, float], count: int = 3) -> str:
    """`` (photometric 0.41, landmarks 0.12, ...)``: the ``count`` largest terms by magnitude, or ""."""
    shown = sorted(terms.items(), key=lambda item: -abs(item[1]))[:count]
    return " (" + ", ".join(f"{name} {value:.3g}" for name, value in shown) + ")" if shown else ""
