"""Stage 3's diffuse step and the diffuse map's terms scale with the map's level: the same face with a darker
skin is refined alike."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from deface.fit.config import LearningRates, Weights
from deface.fit.stage3 import MIN_LEVEL, diffuse_step, map_level, relative_scale
from deface.losses.texture import PAPER_WEIGHTS, map_regulariser
from deface.priors.global_prior import global_prior
from deface.priors.local_prior import local_prior
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
    fixed = LearningRates(stage3_diffuse_level=0.0)
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
    fixed = LearningRates(stage3_diffuse_level=0.0)
    light_fixed = _refined(initial, photo, diffuse_step(fixed, initial, mask), steps=10)
    dark_fixed = _refined(dark * initial, dark * photo, diffuse_step(fixed, dark * initial, mask), steps=10)
    assert float(((dark_fixed - dark * light_fixed).abs() / (dark * light_fixed)).max()) > 0.02


def test_relative_scale_is_one_without_a_level_and_the_level_over_the_maps_otherwise():
    diffuse, mask = _skin()
    assert relative_scale(Weights(diffuse_level=0.0), diffuse, mask) == 1.0
    assert relative_scale(Weights(diffuse_level=0.33), diffuse, mask) == pytest.approx(0.33 / map_level(diffuse, mask))
    assert relative_scale(Weights(diffuse_level=0.33), 0.25 * diffuse, mask) == pytest.approx(
        4 * relative_scale(Weights(diffuse_level=0.33), diffuse, mask))


@pytest.mark.parametrize("dark", [0.2, 0.5])
def test_the_diffuse_terms_cost_a_map_and_a_darker_copy_alike(dark):
    """Each term is homogeneous in the map (the degrees :meth:`MapWeights.relative` and stage 3 assume): the
    regularisers with relative weights, GP (squared) and LP (L1) cost the map times ``dark`` as the map."""
    texture, mask = _skin(0)
    reference, _ = _skin(1)
    weights = replace(PAPER_WEIGHTS["diffuse"], chromaticity=0.0, grey=0.5)  # xy is scale-free but for its + 1
    scale = 1.0 / dark
    torch.testing.assert_close(map_regulariser(dark * texture, dark * reference, mask, weights.relative(scale)),
                               map_regulariser(texture, reference, mask, weights))
    palette = reference.reshape(-1, 3)[::97]
    torch.testing.assert_close(scale ** 2 * global_prior(dark * texture, dark * palette, mask),
                               global_prior(texture, palette, mask))
    coverage = mask
    torch.testing.assert_close(scale * local_prior(dark * texture, dark * reference, coverage),
                               local_prior(texture, reference, coverage))


def _regularised(initial: torch.Tensor, mask: torch.Tensor, photo: torch.Tensor, brightness: float,
                 weights: Weights, steps: int = 30) -> torch.Tensor:
    """The map after a stage-3-like fit: the photo lit by ``brightness`` times the map, plus the diffuse
    regularisers against ``initial`` with the weights stage 3 gives them (strong symmetry and smoothness; no reference
    term: its L1 has no gradient at T^0, where the fit starts, and float rounding in the pyramid picks the sign
    there, a noise of about 1 % on these maps whatever the weights)."""
    rates = LearningRates(stage3_diffuse_level=0.33)
    map_weights = replace(PAPER_WEIGHTS["diffuse"], chromaticity=0.0, symmetry=3e4, reference=0.0,
                          smoothness=1.0).relative(
        relative_scale(weights, initial, mask))
    pyramid = TexturePyramid(initial, level_gates(np.full((32, 32), 0.5), [32, 16, 8], power=2.0))
    optimiser = torch.optim.Adam(pyramid.parameters(), lr=diffuse_step(rates, initial, mask))
    for _ in range(steps):
        optimiser.zero_grad()
        texture = pyramid()
        loss = ((brightness * texture - photo) ** 2).sum() + map_regulariser(texture, initial, mask, map_weights)
        loss.backward()
        optimiser.step()
    return pyramid().detach()


def test_a_darker_skin_under_brighter_light_is_held_to_its_map_as_much():
    """The same photo explained by a map ``dark`` times as light under lights 1 / ``dark`` times as bright (the
    tone/light trade the scene decides): with the diffuse terms relative to the map's level the refined map is
    ``dark`` times the light one's; with absolute weights the terms weigh less against the photo on the darker
    map and its refinement is not the light one's (10 % apart here)."""
    initial, mask = _skin(0)
    photo, _ = _skin(1)
    dark, relative, absolute = 0.2, Weights(diffuse_level=0.33), Weights(diffuse_level=0.0)
    light_map = _regularised(initial, mask, photo, 1.0, relative)
    dark_map = _regularised(dark * initial, mask, photo, 1.0 / dark, relative)
    torch.testing.assert_close(dark_map, dark * light_map, rtol=1e-4, atol=1e-6)
    dark_absolute = _regularised(dark * initial, mask, photo, 1.0 / dark, absolute)
    light_absolute = _regularised(initial, mask, photo, 1.0, absolute)
    assert float(((dark_absolute - dark * light_absolute).abs() / (dark * light_absolute)).max()) > 0.05
