"""The diffuse map's chroma follows its luminance: a guided filter of the log-chromaticity, guided by the
log-luminance.

Why: a skin albedo's chroma changes slowly; where it changes fast (lips, brows, a mole, a birthmark) its luminance
changes with it. Chroma that changes with no luminance change beside it is what the lights left in the map: the
different colours of two lights under a mask edge, per-texel colour noise where a map has more texels than the
photo has pixels. A guided filter (He, Sun and Tang 2013, "Guided Image Filtering") keeps, in every window, the
part of the chroma that is a linear function of the luminance and replaces the rest by its local mean:

    c'(x) = mean_w(a) G(x) + mean_w(b),   a = cov(G, c) / (var(G) + eps),   b = mean(c) - a mean(G)

with G = log Y (the guide: the map's luminance, left unchanged), c = log(X / Y) for X = R, G, B, windows of
``radius`` of the map's side, and every mean weighted by how squarely the photos saw each texel, so texels no
photo showed (completion fills them next) do not bleed in. A mole (darker and browner) keeps its chroma, because it
is darker; a chroma step at a mask's edge across even skin is averaged away. The luminance, where every fine detail
of a beard, stubble or freckles lives, is exactly the fitted one.

The window is never finer than the photos' colour: a camera records colour at half its resolution (the colour
filter array; JPEG's 4:2:0 sampling), so chroma that changes within about two pixels is not in a photo. Where the
map has more texels than the photo has pixels (a small face, a large map, the benchmarks' 128-px working photos:
2.7 texels a pixel at 256²), the window's half-side grows to ``pixels`` photo pixels in texels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from deface.io.images import LUMINANCE

FLOOR = 1e-4  # linear albedo floor before the logs (a black texel)


@dataclass(frozen=True)
class ChromaConfig:
    """How the diffuse map's chroma is held to its luminance after stage 3 (``FitConfig.chroma``)."""

    enabled: bool = True
    """Filter the diffuse map's chroma (docs/textures.md "Chroma"). Off (the paper's and NextFace's presets, and
    deface-mean-skin): stage 3's map as it is."""
    radius: float = 0.016
    """Window half-side as a fraction of the map's side (8 texels at 512², about 4 pixels of a 512-px crop): the
    scale of the colour noise removed (0.008 before 2026-11-29: the board's colour noise at the working size 14-22 %
    higher, its synthesis the same)."""
    pixels: float = 2.0
    """Least window half-side in the photos' pixels (the module doc: a photo's colour has half its resolution),
    read in texels from how many texels a photo pixel spans on the face (:func:`texels_per_pixel`). At the
    default's 512² maps of a 512-px crop a pixel spans about 1.8 texels, so ``radius`` decides there; with
    fewer pixels per texel the window grows."""
    eps: float = 0.002
    """Regularisation of the guided filter, in (log luminance)²: a window whose luminance varies less than about
    sqrt(eps) (4 %) is treated as flat, its chroma set to the local mean."""


def _box(image: np.ndarray, size: int) -> np.ndarray:
    return ndimage.uniform_filter(image, size=(size, size) + (1,) * (image.ndim - 2), mode="nearest")


def texels_per_pixel(density: np.ndarray, weight: np.ndarray) -> float:
    """How many texels one photo pixel spans across, at the median texel seen at least half squarely: 1 / sqrt of
    the pixels per texel ``density`` [Ht, Wt] (the best frame's, foreshortening included); 0 when none is."""
    seen = (weight >= 0.5) & (density > 0)
    return float(np.median(1.0 / np.sqrt(density[seen]))) if seen.any() else 0.0


def window_side(config: ChromaConfig, size: int, texels_a_pixel: float) -> int:
    """The guided filter's window side in texels for a size² map (odd, at least 3)."""
    return 2 * max(1, round(max(config.radius * size, config.pixels * texels_a_pixel))) + 1


MIN_SKIN = 200  # fewer trusted skin texels than this: the skin's chroma is not read off the map


