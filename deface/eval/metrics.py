"""Image metrics of the paper's protocol (Sec. 4): PSNR, SSIM, LPIPS-alex, over the face and the full image.

All images are float ``[H, W, 3]`` arrays in [0, 1] (sRGB, as written to disk); masks are ``[H, W]``
(bool or float in [0, 1]; the face *region* is ``mask > 0.5``, the composite uses the soft values).

Two variants, clearly labelled in every result:

- ``"full"`` (the authors' protocol as coded): the prediction is pasted into the reference,
  ``composite = mask * output + (1 - mask) * reference``, and PSNR / SSIM / LPIPS are computed
  between ``composite`` and ``reference`` over the whole image. The untouched background inflates
  PSNR and SSIM, which is why the face variant exists.
- ``"face"``: only the face pixels count.
  * PSNR: the MSE over the mask's pixels (all three channels) only.
  * SSIM: the mean of the full-resolution SSIM map (channel-averaged) over the mask's pixels.
  * LPIPS: ``composite`` vs ``reference`` (outside-mask pixels are equal, so they add no
    difference) cropped to the bounding box of the mask (grown to at least 32 px per side,
    AlexNet's minimum input).

SSIM settings (:class:`SsimConfig`): by default the sewar defaults the authors used
(``sewar.full_ref.ssim``: 11x11 uniform window, population covariance, K1=0.01, K2=0.03,
per-channel mean), computed with ``skimage.metrics.structural_similarity(win_size=11,
gaussian_weights=False, use_sample_covariance=False, data_range=1, channel_axis=-1)``. sewar crops
6 border pixels of the map and skimage 5, so values differ from sewar's in the 4th decimal.
``SsimConfig(window="gaussian")`` gives Wang et al. 2004 (11-tap Gaussian, sigma 1.5).

LPIPS is reported x100, as in the paper's tables.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from skimage.metrics import structural_similarity

from deface.eval.lpips import lpips_distance

METRIC_NAMES = ("psnr", "ssim", "lpips")
LPIPS_MIN_SIDE = 32


@dataclass(frozen=True)
class SsimConfig:
    """How SSIM windows are formed."""

    window: Literal["uniform", "gaussian"] = "uniform"
    """"uniform": sewar default (11x11 box, what the authors ran); "gaussian": Wang et al. 2004."""
    win_size: int = 11
    """Window side in pixels (uniform window only; the Gaussian window is 11 taps for sigma 1.5)."""


def _check_pair(output: np.ndarray, reference: np.ndarray) -> None:
    if output.shape != reference.shape or output.ndim != 3 or output.shape[2] != 3:
        raise ValueError(f"need two [H, W, 3] images of one shape, got {output.shape} and {reference.shape}")


def _check_mask(mask: np.ndarray, image: np.ndarray) -> np.ndarray:
    """Return the mask as float ``[H, W]``; raise if its shape does not match or it is empty."""
    mask = np.asarray(mask)
    if mask.ndim == 3 and mask.shape[2] == 1:
        mask = mask[..., 0]
    if mask.shape != image.shape[:2]:
        raise ValueError(f"mask shape {mask.shape} does not match image {image.shape[:2]}")
    mask = mask.astype(np.float64)
    if not (mask > 0.5).any():
        raise ValueError("mask is empty: no pixel above 0.5")
    return mask


def psnr(output: np.ndarray, reference: np.ndarray, region: np.ndarray | None = None) -> float:
    """PSNR in dB for data range 1; ``region`` (bool ``[H, W]``) restricts the MSE to those pixels.

    Identical images give ``inf``.
    """
    _check_pair(output, reference)
    diff2 = (np.asarray(output, np.float64) - np.asarray(reference, np.float64)) ** 2  # [H, W, 3]
    mse = float(diff2[region].mean()) if region is not None else float(diff2.mean())
    return float("inf") if mse == 0.0 else float(-10.0 * np.log10(mse))


def _ssim_kwargs(config: SsimConfig) -> dict:
    if config.window == "gaussian":
        return dict(gaussian_weights=True, sigma=1.5, use_sample_covariance=False)
    if config.window == "uniform":
        return dict(win_size=config.win_size, gaussian_weights=False, use_sample_covariance=False)
    raise ValueError(f"unknown SSIM window {config.window!r}; choose 'uniform' or 'gaussian'")


def ssim(
    output: np.ndarray,
    reference: np.ndarray,
    region: np.ndarray | None = None,
    config: SsimConfig = SsimConfig(),
) -> float:
    """SSIM (data range 1, channel-averaged); with ``region`` the mean of the SSIM map over those pixels."""
    _check_pair(output, reference)
    a, b = np.asarray(output, np.float64), np.asarray(reference, np.float64)
    kwargs = _ssim_kwargs(config)
    if region is None:
        return float(structural_similarity(a, b, data_range=1.0, channel_axis=-1, **kwargs))
    _, ssim_map = structural_similarity(a, b, data_range=1.0, channel_axis=-1, full=True, **kwargs)
    return float(ssim_map.mean(axis=-1)[region].mean())


def mask_bbox(region: np.ndarray, min_side: int = LPIPS_MIN_SIDE) -> tuple[slice, slice]:
    """Bounding box of a bool ``[H, W]`` region as (rows, cols) slices, grown to ``min_side`` if possible."""
    rows, cols = np.nonzero(region)
    if rows.size == 0:
        raise ValueError("mask_bbox: empty region")
    spans = []
    for idx, size in ((rows, region.shape[0]), (cols, region.shape[1])):
        lo, hi = int(idx.min()), int(idx.max()) + 1
        need = min(min_side, size)
        if hi - lo < need:  # grow around the centre, shifted back inside the image
            lo = int(np.clip((lo + hi) // 2 - need // 2, 0, size - need))
            hi = lo + need
        spans.append(slice(int(lo), int(hi)))
    return spans[0], spans[1]


def lpips(output: np.ndarray, reference: np.ndarray) -> float:
    """LPIPS-alex v0.1 x100 (the paper's unit) between two ``[H, W, 3]`` images in [0, 1]."""
    _check_pair(output, reference)
    return 100.0 * lpips_distance(output, reference)


def composite(output: np.ndarray, reference: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``mask * output + (1 - mask) * reference``, the authors' I_out; ``[H, W, 3]`` float32."""
    _check_pair(output, reference)
    m = _check_mask(mask, output)[..., None]
    return (m * output + (1.0 - m) * reference).astype(np.float32)


def score_images(
    output: np.ndarray, reference: np.ndarray, mask: np.ndarray, ssim_config: SsimConfig = SsimConfig()
) -> dict[str, dict[str, float]]:
    """Score a rendering against its reference photo.

    Args:
        output: ``[H, W, 3]`` rendering in [0, 1] (only its masked pixels matter).
        reference: ``[H, W, 3]`` photo in [0, 1].
        mask: ``[H, W]`` face mask (bool or float in [0, 1]).

    Returns:
        ``{"face": {"psnr", "ssim", "lpips"}, "full": {"psnr", "ssim", "lpips"}}``; PSNR in dB,
        LPIPS x100. See the module docstring for the exact definitions.
    """
    _check_pair(output, reference)
    output = np.clip(np.asarray(output, np.float32), 0.0, 1.0)
    reference = np.clip(np.asarray(reference, np.float32), 0.0, 1.0)
    mask = _check_mask(mask, output)
    region = mask > 0.5
    pasted = composite(output, reference, mask)
    rows, cols = mask_bbox(region)
    face = {
        "psnr": psnr(pasted, reference, region),
        "ssim": ssim(pasted, reference, region, ssim_config),
        "lpips": lpips(pasted[rows, cols], reference[rows, cols]),
    }
    full = {
        "psnr": psnr(pasted, reference),
        "ssim": ssim(pasted, reference, None, ssim_config),
        "lpips": lpips(pasted, reference),
    }
    return {"face": face, "full": full}


def mean_scores(scores: list[dict[str, dict[str, float]]]) -> dict[str, dict[str, float]]:
    """Average a list of :func:`score_images` results key by key (PSNR inf values are kept: mean is inf)."""
    if not scores:
        raise ValueError("mean_scores: no scores to average")
    return {
        region: {name: float(np.mean([s[region][name] for s in scores])) for name in METRIC_NAMES}
        for region in ("face", "full")
    }
