"""Which pixels tell the lights apart from the albedo: a weight that is low where the photo has hair-like texture.

A light, even a cast shadow, multiplies the skin's radiance: in log luminance it adds a smooth offset (and a step
along a shadow's edge) but leaves the skin's fine texture as it was. Hair (a beard, stubble, brows), freckles and
make-up are fine texture themselves. Stage 2 fits the lights, the light masks and the geometry with an albedo
model that has no room for them, so where they are it explains them with the lights: a goatee as a light from
above, a moustache as a mask. With this weight on stage 2's photometric term, such pixels count less there
(stage 3 still fits every pixel of the face region, so their albedo comes from the photo).

    fine   = log Y - G_a * log Y                 Y the photo's linear luminance, a = ``fine_scale`` x face size
    energy = G_b * fine^2                        b = ``energy_scale`` x face size
    weight = exp(-energy / (strength x median energy over the face))

A shadow's edge is a line of high energy a few pixels wide; the beard is an area of it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from deface.io.images import LUMINANCE


@dataclass(frozen=True)
class ShadingEvidenceConfig:
    """How stage 2 weighs pixels by their fine texture (``FitConfig.shading_evidence``)."""

    strength: float = 0.0
    """A pixel whose texture energy is this many times the face's median gets weight 1/e in stage 2's L_pho;
    0 = every pixel counts alike (the paper)."""
    fine_scale: float = 0.008
    """Gaussian whose residue is the fine texture, as a share of the face's size (its landmarks' box diagonal):
    about a pixel at the default working size."""
    energy_scale: float = 0.02
    """Gaussian over which the fine texture's energy is averaged, as a share of the face's size."""
    floor: float = 1e-3
    """Least linear luminance of the log (dark pixels' noise stays finite)."""


def texture_weight(image: np.ndarray, face: np.ndarray, face_size: float, config: ShadingEvidenceConfig) -> np.ndarray:
    """[H, W] in (0, 1]: the weight of each pixel of ``image`` (linear RGB [H, W, 3]) in stage 2's L_pho; ``face``
    [H, W] in [0, 1] (h) says where the face's median energy is taken, ``face_size`` in pixels."""
    if config.strength <= 0:
        return np.ones(image.shape[:2], np.float32)
    log_luminance = np.log(np.maximum(image @ LUMINANCE, config.floor))
    fine = log_luminance - ndimage.gaussian_filter(log_luminance, config.fine_scale * face_size, mode="nearest")
    energy = ndimage.gaussian_filter(fine * fine, config.energy_scale * face_size, mode="nearest")
    inside = face > 0.5
    reference = float(np.median(energy[inside])) if inside.any() else float(np.median(energy))
    return np.exp(-energy / (config.strength * max(reference, 1e-12))).astype(np.float32)
