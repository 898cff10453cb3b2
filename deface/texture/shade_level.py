"""Texels the render lights dimly take their level and colour from the lit skin around them.

Why: where the render's shading of a texel is dim (the masks keep most of the light from it, or its fitted surface
faces away from the lights), stage 3 reads its albedo as the photo over that dim shading, so any error of the masks,
the lights or the surface there is divided up and painted into the map: the eye socket's shading spread over the
upper lids gives bright yellow crescents above the eyes; a stripe of shade whose light has another colour leaves a
coloured streak. One photo tells the level and the colour of skin in the dark far worse than of the skin beside it
in the light.

So, with ``lit`` in [0, 1] how lit a texel is against the face's typical texel (its shading over the median of the
seen texels'; 1 from ``high`` of it up, 0 at ``low`` and below; smoothed over ``own_radius``), and Gaussian windows of
``own_radius`` and ``radius`` of the map's side:

    shift = mean_dark(x) - mean_lit(x)            (log luminance and log chromaticity, weights 1 - lit in the
                                                   small window and lit in the wide one)
    x' = x - (1 - lit) * shift                     (the luminance part only where it is > 0)

A texel in the dark keeps its own detail (its difference from the dark texels' local mean), and its local mean
becomes the lit skin's. Its luminance is only ever lowered: a dark texel darker than the lit skin around it may be
pigment (a beard under a brim), which the masks cannot be trusted to tell from shade, but one brighter than the lit
skin around it is the shading's error. Its chroma follows the lit skin both ways: skin chroma changes slowly. Where no
lit texel is near (a shadow wider than the window), nothing changes: ``support`` fades the shift out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from deface.texture.chroma import from_log_parts, log_parts, map_gaussian


@dataclass(frozen=True)
class ShadeLevelConfig:
    """The level and colour of the texels the render lights dimly (``FitConfig.shade_level``)."""

    enabled: bool = True
    """Move the texels the render lights dimly to the lit skin's level and colour around them (docs/textures.md
    "Texels in the dark"). Off (the paper's and NextFace's presets, and deface-mean-skin): stage 3's maps as they
    are."""
    radius: float = 0.03
    """Gaussian sigma of the lit skin's window, as a fraction of the map's side (15 texels at 512²): wider than the
    crescents and the stripes it corrects."""
    own_radius: float = 0.01
    """Gaussian sigma of the dark texels' own window (5 texels at 512²): what varies within it is their detail,
    kept."""
    low: float = 0.3
    """A texel whose shading is this share of the face's median or less counts fully as dark ..."""
    high: float = 0.8
    """... and one at this share or more fully as lit."""
    support: float = 0.2
    """The lit texels' weight in a window (its share of the seen ones) under which the shift fades out."""


def lit_share(light: np.ndarray, seen: np.ndarray, config: ShadeLevelConfig) -> np.ndarray:
    """[Ht, Wt] in [0, 1]: how lit each texel is against the face's median seen texel. ``light`` [Ht, Wt] is the
    shading at each texel, ``seen`` [Ht, Wt] how squarely it was seen (unseen texels: 1)."""
    trusted = seen >= 0.5
    if not trusted.any():
        return np.ones_like(light)
    reference = max(float(np.median(light[trusted])), 1e-6)
    share = np.where(seen > 0, np.clip((light / reference - config.low) / (config.high - config.low), 0.0, 1.0), 1.0)
    return np.clip(map_gaussian(share, config.own_radius), 0.0, 1.0)  # no seam where the shading steps (a lid's fold)


def shade_levelled(diffuse: np.ndarray, lit: np.ndarray, seen: np.ndarray, config: ShadeLevelConfig) -> np.ndarray:
    """``diffuse`` [Ht, Wt, 3] linear, ``lit`` [Ht, Wt] from :func:`lit_share`, ``seen`` [Ht, Wt] -> the map with
    its dark texels' local level and colour taken from the lit texels around them (module doc)."""
    _, log_luminance, chroma = log_parts(diffuse)
    values = np.concatenate([log_luminance[..., None], chroma], -1)
    weight = (seen > 0).astype(np.float64)
    dark_weight, lit_weight = weight * (1.0 - lit), weight * lit
    lit_total, total = map_gaussian(lit_weight, config.radius), map_gaussian(weight, config.radius)
    dark_mean = (map_gaussian(dark_weight[..., None] * values, config.own_radius)
                 / np.maximum(map_gaussian(dark_weight, config.own_radius), 1e-9)[..., None])
    lit_mean = map_gaussian(lit_weight[..., None] * values, config.radius) / np.maximum(lit_total, 1e-9)[..., None]
    shift = dark_mean - lit_mean
    shift[..., 0] = np.maximum(shift[..., 0], 0.0)
    fade = np.clip(lit_total / np.maximum(total, 1e-9) / config.support, 0.0, 1.0)
    moved = values - ((1.0 - lit) * fade * weight)[..., None] * shift
    return from_log_parts(np.exp(moved[..., 0]), moved[..., 1:], diffuse)
