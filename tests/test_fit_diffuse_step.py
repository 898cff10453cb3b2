"""Stage 3's diffuse step scales with the map's level: the same face with a darker skin is refined alike."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from deface.fit.config import LearningRates
from deface.fit.stage3 import MIN_LEVEL, diffuse_step
from deface.texture.pyramid import TexturePyramid, level_gates


def _skin(seed: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
    """A 32² diffuse map of a light skin with some texel-scale structure, and the face mask (the left 3/4)."""
    generator = torch.Generator().manual_seed(seed)
    base = torch.tensor([0.55, 0.35, 0.25])
    diffuse = base * (1 + 0.2 * torch.rand(32, 32, 1, generator=generator))
    mask = torch.zeros(32, 32)
    mask[:, :24] = 1.0
    return diffuse, mask


def test_step_is_fixed_without_a_level_and_scales_with_the_face_texels_median_green():
    diffuse, mask = _skin()
    fixed = LearningRates()
    assert diffuse_step(fixed, diffuse, mask) == fixed.stage3_diffuse
    rates = LearningRates(stage3_diffuse_level=0.33)
    green = float(diffuse[:, :24, 1].median())
    assert diffuse_step(rates, diffuse, mask) == pytest.approx(0.005 * green / 0.33)
    assert diffuse_step(rates, 0.25 * diffuse, mask) == pytest.approx(0.25 * diffuse_step(rates, diffuse, mask))
    brighter_outside = diffuse.clone()
    brighter_outside[:, 24:] = 1.0  # texels outside the face do not count
    assert diffuse_step(rates, brighter_outside, mask) == diffuse_step(rates, diffuse, mask)
    assert diffuse_step(rates, torch.zeros_like(diffuse), mask) == pytest.approx(0.005 * MIN_LEVEL / 0.33)


def _refined(initial: torch.Tensor, photo: torch.Tensor, step: float, steps: int = 40) -> torch.Tensor:
    """The map after ``steps`` Adam steps of a per-texel photometric fit through a 3-level pyramid."""
    pyramid = TexturePyramid(initial, level_gates(np.full((32, 32), 0.5), [32, 16, 8], power=2.0))
    optimiser = torch.optim.Adam(pyramid.parameters(), lr=step)
    for _ in range(steps):
        optimiser.zero_grad()
        ((pyramid() - photo) ** 2).sum().backward()  # a sum: gradients far above Adam's eps
        optimiser.step()
    return pyramid().detach()


def test_a_darker_skin_gets_the_same_relative_refinement():
    """Adam's steps ignore the gradient's scale, so with the step proportional to the map the refinement of the
    map times c is c times the refinement; with one fixed step it is not (the darker map moves by the same
    absolute amounts, larger relative to its level: the texel noise of dark textures)."""
    initial, mask = _skin(0)
    photo, _ = _skin(1)
    rates, dark = LearningRates(stage3_diffuse_level=0.33), 0.2
    light_map = _refined(initial, photo, diffuse_step(rates, initial, mask), steps=10)
    dark_map = _refined(dark * initial, dark * photo, diffuse_step(rates, dark * initial, mask), steps=10)
    torch.testing.assert_close(dark_map, dark * light_map, rtol=1e-4, atol=1e-6)
    fixed = LearningRates()
    light_fixed = _refined(initial, photo, diffuse_step(fixed, initial, mask), steps=10)
    dark_fixed = _refined(dark * initial, dark * photo, diffuse_step(fixed, dark * initial, mask), steps=10)
    assert float(((dark_fixed - dark * light_fixed).abs() / (dark * light_fixed)).max()) > 0.02
