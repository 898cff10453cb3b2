"""Stage-3 texture regularisers (deface/losses/texture.py) against hand-computed values."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from deface.losses.texture import (
    MapWeights,
    SmoothDeparture,
    chromaticity,
    map_regulariser,
    neighbour_smoothness,
    texture_regularisers,
)
from deface.render.mesh import Textures

SIZE = 8
ONES = torch.ones(SIZE, SIZE)


def only(**weights) -> MapWeights:
    return MapWeights(**{"symmetry": 0.0, "reference": 0.0, "chromaticity": 0.0, "smoothness": 0.0, **weights})


def test_no_change_from_a_symmetric_smooth_reference_costs_nothing():
    reference = torch.full((SIZE, SIZE, 3), 0.4)
    weights = MapWeights(symmetry=300, reference=100, chromaticity=100, smoothness=0.001, grey=0.0)
    assert float(map_regulariser(reference.clone(), reference, ONES, weights)) == 0.0


def test_symmetry_is_the_mean_difference_between_the_halves():
    texture = torch.full((SIZE, SIZE, 3), 0.2)
    texture[:, SIZE // 2:] = 0.5  # right half brighter: every texel differs from its mirror by 0.3
    loss = map_regulariser(texture, texture, ONES, only(symmetry=1.0))
    assert float(loss) == pytest.approx(0.3, rel=1e-6)


def test_symmetry_ignores_texels_whose_mirror_is_off_the_face():
    texture = torch.rand(SIZE, SIZE, 3, generator=torch.Generator().manual_seed(0))
    mask = ONES.clone()
    mask[:, : SIZE // 2] = 0  # only one side is face: nothing to compare with
    assert float(map_regulariser(texture, texture, mask, only(symmetry=1.0))) == 0.0


def test_reference_term_is_the_l1_distance_over_the_mask_divided_by_all_values():
    reference = torch.full((SIZE, SIZE, 3), 0.4)
    mask = ONES.clone()
    mask[: SIZE // 2] = 0  # half the map is off the face
    loss = map_regulariser(reference + 0.1, reference, mask, only(reference=1.0))
    assert float(loss) == pytest.approx(0.05, rel=1e-5)


def test_chromaticity_sees_hue_but_barely_brightness():
    white = torch.tensor([1.0, 1.0, 1.0])
    assert chromaticity(white).tolist() == pytest.approx([0.3127, 0.3290], abs=2e-3)  # D65 white point
    reference = torch.full((SIZE, SIZE, 3), 0.4)
    darker = map_regulariser(reference * 0.7, reference, ONES, only(chromaticity=1.0))
    redder = reference * torch.tensor([1.0, 0.7, 0.7])
    hue = map_regulariser(redder, reference, ONES, only(chromaticity=1.0))
    assert float(darker) < 0.1 * float(hue)  # only the 1 in the denominator sees brightness


def test_smoothness_of_a_checkerboard_counts_every_neighbour_pair():
    step = 0.1
    board = (torch.arange(SIZE)[:, None] + torch.arange(SIZE)[None, :]) % 2 * step
    texture = board[..., None].expand(SIZE, SIZE, 3)
    pairs = 2 * SIZE * (SIZE - 1)
    assert float(neighbour_smoothness(texture, ONES)) == pytest.approx(pairs * 3 * step**2, rel=1e-5)
    assert float(neighbour_smoothness(torch.full((SIZE, SIZE, 3), 0.3), ONES)) == 0.0


def test_grey_term_sums_the_deviation_from_the_channel_mean():
    texture = torch.zeros(SIZE, SIZE, 3)
    texture[..., 0] = 0.3  # mean 0.1: deviations 0.2, -0.1, -0.1
    loss = map_regulariser(texture, texture, ONES, only(grey=1.0))
    assert float(loss) == pytest.approx(SIZE * SIZE * (0.04 + 0.01 + 0.01), rel=1e-5)


def test_a_one_sided_dark_patch_costs_more_than_the_same_patch_on_both_sides_per_texel():
    reference = torch.full((SIZE, SIZE, 3), 0.5)
    one_side = reference.clone()
    one_side[2:6, 1:3] *= 0.6
    both = one_side.clone()
    both[2:6, SIZE - 3:SIZE - 1] *= 0.6
    weights = MapWeights(symmetry=300, reference=100, chromaticity=100, smoothness=0.001)
    per_patch_one = float(map_regulariser(one_side, reference, ONES, weights))
    per_patch_both = float(map_regulariser(both, reference, ONES, weights)) / 2
    assert per_patch_one > 2 * per_patch_both


def test_all_maps_are_summed_and_gradients_reach_each_map():
    gen = torch.Generator().manual_seed(1)
    maps = [torch.rand(SIZE, SIZE, c, generator=gen, requires_grad=True) for c in (3, 3, 1)]
    initial = Textures(torch.full((SIZE, SIZE, 3), 0.5), torch.full((SIZE, SIZE, 3), 0.2),
                       torch.full((SIZE, SIZE, 1), 0.4))
    texture_regularisers(Textures(*maps), initial, ONES).backward()
    assert all(m.grad is not None and m.grad.abs().sum() > 0 for m in maps)


def _cellwise_constant(cells: int, size: int, seed: int = 0) -> torch.Tensor:
    """[size, size, 3] linear colours constant over each of cells x cells blocks."""
    values = torch.rand(cells, cells, 3, generator=torch.Generator().manual_seed(seed)) * 0.5 + 0.1
    return values.repeat_interleave(size // cells, 0).repeat_interleave(size // cells, 1)


def test_smooth_departure_is_zero_for_the_reference_and_one_gain_per_channel():
    reference, mask = _cellwise_constant(8, 64), torch.ones(64, 64)
    assert float(SmoothDeparture(reference, mask, 8)(reference)) == pytest.approx(0.0, abs=1e-12)
    gained = reference * torch.tensor([1.4, 0.8, 1.1])  # the tone the photo shows stays free
    assert float(SmoothDeparture(reference, mask, 8)(gained)) == pytest.approx(0.0, abs=1e-10)


def test_smooth_departure_ignores_detail_finer_than_a_cell():
    reference, mask = _cellwise_constant(8, 64), torch.ones(64, 64)
    checker = (torch.arange(64)[:, None] + torch.arange(64)[None, :]) % 2 * 2.0 - 1.0  # zero mean per cell
    detailed = reference * (1.0 + 0.3 * checker)[..., None]
    assert float(SmoothDeparture(reference, mask, 8)(detailed)) == pytest.approx(0.0, abs=1e-10)


def test_smooth_departure_of_a_shading_gradient_matches_its_variance_over_cells():
    """T = T^0 exp(a y), y constant per cell row: the cost is a^2 times the variance of the rows' y."""
    cells, size, slope = 8, 64, 0.3
    reference, mask = _cellwise_constant(cells, size, seed=1), torch.ones(size, size)
    row = (torch.arange(cells, dtype=torch.float64) + 0.5) / cells
    y = row.repeat_interleave(size // cells)[:, None, None].float()
    expected = slope**2 * float(row.var(unbiased=False))
    assert float(SmoothDeparture(reference, mask, cells)(reference * torch.exp(slope * y))) == \
        pytest.approx(expected, rel=1e-4)


def test_smooth_departure_leaves_out_cells_mostly_outside_the_face():
    reference = _cellwise_constant(8, 64)
    mask = torch.zeros(64, 64)
    mask[:, :32] = 1.0
    outside = reference.clone()
    outside[:, 40:] *= 2.0  # a change off the face: no cost
    assert float(SmoothDeparture(reference, mask, 8)(outside)) == pytest.approx(0.0, abs=1e-10)
    inside = reference.clone()
    inside[:, :8] *= 2.0
    assert float(SmoothDeparture(reference, mask, 8)(inside)) > 0.05


def test_smooth_departure_of_a_map_smaller_than_the_cells_compares_texels():
    reference, mask = _cellwise_constant(4, 16), torch.ones(16, 16)
    darker = reference.clone()
    darker[:8] *= 0.5
    assert float(SmoothDeparture(reference, mask, 32)(darker)) == pytest.approx(float(np.log(0.5) / 2) ** 2,
                                                                                 rel=1e-4)
