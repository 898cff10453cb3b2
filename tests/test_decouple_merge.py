"""The merge test (deface/decouple/merge.py): one light over two regions against one light each, on pixels
rendered by SH lights of known coefficients."""

from __future__ import annotations

import math

import pytest
import torch

from deface.decouple.merge import MergeEvidence, best_light_render, cheapest_merge, merge_cost, region_errors
from deface.render.sh import cosine_lobe_coefficients, sh_basis

BANDS = 3


def _face_pixels(count: int = 2000, seed: int = 0) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Normals of a hemisphere facing +z, their heights (y) and an albedo that varies over it, and each SH
    coefficient's Lambertian render there [N, J, 3] (irradiance A_l Y_lm(n) times albedo / pi)."""
    generator = torch.Generator().manual_seed(seed)
    normals = torch.randn(count, 3, generator=generator, dtype=torch.float64)
    normals[:, 2] = normals[:, 2].abs() + 0.3
    normals = normals / normals.norm(dim=1, keepdim=True)
    albedo = 0.4 + 0.3 * torch.rand(count, 3, generator=generator, dtype=torch.float64)
    irradiance = sh_basis(normals, BANDS) * cosine_lobe_coefficients(BANDS).to(normals)  # [N, J]
    return normals, albedo, irradiance[:, :, None] * albedo[:, None, :] / math.pi


def _light(seed: int) -> torch.Tensor:
    generator = torch.Generator().manual_seed(seed)
    light = 0.2 * torch.randn(BANDS * BANDS, 3, generator=generator, dtype=torch.float64)
    light[0] = 2.5  # a bright ambient term keeps the render positive
    return light


def _evidence(basis, target, label) -> MergeEvidence:
    return MergeEvidence(basis.float(), target.float(), torch.ones(target.shape[0]), label)


def test_one_light_fits_its_own_render_exactly():
    _, _, basis = _face_pixels()
    target = torch.einsum("njc,jc->nc", basis, _light(1))
    everything = torch.ones(2000, dtype=torch.bool)
    render = best_light_render(_evidence(basis, target, torch.zeros(2000, dtype=torch.long)), everything, 1e-9)
    assert torch.allclose(render, target.double(), atol=1e-4 * float(target.mean()))


def test_a_face_cut_where_the_light_does_not_change_merges_at_no_cost():
    normals, _, basis = _face_pixels()
    target = torch.einsum("njc,jc->nc", basis, _light(1))
    below_the_mouth = (normals[:, 1] < -0.3).long()  # f's cut at the mouth: the same light on both sides
    assert abs(merge_cost(_evidence(basis, target, below_the_mouth), 0, 1, ridge=1e-9)) < 1e-3


def test_a_cast_shadow_costs_its_contrast():
    normals, _, basis = _face_pixels()
    lit = torch.einsum("njc,jc->nc", basis, _light(1))
    shadowed = normals[:, 1] > 0.2  # a brim's shadow over the upper face
    target = torch.where(shadowed[:, None], 0.35 * lit, lit)
    evidence = _evidence(basis, target, shadowed.long())
    errors = region_errors(evidence, 0, 1, ridge=1e-9)
    assert all(own < 1e-3 for own, _ in errors)  # each side's own light explains it
    assert max(joint for _, joint in errors) > 0.1  # one light over both cannot
    assert merge_cost(evidence, 0, 1, ridge=1e-9) == pytest.approx(max(j - o for o, j in errors))


def test_a_small_shadow_counts_as_much_as_the_face_around_it():
    normals, _, basis = _face_pixels(count=4000)
    lit = torch.einsum("njc,jc->nc", basis, _light(1))
    finger = (normals[:, 0] - 0.3).abs() < 0.04  # a thin shadow: a few % of the pixels
    assert finger.double().mean() < 0.06
    target = torch.where(finger[:, None], 0.5 * lit, lit)
    assert merge_cost(_evidence(basis, target, finger.long()), 0, 1, ridge=1e-9) > 0.2


def test_the_cheapest_pair_is_the_cut_not_the_shadow():
    normals, _, basis = _face_pixels()
    lit = torch.einsum("njc,jc->nc", basis, _light(1))
    shadowed = normals[:, 1] > 0.2
    target = torch.where(shadowed[:, None], 0.35 * lit, lit)
    label = torch.where(shadowed, 0, torch.where(normals[:, 0] < 0, 1, 2))  # the lit side cut in two
    first, second, cost = cheapest_merge(_evidence(basis, target, label), 3, ridge=1e-9)
    assert (first, second) == (1, 2) and abs(cost) < 1e-3
    assert cheapest_merge(_evidence(basis, target, torch.zeros(2000, dtype=torch.long)), 1) is None


def test_a_light_without_pixels_cannot_be_judged():
    _, _, basis = _face_pixels()
    target = torch.einsum("njc,jc->nc", basis, _light(1))
    assert merge_cost(_evidence(basis, target, torch.zeros(2000, dtype=torch.long)), 0, 1) == math.inf
    assert region_errors(_evidence(basis, target, torch.zeros(2000, dtype=torch.long)), 0, 1) is None


def test_mismatched_shapes_are_refused():
    _, _, basis = _face_pixels(count=10)
    with pytest.raises(ValueError, match="basis"):
        MergeEvidence(basis.float(), torch.ones(9, 3), torch.ones(9), torch.zeros(9, dtype=torch.long))
