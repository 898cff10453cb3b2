"""Stage 3 stops when its refinement stops predicting pixels it was not fitted to (``Iterations.stage3_holdout``).

Stage 3 refines every texel (through the pyramid, deface/texture/pyramid.py), many more values than the
photo constrains. Its first steps move the maps towards what the photo shows; later steps keep lowering the
photometric loss by fitting each texel to the few pixels it lands in, and Adam, which steps every parameter
by about its learning rate whatever its gradient, fills the maps with colour noise that differs from one fit
of the same face to the next. More steps are worse, not better: on 3 shadow pairs (quick schedule) 50 / 100 /
200 steps gave target synthesis 24.51 / 24.32 / 24.11 dB and speckle 1.2 / 3.6 / 4.9 (BENCHMARKS.md). Where
the turn comes depends on the photo's resolution, the face's size and the skin, so no fixed step count
serves.

So a share of the face's pixels (drawn once per frame, reproducibly) is held out of the photometric term:
stage 3 fits the others, scores the held-out ones after every step, and keeps the maps, lights and f of the
step where the held-out error was lowest, stopping once it has not improved for ``convergence_window`` steps.
This is early stopping by validation (e.g. Prechelt, "Early Stopping - But When?", 1998): a texel's noise
raises the error of the neighbouring pixels it was not fitted to, the person's own detail, seen by several
pixels, lowers it.
"""

from __future__ import annotations

import dataclasses

import torch

from deface.fit.state import FrameRender


@dataclasses.dataclass(frozen=True)
class HeldOutPixels:
    """Per frame, the pixels the photometric term scores but does not fit."""

    masks: tuple[torch.Tensor, ...]  # per frame [H, W] float, 1 where held out
    share: float  # expected share of the pixels held out, in (0, 1)

    @classmethod
    def draw(cls, shapes: list[tuple[int, int]], share: float) -> HeldOutPixels:
        """Hold out ``share`` of the pixels of frames of ``shapes`` (H, W), at random, the same on every run."""
        if not 0.0 < share < 1.0:
            raise ValueError(f"the held-out share must be in (0, 1), got {share}")
        masks = tuple((torch.rand(shape, generator=torch.Generator().manual_seed(frame)) < share).float()
                      for frame, shape in enumerate(shapes))
        return cls(masks, share)

    def fitted(self, frame: int, rendered: FrameRender) -> FrameRender:
        """``rendered`` with M_o zero on the held-out pixels and scaled so the fitted term keeps its weight."""
        kept = (1.0 - self.masks[frame]) / (1.0 - self.share)
        return dataclasses.replace(rendered, face_region=rendered.face_region * kept)

    def scored(self, frame: int, rendered: FrameRender) -> FrameRender:
        """``rendered`` with M_o on the held-out pixels only."""
        return dataclasses.replace(rendered, face_region=rendered.face_region * self.masks[frame])


class BestStep:
    """The step with the lowest held-out error so far and a copy of ``tensors`` (the optimised values) then."""

    def __init__(self, tensors: list[torch.Tensor], patience: int):
        self.tensors, self.patience = tensors, patience
        self.error, self.step, self._copy = float("inf"), -1, None

    def update(self, step: int, error: float) -> bool:
        """Record ``error``, the held-out error of the values ``tensors`` hold at ``step`` (before that step's
        update); True once ``patience`` steps have passed without a lower one."""
        if error < self.error:
            self.error, self.step = error, step
            self._copy = [t.detach().clone() for t in self.tensors]
        return step - self.step >= self.patience

    @torch.no_grad()
    def restore(self) -> None:
        """Put the best step's values back into ``tensors``."""
        if self._copy is not None:
            for tensor, value in zip(self.tensors, self._copy, strict=True):
                tensor.copy_(value)
