"""Skin tone as the individual typology angle (ITA), measured on a texture and on the photo it came from.

ITA = atan2(L* - 50, b*) in degrees, CIELAB (D65) of sRGB-encoded colours (Chardon, Cretois, Hourseau,
"Skin colour typology and suntanning pathways", Int. J. Cosmet. Sci. 1991; the measure of the FAIR albedo
benchmark, Feng et al., TRUST, ECCV 2022). Groups after Del Bino et al. 2006: > 55 very light, 41-55 light,
28-41 intermediate, 10-28 tan, -30-10 brown, < -30 dark.

Where: the median (L*, a*, b*) over three UV boxes of the ICT layout, both cheeks and the forehead
(:data:`TONE_BOXES`; the boxes the ground truth of ``../shared/data/skin-tone-synth`` is measured on), then
the ITA of that median. On a texture every texel in the boxes counts. On a photo the same boxes are found
through the fitted geometry: each covered pixel's UV (from the fit's ray cast) picks the pixels that show the
cheeks and forehead; of those, pixels the face-region classifier h rejects (hair, glasses), clipped pixels
(a channel >= 0.98: highlights) and shadowed pixels (luminance below half the 90th percentile of the region:
cast and attached shadows) are left out, so the photo's ITA is that of its lit skin.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from skimage.color import rgb2lab

from deface.io.images import CLIPPED, GAMMA, LUMINANCE, linear_to_srgb

# (u0, u1, y0, y1) with y = 1 - v measured downward from the texture image's top (ICT layout).
TONE_BOXES = {
    "left_cheek": (0.195, 0.342, 0.42, 0.547),
    "right_cheek": (0.658, 0.805, 0.42, 0.547),
    "forehead": (0.352, 0.648, 0.137, 0.205),
}
SHADOW_FRACTION = 0.5  # pixels darker than this fraction of the region's 90th-percentile luminance are shadow
MIN_PIXELS = 12  # fewer usable pixels than this: no photo ITA


def ita_degrees(lab: np.ndarray) -> np.ndarray:
    """ITA in degrees of CIELAB values [..., 3]."""
    lab = np.asarray(lab, dtype=np.float64)
    return np.degrees(np.arctan2(lab[..., 0] - 50.0, lab[..., 2]))


ITA_GROUPS = (("very light", 55.0), ("light", 41.0), ("intermediate", 28.0), ("tan", 10.0), ("brown", -30.0),
              ("dark", -np.inf))
"""Skin colour categories by ITA (Chardon et al. 1991; Del Bino et al. 2006): each name with its lower bound in
degrees, lightest first."""


def ita_group(ita: float) -> str:
    """The :data:`ITA_GROUPS` category of an ITA in degrees."""
    return next(name for name, lower in ITA_GROUPS if ita > lower)


def median_lab(srgb: np.ndarray) -> np.ndarray:
    """Median (L*, a*, b*) [3] of sRGB-encoded colours [N, 3] in [0, 1]."""
    lab = rgb2lab(np.clip(np.asarray(srgb, dtype=np.float64), 0.0, 1.0)[None])[0]
    return np.median(lab, axis=0)


def ita_of_srgb(srgb: np.ndarray) -> float:
    """ITA of the median CIELAB colour of sRGB pixels [N, 3]."""
    return float(ita_degrees(median_lab(srgb)))


def in_tone_boxes(uv: np.ndarray) -> np.ndarray:
    """Whether UV coordinates [..., 2] (v up) fall in a cheek or forehead box -> bool [...]."""
    u, y = uv[..., 0], 1.0 - uv[..., 1]
    inside = np.zeros(u.shape, dtype=bool)
    for u0, u1, y0, y1 in TONE_BOXES.values():
        inside |= (u >= u0) & (u <= u1) & (y >= y0) & (y <= y1)
    return inside


def texture_tone_mask(height: int, width: int) -> np.ndarray:
    """bool [H, W]: texels of a texture image (row 0 = v 1) whose centres fall in the tone boxes."""
    v = 1.0 - (np.arange(height) + 0.5) / height
    u = (np.arange(width) + 0.5) / width
    grid = np.stack(np.meshgrid(u, v, indexing="xy"), -1)
    return in_tone_boxes(grid)


def texture_ita(diffuse_srgb: np.ndarray) -> float:
    """ITA of a diffuse texture [H, W, 3] (sRGB-encoded, as written to textures/diffuse.png)."""
    mask = texture_tone_mask(*diffuse_srgb.shape[:2])
    return ita_of_srgb(diffuse_srgb[mask])


def grayscale(srgb: np.ndarray, tolerance: float = 1.5 / 255) -> bool:
    """Whether colours [..., 3] are grey (all channels equal within ``tolerance`` on 99 % of them)."""
    srgb = np.asarray(srgb).reshape(-1, 3)
    if len(srgb) == 0:
        return False
    return float(np.mean(np.ptp(srgb, axis=-1) <= tolerance)) >= 0.99


GRAYSCALE_NOTE = "a grayscale photo shows no skin tone: the map's colour is the face model's mean skin"


def texture_tone(diffuse_linear: np.ndarray, level_sigma: float | None, photo_srgb: np.ndarray | None = None) -> dict:
    """The tone of a diffuse map [H, W, 3] (linear RGB): its ITA, and the ITA intervals that the white level's
    one- and two-sigma spreads (``level_sigma``, natural log; None when no white level was estimated) allow.
    None for all three, and a ``note``, when the fitted ``photo_srgb`` [H, W, 3] is grayscale: the map's colour is
    then the model's, not the person's (a data set counting tones must not count it).

    A fit holds its brightest light to the white level W, so the map's level is the photo's over W: W brighter by
    exp(sigma) makes every texel exp(-sigma) as light (the map's colour stays). The interval is the ITA of the
    map's tone boxes scaled by exp(-sigma) and exp(+sigma); it covers W's level only, not the light's colour nor
    how the skin was read (docs/skin-tone.md)."""
    if photo_srgb is not None and grayscale(photo_srgb):
        return {"texture_ita": None, "ita_interval": None, "ita_interval_2sigma": None, "note": GRAYSCALE_NOTE}
    linear = np.clip(np.asarray(diffuse_linear, dtype=np.float64), 0.0, 1.0)
    texels = linear[texture_tone_mask(*linear.shape[:2])]
    record = {"texture_ita": round(ita_of_srgb(linear_to_srgb(texels)), 2), "ita_interval": None,
              "ita_interval_2sigma": None}
    if level_sigma is not None:
        for key, sigma in (("ita_interval", level_sigma), ("ita_interval_2sigma", 2 * level_sigma)):
            darker, lighter = (ita_of_srgb(linear_to_srgb(np.clip(texels * np.exp(s), 0.0, 1.0)))
                               for s in (-sigma, sigma))
            record[key] = [round(darker, 2), round(lighter, 2)]
    return record


def lit_skin(pixels_srgb: np.ndarray) -> np.ndarray:
    """bool [N]: pixels that are neither clipped nor in shadow (see the module doc)."""
    if len(pixels_srgb) == 0:
        return np.zeros(0, dtype=bool)
    pixels_srgb = np.clip(pixels_srgb, 0.0, 1.0)  # resampling can overshoot [0, 1] slightly
    unclipped = pixels_srgb.max(-1) < CLIPPED
    luminance = (pixels_srgb**GAMMA) @ LUMINANCE
    bright = np.percentile(luminance[unclipped], 90) if unclipped.any() else np.inf
    return unclipped & (luminance >= SHADOW_FRACTION * bright)


@dataclass(frozen=True)
class PhotoTone:
    """The photo's lit skin over the tone boxes: its ITA (NaN when too few pixels) and pixel count."""

    ita: float
    pixels: int


def photo_tone(photo_srgb: np.ndarray, uv: np.ndarray, covered: np.ndarray, skin: np.ndarray) -> PhotoTone:
    """Photo [H, W, 3] sRGB; uv [H, W, 2] of the fitted face; covered, skin [H, W] bool (M_R, h > 0.5)."""
    region = covered & skin & in_tone_boxes(uv)
    pixels = photo_srgb[region]
    usable = pixels[lit_skin(pixels)]
    if len(usable) < MIN_PIXELS:
        return PhotoTone(float("nan"), int(len(usable)))
    return PhotoTone(ita_of_srgb(usable), int(len(usable)))


def pixel_uvs(fragments, mesh) -> np.ndarray:
    """[H, W, 2] UV of every covered pixel (0 elsewhere) from ray-cast ``fragments`` of ``mesh``."""
    corners = mesh.uvs[mesh.triangle_uvs[fragments.covered_triangles]]  # [N, 3, 2]
    uv = (fragments.covered_barycentrics.detach()[..., None] * corners).sum(1)
    height, width = fragments.triangle_id.shape
    full = torch.zeros(height * width, 2, dtype=uv.dtype).index_copy(0, fragments.covered, uv)
    return full.reshape(height, width, 2).numpy()
