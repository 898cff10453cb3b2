"""L_area, L_bin, L_seg and L_pho against hand-computed values."""

from __future__ import annotations

import math

import pytest
import torch

from deface.losses.decouple import area_loss, binary_loss, segmentation_loss
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
