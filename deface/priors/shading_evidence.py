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
    (with ``edges_as_shading``: energy - k G_b * |g - G_3b * g|^2, g = grad (G_b * log Y), at least 0)
    (with ``coherence_power`` p: energy x (1 - c)^p, c the coherence of fine's structure tensor over b)

A cast shadow's sharp edge also leaves fine energy, along a band a few pixels wide, so the masks are fitted less
along it. ``edges_as_shading`` (off) takes off what a step of the smoothed log luminance predicts (k: the ratio
of the two for an ideal step, :func:`step_ratio`; hair's strokes average out at that scale); on the renders of
known albedo it also took off a beard's energy under a key light, whose strokes' shading is a step too.
``coherence_power`` asks instead how the fine residue is organised: a shadow's edge leaves it along one direction
(coherence near 1), hair, stubble and freckles scatter it (near 0), whatever the shading across them.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from deface.io.images import LUMINANCE
from deface.priors.face_region import hair_zone_mask


@dataclass(frozen=True)
class ShadingEvidenceConfig:
    """How stage 2 weighs pixels by their fine texture (``FitConfig.shading_evidence``)."""

    strength: float = 1.5
    """A pixel whose texture energy is this many times the face's median gets weight 1/e in stage 2's L_pho:
    the albedo model has no room for a beard, so the lights and masks explained it. Lower keeps more of a beard
    and lets more of a shadow's edge into the map; this scored best against the true albedo (docs/textures.md
    "The person's detail"). 0 = every pixel counts alike (the paper)."""
    fine_scale: float = 0.008
    """Gaussian whose residue is the fine texture, as a share of the face's size (its landmarks' box diagonal):
    about a pixel at the default working size."""
    energy_scale: float = 0.02
    """Gaussian over which the fine texture's energy is averaged, as a share of the face's size."""
    edges_as_shading: bool = False
    """Take off the energy a step of log luminance (a cast shadow's edge) alone would leave, so shadow edges keep
    their weight. Off: on the renders of known albedo it also took a beard's energy off under a key light (its
    strokes' shading is a step too) and the beard went into the lights (docs/textures.md)."""
    coherence_power: float = 0.0
    """Take off the share of the fine energy that is organised along one direction (a cast shadow's edge, a curve)
    rather than scattered (hair, stubble, freckles): the energy times (1 - coherence)^p, coherence the structure
    tensor's (lambda1 - lambda2) / (lambda1 + lambda2) of the fine residue over ``energy_scale``. 0 = off: on the
    renders of known albedo (randomly oriented stubble strokes) and the shadow pairs it helped (2 with strength 0.75:
    pairs' synthesis +1 dB), but a real beard's hairs grow one way, so their energy went too and the real bearded
    photos lost their beards (docs/textures.md)."""
    floor: float = 1e-3
    """Least linear luminance of the log (dark pixels' noise stays finite)."""
    hair_zone: float = 0.02
    """Weigh pixels only where a face has fine texture of its own: the brows, eyes (lashes), nostrils and lips grown
    by this share of the face's size, and the beard's reach (``beard_reach``); elsewhere (the forehead, the nose's
    bridge, the upper cheeks) fine texture is a shadow's edge, and every pixel counts. The zone's edge is blended
    over half this share. On the board every split gained (the pairs' texture swap +0.07 / +0.54 / +1.05 dB,
    detail-synth's beard kept 0.36 -> 0.41; docs/textures.md "Where the evidence counts"). Negative = everywhere
    on the face, as before (MediaPipe landmarks only)."""
    beard_reach: float = 0.06
    """With ``hair_zone``: the beard zone (below the nose's base, within the face outline) grows by this share of
    the face's size below the alae's line (a beard runs past the outline's points onto the jaw's underside)."""


def texture_weight(image: np.ndarray, face: np.ndarray, face_size: float, config: ShadingEvidenceConfig,
                   landmarks: np.ndarray | None = None) -> np.ndarray:
    """[H, W] in (0, 1]: the weight of each pixel of ``image`` (linear RGB [H, W, 3]) in stage 2's L_pho; ``face``
    [H, W] in [0, 1] (h) says where the face's median energy is taken, ``face_size`` in pixels; ``landmarks``
    [N, 2] pixels place ``hair_zone``."""
    if config.strength <= 0:
        return np.ones(image.shape[:2], np.float32)
    log_luminance = np.log(np.maximum(image @ LUMINANCE, config.floor))
    fine_scale, energy_scale = config.fine_scale * face_size, config.energy_scale * face_size
    fine = log_luminance - ndimage.gaussian_filter(log_luminance, fine_scale, mode="nearest")
    energy = ndimage.gaussian_filter(fine * fine, energy_scale, mode="nearest")
    inside = face > 0.5
    reference = float(np.median(energy[inside])) if inside.any() else float(np.median(energy))
    if config.edges_as_shading:  # after the reference: it is the face's typical texture, steps and all
        energy = np.maximum(energy - step_energy(log_luminance, fine_scale, energy_scale), 0.0)
    if config.coherence_power > 0:
        energy = energy * (1.0 - coherence(fine, energy_scale)) ** config.coherence_power
    weight = np.exp(-energy / (config.strength * max(reference, 1e-12)))
    if config.hair_zone >= 0 and landmarks is not None and landmarks.shape[0] in (468, 478):
        weight = 1.0 - _hair_zone(landmarks, image.shape[:2], face_size, config) * (1.0 - weight)
    return weight.astype(np.float32)


def _hair_zone(landmarks: np.ndarray, shape: tuple[int, int], face_size: float,
               config: ShadingEvidenceConfig) -> np.ndarray:
    """[H, W] in [0, 1]: 1 over the zone (:func:`hair_zone_mask`), falling to 0 within half ``hair_zone`` beyond."""
    margin = config.hair_zone * face_size
    zone = hair_zone_mask(landmarks, shape, round(margin), round(config.beard_reach * face_size))
    if margin < 2:
        return zone.astype(np.float64)
    return np.minimum(2.0 * ndimage.gaussian_filter(zone.astype(np.float64), margin / 4, mode="nearest"), 1.0)


def coherence(fine: np.ndarray, scale: float) -> np.ndarray:
    """[H, W] in [0, 1]: how much of ``fine``'s gradient energy around each pixel (a Gaussian of ``scale``) lies
    along one direction: 1 along a straight edge, about 0 in scattered strokes and dots."""
    gy, gx = np.gradient(fine)
    xx, yy, xy = (ndimage.gaussian_filter(a, scale, mode="nearest") for a in (gx * gx, gy * gy, gx * gy))
    return np.sqrt((xx - yy) ** 2 + 4 * xy * xy) / np.maximum(xx + yy, 1e-12)


def step_energy(log_luminance: np.ndarray, fine_scale: float, energy_scale: float) -> np.ndarray:
    """[H, W]: the fine energy that steps of ``log_luminance`` alone would give, from its gradient at
    ``energy_scale`` (pixels) less the gradient's mean over three times that scale: a step's gradient is local,
    smooth shading's is the same over the wider window (and leaves no fine energy)."""
    smooth = ndimage.gaussian_filter(log_luminance, energy_scale, mode="nearest")
    local = [g - ndimage.gaussian_filter(g, 3 * energy_scale, mode="nearest") for g in np.gradient(smooth)]
    squared = ndimage.gaussian_filter(local[0] ** 2 + local[1] ** 2, energy_scale, mode="nearest")
    return step_ratio(round(fine_scale, 3), round(energy_scale, 3)) * squared


@functools.lru_cache(maxsize=64)
def step_ratio(fine_scale: float, energy_scale: float) -> float:
    """k: the fine energy of an ideal step over its smoothed squared gradient (both as in :func:`texture_weight`)
    at the step."""
    side = int(40 * max(energy_scale, 1.0)) + 64
    step = (np.arange(side) >= side // 2).astype(np.float64)
    fine = step - ndimage.gaussian_filter1d(step, fine_scale, mode="nearest")
    energy = ndimage.gaussian_filter1d(fine * fine, energy_scale, mode="nearest")
    gradient = np.gradient(ndimage.gaussian_filter1d(step, energy_scale, mode="nearest"))
    gradient = gradient - ndimage.gaussian_filter1d(gradient, 3 * energy_scale, mode="nearest")
    squared = ndimage.gaussian_filter1d(gradient * gradient, energy_scale, mode="nearest")
    centre = side // 2
    return float(energy[centre - 1:centre + 1].mean() / squared[centre - 1:centre + 1].mean())
