"""The fused stage-3 terms (deface/fit/fast_stage3.py) against their torch references, values and gradients
in float64, on random maps with partial masks."""

from __future__ import annotations

import pytest
import torch

from deface.fit import fast_stage3
from deface.losses.texture import PAPER_WEIGHTS, texture_regularisers
from deface.priors.global_prior import global_prior
from deface.priors.local_prior import local_prior
from deface.render import kernels
from deface.render.mesh import Textures

pytestmark = pytest.mark.skipif(fast_stage3.njit is None, reason="numba missing")


def _maps(size: int, seed: int, dtype=torch.float64) -> Textures:
    generator = torch.Generator().manual_seed(seed)

    def rand(*shape):
        return torch.rand(*shape, generator=generator, dtype=dtype)

    return Textures(rand(size, size, 3), rand(size, size, 3), 0.05 + 0.95 * rand(size, size, 1))


def _fields(textures: Textures) -> list[torch.Tensor]:
    return [textures.diffuse, textures.specular, textures.roughness]


def _mask(height: int, width: int, seed: int, dtype=torch.float64) -> torch.Tensor:
    """A soft mask with zeros, ones and fractions, not symmetric in u."""
    generator = torch.Generator().manual_seed(seed)
    values = torch.rand(height, width, generator=generator, dtype=dtype)
    return torch.where(values < 0.3, torch.zeros_like(values), torch.where(values > 0.7, 1.0, values))


def _reference(textures, initial, mask, palette, regulariser, prior, map_weights=PAPER_WEIGHTS):
    loss = regulariser * texture_regularisers(textures, initial, mask, map_weights)
    return loss + prior * global_prior(textures.diffuse, palette, mask) if palette is not None else loss


@pytest.mark.parametrize("size", [9, 16])  # odd: a middle column that is its own mirror image
@pytest.mark.parametrize("with_palette", [True, False])
@pytest.mark.parametrize("relative", [1.0, 3.7])  # stage 3's diffuse weights relative to a dark map's level
def test_texture_terms_match_reference(size, with_palette, relative):
    initial, current = _maps(size, 0), _maps(size, 1)
    mask = _mask(size, size, 2)
    palette = torch.rand(16, 3, generator=torch.Generator().manual_seed(3), dtype=torch.float64)
    palette = palette if with_palette else None
    map_weights = dict(PAPER_WEIGHTS, diffuse=PAPER_WEIGHTS["diffuse"].relative(relative))
    parameters = [t.clone().requires_grad_() for t in _fields(current)]
    fast = fast_stage3.TextureTerms(initial, mask, palette, 0.2, 2e3, map_weights)(Textures(*parameters))
    fast_grads = torch.autograd.grad(3.0 * fast, parameters)
    reference_parameters = [t.clone().requires_grad_() for t in _fields(current)]
    reference = _reference(Textures(*reference_parameters), initial, mask, palette, 0.2, 2e3, map_weights)
    reference_grads = torch.autograd.grad(3.0 * reference, reference_parameters)
    assert fast.item() == pytest.approx(reference.item(), rel=1e-12)
    for got, want in zip(fast_grads, reference_grads, strict=True):
        torch.testing.assert_close(got, want, rtol=1e-10, atol=1e-14)


def test_texture_terms_float32_close_and_deterministic():
    initial, current = _maps(32, 4, torch.float32), _maps(32, 5, torch.float32)
    mask = _mask(32, 32, 6, torch.float32)
    palette = torch.rand(16, 3, generator=torch.Generator().manual_seed(7))
    terms = fast_stage3.TextureTerms(initial, mask, palette, 0.2, 2e3)
    first, second = terms(current), terms(current)
    assert first.dtype == torch.float32 and first.item() == second.item()
    reference = _reference(current, initial, mask, palette, 0.2, 2e3)
    assert first.item() == pytest.approx(reference.item(), rel=1e-5)


@pytest.mark.parametrize("channels", [1, 3])
def test_local_prior_matches_reference(channels):
    generator = torch.Generator().manual_seed(8)
    current = torch.rand(12, 10, channels, generator=generator, dtype=torch.float64)
    reference = torch.rand(12, 10, channels, generator=generator, dtype=torch.float64)
    mask = _mask(12, 10, 9)
    mask[0, 0] = 1.0  # a corner pixel: replicate padding on two sides
    fast_input, reference_input = current.clone().requires_grad_(), current.clone().requires_grad_()
    fast = fast_stage3.local_prior_l1(fast_input, reference, mask)
    (fast_grad,) = torch.autograd.grad(2.0 * fast, fast_input)
    want = local_prior(reference_input, reference, mask)
    (want_grad,) = torch.autograd.grad(2.0 * want, reference_input)
    assert fast.item() == pytest.approx(want.item(), rel=1e-12)
    torch.testing.assert_close(fast_grad, want_grad, rtol=1e-10, atol=1e-14)


def test_switch_follows_the_renderer_kernels():
    tensor = torch.zeros(2)
    assert fast_stage3.enabled(tensor)
    assert not fast_stage3.enabled(tensor, tensor.double())  # one dtype only
    with kernels.backend("torch"):
        assert not fast_stage3.enabled(tensor)


@pytest.mark.parametrize("factor", [2, 3])
def test_block_mean_matches_avg_pool(factor):
    from deface.render import fast_box, supersample

    generator = torch.Generator().manual_seed(10)
    values = torch.rand(2, 4 * factor, 5 * factor, 3, generator=generator, dtype=torch.float64)
    fast_input, reference_input = values.clone().requires_grad_(), values.clone().requires_grad_()
    weights = torch.rand(2, 4, 5, 3, generator=generator, dtype=torch.float64)
    fast = fast_box.block_mean(fast_input, factor)
    with kernels.backend("torch"):
        reference = supersample._pool(reference_input, factor)
    torch.testing.assert_close(fast, reference, rtol=1e-14, atol=0)
    (fast_grad,) = torch.autograd.grad((fast * weights).sum(), fast_input)
    (reference_grad,) = torch.autograd.grad((reference * weights).sum(), reference_input)
    torch.testing.assert_close(fast_grad, reference_grad, rtol=1e-14, atol=0)
