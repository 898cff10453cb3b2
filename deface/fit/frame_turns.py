"""Which frames a stage-2 step renders (``iterations.stage2_frames_per_step``): all of them, or, for a fit of more
frames than that, a turn of them.

A fit of many photos or of a clip's frames costs each step once per frame. The unknowns every frame shares (shape,
albedo coefficients, f, g) need every frame's evidence, but not at every step: an Adam step on a few frames' loss
is a noisy step on the loss of all of them (stochastic gradient over the frames, as multi-view fits step over
views). Each round of steps shows every frame once, in a new order: a seeded shuffle split into
ceil(frames / per_step) near-equal turns, so a fit is repeatable and no frame waits more than two rounds. Stage 2
takes turns only where each photo has its own lights: lights shared by all frames (a clip) stepped on a turn chase
its frames (docs/experiments/person-log.md).

A frame's shadow transfer is refreshed at its first render after ``shadow_refresh_every`` steps since its last one
(with every frame at every step: at steps 0, every, 2 every, ... as before).
"""

from __future__ import annotations

import math

import torch


class FrameTurns:
    """The frames of each step of a stage, and when each frame's shadow transfer is due."""

    def __init__(self, frames: int, per_step: int, refresh_every: int, seed: int = 0):
        self.frames = frames
        self.per_step = frames if per_step <= 0 else min(per_step, frames)
        self.refresh_every = max(refresh_every, 1)
        self._generator = torch.Generator().manual_seed(seed)
        self._turns: list[tuple[int, ...]] = []
        self._last_refresh: dict[int, int] = {}

    @property
    def every_step(self) -> bool:
        """Whether every step renders every frame."""
        return self.per_step >= self.frames

    def at(self, step: int) -> tuple[int, ...]:
        """The frames step ``step`` renders, ascending (steps are asked for in order from 0)."""
        if self.every_step:
            return tuple(range(self.frames))
        while len(self._turns) <= step:
            self._turns.extend(self._round())
        return self._turns[step]

    def refresh(self, frame: int, step: int) -> bool:
        """Whether ``frame``'s shadow transfer is due at ``step`` (the frame is rendered then); records it."""
        last = self._last_refresh.get(frame)
        if last is not None and step - last < self.refresh_every:
            return False
        self._last_refresh[frame] = step
        return True

    def _round(self) -> list[tuple[int, ...]]:
        order = torch.randperm(self.frames, generator=self._generator)
        return [tuple(sorted(part.tolist())) for part in order.tensor_split(math.ceil(self.frames / self.per_step))]
