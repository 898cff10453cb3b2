"""Measures of a fitted diffuse map against the true albedo, in UV space (``deface bench albedo``).

All maps are linear RGB ``[S, S, 3]`` on one UV layout, scored at ``SCORE_SIZE``² (both maps resized first), and
regions are ``[S, S]`` bool masks. A fitted map's overall level is the light's business (its tone has its own
benchmark), so the map is first matched to the truth by one gain per channel over a reference region of plain skin
(:func:`gain_matched`); every other measure reads the matched map.

- **darkness kept** of a region R (a beard, freckles, a birthmark): K = mean luminance over R / mean over the
  reference, and (1 - K_fit) / (1 - K_truth): 1 when the map keeps the region as dark relative to the skin as the
  truth, 0 when it bleached it to skin, negative when the map is lighter there than its skin.
- **fine structure**: the correlation over R of the two maps' luminance minus its Gaussian blur (sigma 2 texels at
  256²): 1 when the map carries the truth's strokes and dots where they are, 0 when it carries none of them.
- **colour noise**: the RMS chroma of a map's fine structure (each channel minus its blur, in log-chroma axes), x100,
  beside the truth's: a map whose fine structure has more colour than the truth's carries colour noise or fringes.
- **colour error**: the RMS over the face of the CIELAB a*b* difference (D65) between the matched map and the truth,
  the map first brought to the truth's luminance texel by texel: its chromaticity alone, at the lightness a viewer
  sees it (about 2.3 is a just-noticeable difference): a map tinted where the lights' colours were wrong
  (green or magenta patches, a fringe along a mask's edge, at any scale) scores high; a map of the truth's colours,
  however light or dark, 0. Log-chromaticity would weigh a dark skin's errors several times a light one's.
- **PSNR / SSIM** of the matched sRGB map against the truth's over the scored face.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage
from skimage.color import rgb2lab
from skimage.metrics import structural_similarity
from skimage.transform import resize

from deface.io.images import LUMINANCE, linear_to_srgb

SCORE_SIZE = 256
"""Maps are compared at this side (the issue's definition: fine structure at 256²)."""
FINE_SIGMA = 2.0
"""Gaussian (texels at SCORE_SIZE) whose residue is the fine structure."""
FLOOR = 1e-3
"""Least linear value in the log-chroma of the colour noise (black stays finite)."""
MIN_CONTRAST = 0.05
"""Darkness kept is not defined for a region whose truth is less than this much darker than the reference."""


def at_score_size(image: np.ndarray) -> np.ndarray:
    """A map [S, S, C] (or a mask [S, S]) resized to SCORE_SIZE² with anti-aliasing (masks: area > 0.5)."""
    if image.shape[0] == SCORE_SIZE and image.shape[1] == SCORE_SIZE:
        return image
    if image.dtype == bool:
        return resize(image.astype(np.float32), (SCORE_SIZE, SCORE_SIZE), anti_aliasing=True) > 0.5
    return resize(image, (SCORE_SIZE, SCORE_SIZE, *image.shape[2:]), anti_aliasing=True)


def gain_matched(fitted: np.ndarray, truth: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """``fitted`` times one gain per channel that makes its mean over ``reference`` the truth's."""
    gain = truth[reference].mean(0) / np.maximum(fitted[reference].mean(0), 1e-6)
    return fitted * gain


def luminance(image: np.ndarray) -> np.ndarray:
    return image @ LUMINANCE


def darkness_kept(fitted: np.ndarray, truth: np.ndarray, region: np.ndarray, reference: np.ndarray) -> float:
    """(1 - K_fit) / (1 - K_truth), K = mean luminance over ``region`` / over ``reference`` (module doc);
    NaN when the truth's region is less than MIN_CONTRAST darker than its reference."""
    def contrast(image: np.ndarray) -> float:
        return float(luminance(image[region]).mean() / max(luminance(image[reference]).mean(), 1e-9))

    truth_contrast = contrast(truth)
    if truth_contrast > 1.0 - MIN_CONTRAST:
        return float("nan")
    return (1.0 - contrast(fitted)) / (1.0 - truth_contrast)


def fine_luminance(image: np.ndarray, sigma: float = FINE_SIGMA) -> np.ndarray:
    """Luminance minus its Gaussian blur of ``sigma`` texels [S, S]."""
    value = luminance(image)
    return value - ndimage.gaussian_filter(value, sigma, mode="nearest")


def fine_structure(fitted: np.ndarray, truth: np.ndarray, region: np.ndarray, sigma: float = FINE_SIGMA) -> float:
    """Correlation over ``region`` of the two maps' fine luminance (0 when the map's is flat there)."""
    mine, true = fine_luminance(fitted, sigma)[region], fine_luminance(truth, sigma)[region]
    mine, true = mine - mine.mean(), true - true.mean()
    norm = np.sqrt((mine * mine).sum() * (true * true).sum())
    return float((mine * true).sum() / norm) if norm > 0 else 0.0


def colour_noise(image: np.ndarray, region: np.ndarray, sigma: float = FINE_SIGMA) -> float:
    """RMS over ``region`` of the chroma of the map's fine structure, x100 (module doc): log-RGB minus its blur,
    projected on the two axes orthogonal to grey (red-green, yellow-blue)."""
    logs = np.log(np.maximum(image, FLOOR))
    fine = logs - np.stack([ndimage.gaussian_filter(logs[..., c], sigma, mode="nearest") for c in range(3)], -1)
    axes = np.array([[1.0, -1.0, 0.0], [0.5, 0.5, -1.0]])
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    chroma = fine[region] @ axes.T
    return float(100 * np.sqrt((chroma ** 2).sum(-1).mean()))


def colour_error(fitted: np.ndarray, truth: np.ndarray, region: np.ndarray) -> float:
    """RMS over ``region`` of the a*b* difference of two linear maps at the truth's luminance (module doc)."""
    ratio = luminance(truth[region]) / np.maximum(luminance(fitted[region]), FLOOR)
    recoloured = fitted[region] * ratio[:, None]
    lab_fitted, lab_truth = (rgb2lab(linear_to_srgb(np.clip(x, 0.0, 1.0))[None])[0]
                             for x in (recoloured, truth[region]))
    return float(np.sqrt(((lab_fitted[:, 1:] - lab_truth[:, 1:]) ** 2).sum(-1).mean()))


def psnr_ssim(fitted: np.ndarray, truth: np.ndarray, region: np.ndarray) -> tuple[float, float]:
    """PSNR (dB) and SSIM of the sRGB maps over ``region`` (SSIM: mean of its map over the region)."""
    mine, true = linear_to_srgb(np.clip(fitted, 0, 1)), linear_to_srgb(np.clip(truth, 0, 1))
    mse = float(((mine - true)[region] ** 2).mean())
    psnr = 10 * np.log10(1.0 / max(mse, 1e-12))
    _, ssim_map = structural_similarity(true, mine, channel_axis=-1, data_range=1.0, full=True)
    return psnr, float(ssim_map.mean(-1)[region].mean())


def difference_image(fitted: np.ndarray, truth: np.ndarray, shown: np.ndarray, gain: float = 4.0) -> np.ndarray:
    """|fitted - truth| of the sRGB maps times ``gain``, mid-grey where not shown [S, S, 3] (contact sheets)."""
    diff = np.abs(linear_to_srgb(np.clip(fitted, 0, 1)) - linear_to_srgb(np.clip(truth, 0, 1))) * gain
    return np.where(shown[..., None], np.clip(diff, 0, 1), 0.5)
