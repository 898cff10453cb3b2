"""L_area, L_bin, L_seg and L_pho against hand-computed values."""

from __future__ import annotations

import math

import pytest
import torch

from deface.losses.decouple import area_loss, binary_loss, segmentation_loss, variation_loss
from deface.losses.photometric import blur3, gaussian_kernel3, photometric_loss


def test_area_loss_one_pixel_by_hand():
    masks = torch.tensor([0.8, 0.2])[:, None, None]  # [n=2, 1, 1], mean 0.5, deviations +-0.3
    coverage = torch.ones(1, 1)
    assert area_loss(masks, coverage, "code").item() == pytest.approx(2 * math.exp(-0.09) - 1, abs=1e-6)
    assert area_loss(masks, coverage, "paper").item() == pytest.approx(math.exp(-0.3) - 1, abs=1e-6)


def test_area_loss_ignores_uncovered_pixels_and_normalisers():
    masks = torch.tensor([[0.8, 0.5], [0.2, 0.5]])[:, None, :]  # [2, 1, 2]: pixel 2 sits on the mean
    coverage = torch.tensor([[1.0, 0.0]])
    assert area_loss(masks, coverage, "code").item() == pytest.approx(2 * math.exp(-0.09) - 1, abs=1e-6)
    paper_image = area_loss(masks, coverage, "paper", normaliser="image").item()
    assert paper_image == pytest.approx(math.exp(-0.3) / 2 - 1, abs=1e-6)


def test_area_loss_favours_separated_masks():
    coverage = torch.ones(1, 4)
    uniform = torch.full((2, 1, 4), 0.5)
    binary = torch.tensor([[1.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 1.0]])[:, None, :]
    for form in ("code", "paper"):
        assert area_loss(binary, coverage, form) < area_loss(uniform, coverage, form)


def test_binary_loss_by_hand():
    masks = torch.tensor([[1.0, 0.5], [0.0, 0.5]])[:, None, :]  # areas 0.75 and 0.25, deviations +-0.25
    coverage = torch.ones(1, 2)
    assert binary_loss(masks, coverage, "code").item() == pytest.approx(2 * math.exp(-0.0625) - 1, abs=1e-6)
    assert binary_loss(masks, coverage, "paper").item() == pytest.approx(math.exp(-0.25) - 1, abs=1e-6)


def test_binary_loss_paper_image_normaliser_changes_the_area():
    masks = torch.tensor([[1.0, 0.0], [0.0, 0.0]])[:, None, :]  # light 0 covers the one covered pixel
    coverage = torch.tensor([[1.0, 0.0]])
    # a = (1/2, 0) with the image normaliser: pixel 1 deviations (0.5, 0); summed, then divided by 2 pixels
    expected = (math.exp(-0.5) + 1.0) / 2 / 2 - 1
    assert binary_loss(masks, coverage, "paper", "image").item() == pytest.approx(expected, abs=1e-6)


def test_losses_accept_frames_and_give_gradients():
    logits = torch.randn(2, 3, 4, 4, requires_grad=True)
    masks = torch.softmax(logits, dim=1)
    loss = area_loss(masks, torch.ones(2, 4, 4)) + binary_loss(masks, torch.ones(2, 4, 4), "paper")
    loss.backward()
    assert logits.grad.abs().sum() > 0


def _square_inside(side: int, square: tuple[int, int]) -> tuple[torch.Tensor, torch.Tensor]:
    """Two masks over a face (the middle 80 % of a ``side``² image) split by a square of light 1 at
    [square[0], square[1]) in both axes, and the face's coverage."""
    coverage = torch.zeros(side, side)
    edge = side // 10
    coverage[edge:side - edge, edge:side - edge] = 1.0
    masks = torch.stack([coverage.clone(), torch.zeros(side, side)])
    start, stop = square
    masks[0, start:stop, start:stop] = 0.0
    masks[1, start:stop, start:stop] = 1.0
    return masks, coverage


def test_variation_loss_is_the_masks_perimeter_over_the_face_size():
    uniform, coverage = _square_inside(100, (0, 0))
    assert variation_loss(uniform, coverage).item() == 0.0  # the face's own outline is M_R's, not a mask's
    masks, coverage = _square_inside(100, (30, 50))
    # a 20-pixel square: perimeter 80 in each of the two masks, over sqrt(80 * 80)
    assert variation_loss(masks, coverage).item() == pytest.approx(2 * 80 / 80)


