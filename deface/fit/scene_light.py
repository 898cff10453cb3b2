"""Starting stage 2 consistent with the scene's illuminant (``tone.scene_light_prior``).

With light masks, a fit that starts from the paper's light values and the model's mean skin can explain a
dark skin as a light skin under a dim light condition that f spreads over the face: the scene-light prior
holds only the brightest light to the scene's white level W, and the tone moves a fraction of a degree per
step. So the fit starts where the scene says it is:
- the initial lights are scaled per channel so the brightest one's peak white response is W (their ratios,
  signs and SH structure, which ACE and f depend on, are kept);
- the tone starts at the ITA of the photo's lit skin (unclipped cheek and forehead pixels at least half as
  bright as their 90th percentile, :mod:`deface.models.ita`, without the brightest tenth, where the
  specular highlight is - a larger share of a dark skin's light, so leaving it in would lighten dark skins)
  divided by W and by ``LIT_SKIN_SHADING``. Stage 2 then refines both;
- the skin pixels of the cheeks and forehead are kept (``SceneLight.regions``) for the scene-light prior's
  level term.
"""

from __future__ import annotations

import numpy as np
import torch

from deface.fit.state import SceneLight
from deface.io.images import LUMINANCE, linear_to_srgb, srgb_to_linear
from deface.losses.illuminant import KEY_QUANTILE, front_directions, peak_white
from deface.models.ita import CLIPPED, in_tone_boxes, ita_of_srgb, lit_skin, pixel_uvs

LIT_SKIN_SHADING = 0.85
"""The light on lit cheeks and forehead as a fraction of the key light's level facing it: a typical cosine of
about 30 degrees between those surfaces and a portrait's key light."""


def lights_scaled_to_white(lights: torch.Tensor, white: np.ndarray) -> torch.Tensor:
    """``lights`` [n, B*B, 3] scaled per channel so the brightest light's peak white response is ``white``."""
    peak = peak_white(lights, front_directions())  # [n, 3]
    brightest = peak[int((peak @ torch.as_tensor(LUMINANCE, dtype=torch.float32)).argmax())]
    if bool((brightest <= 0).any()):
        return lights
    return lights * (torch.as_tensor(white, dtype=lights.dtype) / brightest)


@torch.no_grad()
def tone_regions(face, classifier) -> list[np.ndarray]:
    """Per frame [H, W] bool: pixels of ``face`` (a :class:`~deface.fit.state.PosedFace`) showing the cheeks
    and forehead that h (``classifier``, T x [H, W]) calls skin."""
    regions = []
    for frame, h in enumerate(classifier):
        geometry, fragments = face.fragments(frame)
        skin = h.numpy() > 0.5
        region = (fragments.mask.numpy() > 0) & skin & in_tone_boxes(pixel_uvs(fragments, geometry.mesh))
        regions.append(region)
    return regions


def photo_skin_ita(frames_srgb: list[np.ndarray], regions: list[np.ndarray], white: np.ndarray) -> float | None:
    """The ITA of the photo's most lit skin as albedo under white level ``white`` (None: too little skin)."""
    srgb = np.concatenate([frames_srgb[f][r] for f, r in enumerate(regions)])
    srgb = srgb[srgb.max(-1) < CLIPPED]
    if len(srgb) < 12:
        return None
    luminance = srgb_to_linear(srgb) @ LUMINANCE
    lit = lit_skin(srgb) & (luminance <= np.percentile(luminance, 100 * KEY_QUANTILE))
    albedo = np.median(srgb_to_linear(srgb[lit]), axis=0) / (np.asarray(white) * LIT_SKIN_SHADING)
    return ita_of_srgb(linear_to_srgb(np.clip(albedo, 0.0, 1.0))[None])


def start_from_scene(face, frames_srgb: list[np.ndarray], classifier, illuminant, config, log) -> SceneLight:
    """Scale ``face.scene``'s initial lights to the scene's white level and start the tone at the photo's (in
    place); returns the scene light the scene-light terms hold the fit to."""
    white, scene = illuminant.white, face.scene
    with torch.no_grad():
        scene.lights.copy_(lights_scaled_to_white(scene.lights, white))
    regions = tone_regions(face, classifier)
    kept = tuple(torch.as_tensor(r) for r in regions) if sum(int(r.sum()) for r in regions) >= 12 else None
    if config.tone.free_tone:
        ita = photo_skin_ita(frames_srgb, regions, white)
        if ita is not None:
            with torch.no_grad():
                scene.tone.fill_(ita)
            face.model.albedo.tone.clamp_(scene.tone, config.tone.ita_range)
            log.info(f"skin tone starts at ITA {float(scene.tone.detach()):.1f} (the photo's lit "
                     "skin under the scene's light)")
    return SceneLight(illuminant, kept)
