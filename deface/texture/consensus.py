"""Several photos of one person: pigment is dark in every photo that lights it, a shadow only in some.

Stage 2's albedo model has no beard, freckles or moles, and its light masks learn to explain such dark pigment as a
dimmer light; stage 3 then fits the map under those masks and bleaches the pigment. One photo cannot tell the two
apart. Several photos can: the albedo is shared and the light is not. For each frame t and texel u,

    e_t(u) = Y(photo_t - specular_t) / Y(S_t)   at the texel's pixel,

is the albedo that frame implies under its *main* light alone (S_t: the diffuse shading of the kept light with the
largest masked area in frame t, with the fit's geometry and self-shadowing, no cast-shadow mask): the true albedo
times the frame's cast shadow there (<= 1). Its ratio to the fitted map, r_t(u) = e_t(u) / Y(T(u)), normalised by
its weighted median over the frame's texels (each frame's exposure and light level are left to the fit), is about 1
where the map explains that frame's main light, below 1 where the frame has a shadow the map does not hold or the
map is too bright (bleached pigment), above 1 where the map holds a shadow the frame does not show.

Per texel the frames' ratios are combined by a weighted upper quantile (``quantile``; weights: how squarely and
how sharply each frame sees the texel inside its face region): a shadow in one frame of three is outvoted by the
frames that light the texel, and a darkening every lit frame shows is kept, as pigment. The map's luminance is then
multiplied by that gain, smoothed over a few texels and held within ``gain_range``; its chroma ratios are kept
(the chroma filter follows). Texels fewer than ``min_frames`` frames see are left as they are: with one photo this
step changes nothing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

FLOOR = 1e-4


@dataclass(frozen=True)
class ConsensusConfig:
    """How the frames of a fit of several photos correct the map where they agree (``FitConfig.consensus``)."""

    enabled: bool = True
    """Correct the diffuse map's luminance from the frames' consensus (module doc; docs/textures.md). Acts only on
    texels at least ``min_frames`` frames see: a single photo's fit is unchanged."""
    quantile: float = 0.75
    """The weighted quantile of the frames' ratios per texel: above the median, so a frame's cast shadow is outvoted
    by frames that light the texel, below the maximum, so one frame's specular glint is too."""
    min_frames: int = 2
    """Frames that must see a texel (facing within ``max_angle``, inside their face region) for it to be corrected."""
    max_angle: float = 60.0
    """Degrees: a frame seeing a texel more obliquely does not vote on it (its shading is least certain there)."""
    smooth: float = 0.004
    """Gaussian sigma of the gain, as a fraction of the map's side (2 texels at 512²): the photos' registration
    error between frames is about a texel or two."""
    gain_range: tuple[float, float] = (0.5, 2.0)
    """The smallest and largest gain on a texel's luminance."""


def frame_ratios(estimates: np.ndarray, fitted: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """[T, Ht, Wt] each frame's implied luminance ``estimates`` over the map's ``fitted`` [Ht, Wt], normalised by
    its median over the texels it weighs (``weights`` [T, Ht, Wt] >= 0); 1 where unweighted."""
    ratios = np.ones_like(estimates, dtype=np.float64)
    for frame, (estimate, weight) in enumerate(zip(estimates, weights, strict=True)):
        valid = weight > 0
        if valid.sum() < 16:
            continue
        ratio = np.maximum(estimate[valid], FLOOR) / np.maximum(fitted[valid], FLOOR)
        ratios[frame][valid] = ratio / weighted_quantile(ratio[None], weight[valid][None], 0.5)[0]
    return ratios


def weighted_quantile(values: np.ndarray, weights: np.ndarray, quantile: float) -> np.ndarray:
    """The weighted ``quantile`` along axis 0 of ``values`` [T, ...] with ``weights`` [T, ...] >= 0: linear between
    the sorted values placed at their weights' midpoints (numpy's default for equal weights), the end values beyond
    them; NaN where every weight is 0."""
    order = np.argsort(values, axis=0)
    ranked = np.take_along_axis(values, order, 0).astype(np.float64)
    ranked_weights = np.take_along_axis(weights, order, 0).astype(np.float64)
    total = ranked_weights.sum(0)
    points = (np.cumsum(ranked_weights, 0) - 0.5 * ranked_weights) / np.where(total > 0, total, 1.0)
    valid = ranked_weights > 0
    below, above = valid & (points <= quantile), valid & (points > quantile)
    last = len(values) - 1 - np.argmax(below[::-1], axis=0)  # the last valid point at or below the quantile
    first = np.argmax(above, axis=0)  # the first valid point above it

    def at(array: np.ndarray, index: np.ndarray) -> np.ndarray:
        return np.take_along_axis(array, index[None], 0)[0]

    low_value, high_value = at(ranked, last), at(ranked, first)
    low_point, high_point = at(points, last), at(points, first)
    step = (quantile - low_point) / np.where(high_point > low_point, high_point - low_point, 1.0)
    between = low_value + step * (high_value - low_value)
    has_low, has_high = below.any(0), above.any(0)
    result = np.where(has_low & has_high, between, np.where(has_low, low_value, high_value))
    return np.where(total > 0, result, np.nan)


def consensus_gain(ratios: np.ndarray, weights: np.ndarray, config: ConsensusConfig) -> np.ndarray:
    """[Ht, Wt] the luminance gain of each texel from the frames' ``ratios`` and ``weights`` [T, Ht, Wt]: their
    weighted upper quantile where at least ``min_frames`` frames weigh the texel, smoothed, else 1 (module doc)."""
    voters = (weights > 0).sum(0)
    gain = weighted_quantile(np.log(np.maximum(ratios, FLOOR)), weights, config.quantile)
    supported = voters >= config.min_frames
    log_gain = np.where(supported, np.nan_to_num(gain), 0.0)
    sigma = config.smooth * ratios.shape[1]
    if sigma > 0:  # normalised convolution over the supported texels: no bleeding from texels left alone
        support = ndimage.gaussian_filter(supported.astype(np.float64), sigma)
        log_gain = ndimage.gaussian_filter(log_gain, sigma) / np.maximum(support, 1e-6) * supported
    if supported.sum() >= 16:  # the map's level stays the fit's: only where the frames disagree with it locally
        log_gain = (log_gain - np.median(log_gain[supported])) * supported
    low, high = config.gain_range
    return np.exp(np.clip(log_gain, np.log(low), np.log(high)))
