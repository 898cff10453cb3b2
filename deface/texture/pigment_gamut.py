"""The diffuse map's colours held to the hues the face's own pigments make: no green or blue skin, beard or lips.

Why: the pigments of skin, hair and lips (eumelanin, pheomelanin, haemoglobin, carotene) all absorb blue more than
green and green no less than red, so their albedos go from red through orange to yellow and grey: red >= green, and
yellow (the mean of red and green in log) >= blue. The renders of known albedo stay within it to the last texel, and
so do the maps of clean, evenly lit photos. A texel outside it is the light's colour left in the map: the green of
sunlight through leaves on a beard, the blue of a sky fill under a mask edge, a lens's tint. The fit cannot always
tell a light's colour from the albedo's, but it can tell that no face is teal.

So, in log chromaticity, with u = log(R / G) and v = log(sqrt(R G) / B) (the gamut is u >= 0 and v >= 0):
- a texel outside by ``excess`` (its distance to the gamut in (u, v)) takes the chroma of the in-gamut texels
  around it (a Gaussian window of ``radius`` of the map's side), by min(excess / ``ramp``, 1): far outside, all of
  it; at the edge, little. The window weighs a texel by how far inside it is, min(u, v) / ``ramp`` up to 1: the
  texels just inside beside a green patch are the patch's fringe (olive), not the skin;
- then what is still outside (no in-gamut texel near) is moved to the gamut's edge: red raised to green, blue
  lowered to yellow.
Every texel's luminance is kept, so a beard stays as dark as it was; only its hue changes. In-gamut texels are not
touched. Make-up or a tattoo in blue, green or violet is outside the gamut too and is greyed towards the skin: turn
this off (``pigment_gamut.enabled=false``) for such a face.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from deface.texture.chroma import from_log_parts, log_parts, map_gaussian


@dataclass(frozen=True)
class PigmentGamutConfig:
    """The diffuse map's hues held to the pigments' (``FitConfig.pigment_gamut``)."""

    enabled: bool = True
    """Move the texels whose hue no skin, hair or lip pigment makes (green, blue, violet) to the chroma of the skin
    around them (docs/textures.md "Pigment hues"). Off (the paper's and NextFace's presets, deface-mean-skin, and
    faces with blue, green or violet make-up): the maps' hues as fitted."""
    radius: float = 0.02
    """Gaussian sigma of the window whose in-gamut texels give an outside texel its chroma, as a fraction of the
    map's side (10 texels at 512²): wider than a beard's strands, narrower than the face's features."""
    ramp: float = 0.05
    """Distance outside the gamut (natural log of a channel ratio: 5 %) at which a texel takes all of its window's
    chroma, nearer the edge a share in proportion; and the depth inside at which a texel counts fully in the
    window (skin is 0.25 or more inside on every texel of the truth renders)."""


def hue_coordinates(chroma: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(u, v) [Ht, Wt] of log-chromaticity ``chroma`` [Ht, Wt, 3] (:func:`~deface.texture.chroma.log_parts`):
    u = log(R / G), v = log(sqrt(R G) / B); the pigments' gamut is u >= 0 and v >= 0."""
    red, green, blue = chroma[..., 0], chroma[..., 1], chroma[..., 2]
    return red - green, 0.5 * (red + green) - blue


def gamut_excess(chroma: np.ndarray) -> np.ndarray:
    """[Ht, Wt]: each texel's distance outside the gamut in (u, v) (0 inside)."""
    u, v = hue_coordinates(chroma)
    return np.hypot(np.minimum(u, 0.0), np.minimum(v, 0.0))


def outside_share(diffuse: np.ndarray, seen: np.ndarray) -> float:
    """The share of the seen texels (``seen`` [Ht, Wt] > 0) of ``diffuse`` [Ht, Wt, 3] whose hue lies outside the
    pigments' gamut (0 when none was seen)."""
    shown = seen > 0
    if not shown.any():
        return 0.0
    return float((gamut_excess(log_parts(diffuse)[2]) > 0)[shown].mean())


def in_pigment_gamut(diffuse: np.ndarray, seen: np.ndarray, config: PigmentGamutConfig) -> np.ndarray:
    """``diffuse`` [Ht, Wt, 3] linear, ``seen`` [Ht, Wt] (> 0: a photo showed the texel) -> the map with every
    texel's hue within the pigments' gamut and its luminance unchanged (module doc)."""
    luminance, _, chroma = log_parts(diffuse)
    excess = gamut_excess(chroma)
    if not (excess > 0).any():
        return diffuse
    u, v = hue_coordinates(chroma)
    inside = np.clip(np.minimum(u, v) / config.ramp, 0.0, 1.0) * (seen > 0)
    total = map_gaussian(inside, config.radius)
    window = map_gaussian(inside[..., None] * chroma, config.radius) / np.maximum(total, 1e-9)[..., None]
    share = np.clip(excess / config.ramp, 0.0, 1.0) * (total > 1e-6)
    moved = chroma + share[..., None] * (window - chroma)
    return from_log_parts(luminance, onto_gamut(moved), diffuse)


def onto_gamut(chroma: np.ndarray) -> np.ndarray:
    """``chroma`` [Ht, Wt, 3] with the texels still outside the gamut moved to its edge: red raised to green (u = 0),
    then blue lowered to the mean of red and green (v = 0); the luminance is restored by the caller."""
    out = chroma.copy()
    u, _ = hue_coordinates(out)
    out[..., 0] -= np.minimum(u, 0.0)
    _, v = hue_coordinates(out)
    out[..., 2] += np.minimum(v, 0.0)
    return out
