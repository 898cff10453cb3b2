"""Global (K-means palette) and local (5x5 variation) priors."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from deface.priors.global_prior import global_prior, kmeans_palette
from deface.priors.local_prior import local_prior, local_variations, material_local_prior


def test_global_prior_by_hand():
    diffuse = torch.tensor([[[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]]])  # [1, 2, 3]
    centres = torch.tensor([[0.0, 0.0, 0.0], [0.5, 0.5, 0.5]])
    assert global_prior(diffuse, centres).item() == pytest.approx(0.375)
    unsquared = global_prior(diffuse, centres, squared=False).item()
    assert unsquared == pytest.approx(math.sqrt(0.75) / 2, abs=1e-5)
    assert global_prior(diffuse, centres, torch.tensor([[1.0, 0.0]])).item() == pytest.approx(0.0)


def test_kmeans_palette_recovers_separated_colours():
    rng = np.random.default_rng(3)
    colours = np.array([[0.8, 0.6, 0.5], [0.3, 0.2, 0.1], [0.1, 0.5, 0.9]])
    labels = rng.integers(0, 3, size=(20, 30))
    diffuse = colours[labels] + rng.normal(0, 0.005, size=(20, 30, 3))
    mask = np.ones((20, 30))
    mask[:, :5] = 0
    centres = kmeans_palette(diffuse, mask, k=3, seed=0).numpy()
    assert centres.shape == (3, 3)
    nearest = np.abs(centres[:, None] - colours[None]).max(-1).min(0)
    assert np.all(nearest < 0.01)
    again = kmeans_palette(torch.as_tensor(diffuse), torch.as_tensor(mask), k=3, seed=0).numpy()
    assert np.allclose(np.sort(centres, 0), np.sort(again, 0))
    # the fitted palette explains its own texture almost exactly
    gp = global_prior(torch.as_tensor(diffuse, dtype=torch.float32), torch.as_tensor(centres))
    assert gp.item() < 3 * 0.005**2 * 2


def test_local_variations_of_a_ramp():
    ramp = torch.arange(7.0)[None, :, None].expand(7, 7, 1).contiguous()  # T(y, x) = x
    variations = local_variations(ramp)
    assert variations.shape == (7, 7, 1, 24)
    offsets_x = [dx for dy in range(-2, 3) for dx in range(-2, 3) if (dy, dx) != (0, 0)]
    assert variations[3, 3, 0].tolist() == [-float(dx) for dx in offsets_x]
    # replicate padding: at the left border neighbours to the left equal the pixel itself
    left = [v for v, dx in zip(variations[3, 0, 0].tolist(), offsets_x, strict=True) if dx < 0]
    assert left == [0.0] * len(left)


def test_local_prior_by_hand_and_invariance_to_offsets():
    ramp = torch.arange(9.0)[None, :, None].expand(9, 9, 1).contiguous()
    interior = torch.zeros(9, 9)
    interior[2:7, 2:7] = 1.0
    assert local_prior(ramp + 0.3, ramp, interior).item() == pytest.approx(0.0, abs=1e-6)
    # doubling the ramp: |N - N0| = |dx|, mean over the 24 offsets = 5 (2 + 1 + 0 + 1 + 2) / 24
    assert local_prior(2 * ramp, ramp, interior).item() == pytest.approx(30 / 24)
    assert local_prior(2 * ramp, ramp, interior, norm="l2sq").item() == pytest.approx(5 * 10 / 24)
    maps = (2 * ramp, 2 * ramp, 2 * ramp)
    refs = (ramp, ramp, ramp)
    assert material_local_prior(maps, refs, interior).item() == pytest.approx(12 * 30 / 24)


def test_local_prior_gradient_and_errors():
    current = torch.rand(6, 6, 3, requires_grad=True)
    local_prior(current, torch.rand(6, 6, 3)).backward()
    assert current.grad.abs().sum() > 0
    with pytest.raises(ValueError):
        local_prior(torch.rand(6, 6, 3), torch.rand(6, 5, 3))