def test_variation_loss_does_not_depend_on_the_working_size():
    small = variation_loss(*_square_inside(100, (30, 50)))
    large = variation_loss(*_square_inside(200, (60, 100)))
    assert large.item() == pytest.approx(small.item())


def test_variation_loss_is_the_same_for_a_hard_and_a_ramped_edge_of_one_height():
    """Total variation pays for the step's height, not its sharpness: a shadow's edge costs the same sharp
    or soft, so the term does not blur it."""
    coverage = torch.ones(1, 40)
    hard = torch.zeros(2, 1, 40)
    hard[0, 0, :20] = 1.0
    hard[1] = 1.0 - hard[0]
    ramp = torch.clamp(torch.linspace(1.5, -0.5, 40), 0.0, 1.0)
    soft = torch.stack([ramp, 1.0 - ramp])[:, None, :]
    assert variation_loss(soft, coverage).item() == pytest.approx(variation_loss(hard, coverage).item(), rel=1e-5)


def test_segmentation_loss_both_forms_by_hand():
    g = torch.tensor([[0.5, 1.0]])
    h = torch.tensor([[1.0, 0.0]])
    coverage = torch.ones(1, 2)
    assert segmentation_loss(g, h, coverage, "code").item() == pytest.approx(1.25)
    assert segmentation_loss(g, h, coverage, "paper").item() == pytest.approx(math.sqrt(1.25) / 2)
    half = torch.tensor([[0.5, 1.0]])
    assert segmentation_loss(g, h, half, "code").item() == pytest.approx((0.75**2 + 1.0) / 1.0)


def test_photometric_loss_both_forms_by_hand():
    render = torch.ones(1, 1, 3)
    image = torch.zeros(1, 1, 3)
    face_region = torch.full((1, 1), 0.5)
    coverage = torch.ones(1, 1)
    paper = photometric_loss(render, image, face_region, coverage, blur=False, form="paper")
    code = photometric_loss(render, image, face_region, coverage, blur=False, form="code")
    assert paper.item() == pytest.approx(0.5) and code.item() == pytest.approx(1.0)
    half = photometric_loss(render, image, face_region, coverage * 0.5, blur=False, form="code")
    assert half.item() == pytest.approx(0.5)


def test_a_clipped_channel_is_a_lower_bound():
    image = torch.tensor([[[1.0, 0.5, 0.2]]])
    clipped = torch.tensor([[[True, False, False]]])
    ones = torch.ones(1, 1)
    above = torch.tensor([[[1.4, 0.5, 0.2]]], requires_grad=True)  # brighter than the clip: no error
    loss = photometric_loss(above, image, ones, ones, blur=False, form="paper", clipped=clipped)
    loss.backward()
    assert loss.item() == 0.0 and above.grad.abs().sum().item() == 0.0
    below = torch.tensor([[[0.7, 0.5, 0.2]]])  # darker than the clip: an error as before
    unbounded = photometric_loss(below, image, ones, ones, blur=False, form="paper")
    assert photometric_loss(below, image, ones, ones, blur=False, form="paper", clipped=clipped) == unbounded
    assert unbounded.item() == pytest.approx(0.1)
    # unclipped channels keep both signs
    over = torch.tensor([[[1.0, 0.8, 0.2]]])
    assert photometric_loss(over, image, ones, ones, blur=False, form="paper", clipped=clipped).item() == \
        pytest.approx(0.1)


def test_blur_kernel_and_effect_on_the_loss():
    kernel = gaussian_kernel3(1.0)
    assert kernel.sum().item() == pytest.approx(1.0)
    assert kernel[1, 1] / kernel[0, 1] == pytest.approx(math.exp(0.5)) and kernel[0, 1] / kernel[0, 0] == (
        pytest.approx(math.exp(0.5))
    )
    constant = torch.full((4, 5, 3), 0.3)
    assert torch.allclose(blur3(constant), constant)
    delta = torch.zeros(5, 5, 3)
    delta[2, 2] = 1.0
    assert torch.allclose(blur3(delta)[1:4, 1:4, 0], kernel)
    # the render's delta is spread by the blur: |blur(I_R) - 0| sums to the same mass over the 9 pixels
    ones = torch.ones(5, 5)
    blurred = photometric_loss(delta, torch.zeros(5, 5, 3), ones, ones, blur=True, form="paper")
    assert blurred.item() == pytest.approx(1.0 / 25.0, abs=1e-6)


def test_photometric_loss_shape_errors():
    with pytest.raises(ValueError):
        photometric_loss(torch.ones(2, 2, 3), torch.ones(2, 2, 3), torch.ones(2, 3), torch.ones(2, 2))
