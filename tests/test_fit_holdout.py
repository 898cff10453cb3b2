"""Stage 3's held-out pixels and the step it keeps (deface/fit/holdout.py)."""

from __future__ import annotations

import pytest
import torch

from deface.fit.holdout import BestStep, HeldOutPixels
from deface.fit.state import FrameRender


def _render(face_region: torch.Tensor) -> FrameRender:
    h, w = face_region.shape
    images = torch.rand(1, h, w, 3)
    return FrameRender(images, torch.ones(h, w), torch.ones(1, h, w), face_region, images[0])


def test_held_out_pixels_are_a_reproducible_share_that_partitions_the_face():
    held = HeldOutPixels.draw([(200, 300), (40, 50)], 0.1)
    assert [tuple(m.shape) for m in held.masks] == [(200, 300), (40, 50)]
    assert torch.equal(held.masks[0], HeldOutPixels.draw([(200, 300)], 0.1).masks[0])  # same on every run
    assert set(held.masks[0].unique().tolist()) == {0.0, 1.0}
    assert abs(float(held.masks[0].mean()) - 0.1) < 0.005  # 60k draws: 5 sigma is 0.006
    assert not torch.equal(held.masks[1], held.masks[0][:40, :50])  # frames draw their own pixels
    region = torch.rand(40, 50)
    rendered = _render(region)
    fitted, scored = held.fitted(1, rendered), held.scored(1, rendered)
    # the fitted term keeps its expected weight; together the two cover M_o exactly once
    assert torch.allclose(fitted.face_region * (1 - held.share) + scored.face_region, region)
    assert bool(((fitted.face_region > 0) & (scored.face_region > 0)).sum() == 0)
    assert fitted.face is rendered.face and scored.light_images is rendered.light_images
    for share in (0.0, 1.0, -0.1):
        with pytest.raises(ValueError, match="share"):
            HeldOutPixels.draw([(4, 4)], share)


def test_best_step_keeps_the_values_of_the_lowest_error_and_waits_patience_steps():
    value = torch.zeros(3)
    best = BestStep([value], patience=2)
    errors = [5.0, 4.0, 3.0, 3.0, 2.9, 4.0, 4.0, 1.0]  # a tie (step 3) is no improvement
    stops = []
    for step, error in enumerate(errors):
        value.fill_(step)  # the value the error was measured at
        stops.append(best.update(step, error))
        if stops[-1]:
            break
    assert stops == [False, False, False, False, False, False, True]  # 2 steps without a lower error
    assert best.step == 4 and best.error == 2.9
    best.restore()
    assert torch.equal(value, torch.full((3,), 4.0))
    BestStep([torch.ones(1)], patience=1).restore()  # nothing recorded: nothing to restore