def skin_chroma_gain(diffuse: np.ndarray, skin_texels: np.ndarray, skin: np.ndarray) -> np.ndarray | None:
    """[3] the per-channel gain that gives the map's skin (the median colour of ``diffuse`` [Ht, Wt, 3] over
    ``skin_texels`` [Ht, Wt] bool) the chroma of ``skin`` [3] (linear RGB) at the map's own luminance; None with
    fewer than ``MIN_SKIN`` texels."""
    if skin_texels.sum() < MIN_SKIN:
        return None
    median = np.maximum(np.median(diffuse[skin_texels].astype(np.float64), axis=0), FLOOR)
    gain = np.maximum(np.asarray(skin, np.float64), FLOOR) / median
    luminance = np.asarray(LUMINANCE, np.float64)
    return gain * (median @ luminance) / ((median * gain) @ luminance)


def log_parts(diffuse: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``diffuse`` [Ht, Wt, 3] linear -> (luminance Y [Ht, Wt], log Y [Ht, Wt], log-chromaticity log(X / Y)
    [Ht, Wt, 3]), in float64, the albedo floored at ``FLOOR`` before the logs."""
    rgb = np.maximum(diffuse.astype(np.float64), FLOOR)
    luminance = rgb @ np.asarray(LUMINANCE, np.float64)
    log_luminance = np.log(luminance)
    return luminance, log_luminance, np.log(rgb) - log_luminance[..., None]


def from_log_parts(luminance: np.ndarray, chroma: np.ndarray, diffuse: np.ndarray) -> np.ndarray:
    """The map of ``luminance`` [Ht, Wt] (linear, kept exactly) and log-chromaticity ``chroma`` [Ht, Wt, 3], in
    ``diffuse``'s dtype; ``diffuse``'s black texels (outside the layout) stay as they were."""
    out = luminance[..., None] * np.exp(chroma)
    out *= (luminance / np.maximum(out @ np.asarray(LUMINANCE, np.float64), FLOOR))[..., None]
    keep = diffuse.max(-1) <= FLOOR
    out[keep] = diffuse[keep]
    return out.astype(diffuse.dtype)


def map_gaussian(image: np.ndarray, radius: float) -> np.ndarray:
    """``image`` [Ht, Wt] or [Ht, Wt, C] blurred over the map's two axes by a Gaussian of sigma ``radius`` of its side
    (channels apart, edges repeated): the local windows of the texel steps after stage 3."""
    sigma = radius * image.shape[0]
    return ndimage.gaussian_filter(image, (sigma, sigma) + (0,) * (image.ndim - 2), mode="nearest")


def filter_chroma(diffuse: np.ndarray, weight: np.ndarray, config: ChromaConfig,
                  texels_a_pixel: float = 0.0) -> np.ndarray:
    """``diffuse`` [Ht, Wt, 3] linear, ``weight`` [Ht, Wt] >= 0 (how well each texel was seen) -> the map with its
    chroma guided by its luminance; every texel's luminance unchanged (module doc). ``texels_a_pixel``: how many
    texels a photo pixel spans (:func:`texels_per_pixel`; 0: the window is ``config.radius`` alone)."""
    size = window_side(config, diffuse.shape[0], texels_a_pixel)
    luminance, guide, chroma = log_parts(diffuse)
    w = np.asarray(weight, np.float64) + 1e-6
    total = _box(w, size)

    def mean(values: np.ndarray) -> np.ndarray:
        spread = w if values.ndim == 2 else w[..., None]
        return _box(spread * values, size) / (total if values.ndim == 2 else total[..., None])

    mean_g, mean_c = mean(guide), mean(chroma)
    var_g = mean(guide * guide) - mean_g ** 2
    cov = mean(guide[..., None] * chroma) - mean_g[..., None] * mean_c
    a = cov / (np.maximum(var_g, 0.0) + config.eps)[..., None]
    b = mean_c - a * mean_g[..., None]
    return from_log_parts(luminance, mean(a) * guide[..., None] + mean(b), diffuse)
