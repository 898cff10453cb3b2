"""Starting stage 2 consistent with the scene's illuminant (``tone.scene_light_prior``).

With light masks, a fit that starts from the paper's light values and the model's mean skin can explain a
dark skin as a light skin under a dim light condition that f spreads over the face: the scene-light prior
holds only the brightest light to the scene's white level W, and the tone and the light's level trade freely
against each other in stage 2 (the fitted tone stays within a few degrees of its start). So the fit starts
where the scene says it is:
- the initial lights are scaled per channel so the brightest one's peak white response is W (their ratios,
  signs and SH structure, which ACE and f depend on, are kept);
- the tone starts at the ITA of the skin's colour in the key light over W (:func:`lit_skin_albedo`);
- the skin pixels of the cheeks and forehead are kept (``SceneLight.regions``) for the scene-light prior's
  level term.

The skin's colour in the key light must not depend on what else darkens or lightens the face: a hat brim,
leaves or a hand casting a shadow over the cheeks (the same person must get the same tone with and without
it), a highlight (a larger share of a dark skin's light, so leaving it in lightens dark skins), a clipped
channel (the red of a light skin under a warm light). :func:`lit_skin_albedo` therefore reads it over the
whole face, not only the measured regions:
1. skin: pixels h calls skin whose colour (log red/green and blue/green, over unclipped channels) is within
   ``SKIN_CHROMA`` of the cheeks' and forehead's median (a cast shadow keeps it; hair, beard, a white
   turban, glasses do not);
2. lit: an upper envelope of the green level over the normals, y = a0 + a . n (the Lambertian key light plus
   ambient, linear in n on the lit side), started as the ``ENVELOPE_QUANTILE`` (90 %) quantile regression of the
   level on the normals (a shadow only darkens, so the lit skin is the top of the cloud even when the shadow
   covers most of it, and where it falls on the brightest normals, a brim over the forehead, it cannot tilt the
   envelope), then refitted by least squares to the pixels within ``LIT_BAND`` of it: pixels in a cast or
   attached shadow fall below the band and leave the fit. A quantile envelope that rises away from the camera
   describes no light in front of the face: the top of the cloud is then something else (a grey beard mixed
   with skin along the jaw, a frontal skin clipped in green), and the envelope starts from least squares;
3. no highlights: pixels whose normal is within ``HIGHLIGHT_COS`` of the half vector between the key light
   (a / |a|) and the camera are left out;
4. no sheen: skin is a dielectric whose surface reflects a share of every light in the light's own colour
   (the dichromatic model, Shafer 1985), F0 = 0.028 at normal incidence (skin's refractive index 1.4: Donner
   and Jensen 2006; Weyrich et al. 2006 measured 1.38). Under a broad ambient light this sheen lies over the
   whole face, not only in the highlight: a rough dielectric under a uniform sky mirrors F0 times the sky's
   radiance, so with the ambient's white level A (``SHEEN_AMBIENT``) it adds F0 A to every channel of every
   pixel, about 1 % of a white: 3 % of a light skin's level but 10-15 % of a dark skin's (part of why dark
   skins read lighter on the renders of known albedo: the start's error there 9.7 -> 8.9 degrees without it,
   the fitted tone's 9.9 -> 9.8, BENCHMARKS.md). It is taken off before the level and the colour are
   read (``_without_sheen``). Its growth towards grazing angles (Fresnel) is left alone: it depends on the
   skin's roughness, and the 90th-percentile level comes from surfaces facing the light, not grazing ones;
5. level: the ``KEY_QUANTILE`` (90th percentile) over all the skin's normals of the lit skin's envelope, the same
   quantile the scene-light level term holds the key light's white response to on the face (so start and prior
   agree). It is read from the envelope, not from the lit pixels themselves, so that it does not depend on which
   normals a shadow leaves lit (a brim over the forehead takes the skin facing the key light out of the lit
   pixels, and their own 90th percentile then reads a darker skin: shadow pairs' start ITA gap 4.6 -> 2.8,
   BENCHMARKS.md). Green because a skin's red clips first and its blue is the noisiest; the colour: each
   channel's median ratio to green over the lit pixels where that channel is not clipped.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
import torch
from sklearn.linear_model import QuantileRegressor

from deface.fit.state import SceneLight, first_of_each
from deface.io.images import LUMINANCE, linear_to_srgb, srgb_to_linear
from deface.losses.illuminant import KEY_QUANTILE, front_directions, peak_white
from deface.models.ita import CLIPPED, MIN_PIXELS, grayscale, in_tone_boxes, ita_of_srgb, pixel_uvs
from deface.priors.illuminant import CARD_SOURCES, IlluminantEstimate

SKIN_CHROMA = 0.12
"""Largest difference in log(red / green) and log(blue / green) from the cheeks' skin (about 12 %)."""
LIT_BAND = (0.85, 1.25)
"""A pixel whose level lies within this fraction of the key-light envelope's is lit."""
ENVELOPE_QUANTILE = 0.9
"""Quantile of the level over the normals that starts the key light's envelope (the lit skin's upper part)."""
ENVELOPE_SAMPLE = 4000
"""Most pixels the quantile regression reads (0.2 s)."""
HIGHLIGHT_COS = 0.87
"""Normals within about 30 degrees of the half vector carry the specular highlight."""
SKIN_F0 = 0.028
"""Skin's reflectance at normal incidence, ((n - 1) / (n + 1))^2 for a refractive index n = 1.4 (Donner and
Jensen 2006; Weyrich et al. 2006 fitted 1.38 to measured faces)."""
SHEEN_AMBIENT = 0.3
"""The ambient's white level A whose sheen the start takes off, as a share of the white level W (a white facing
the key light): a typical daylight or key-plus-fill portrait. Not read from the face: the envelope's intercept
gives it on a clean face (0.3-0.4 on the renders of known albedo) but takes a soft cast shadow for ambient light
(twice the clean photo's A on a leaf-shadowed one), and the same person then got a darker tone (ITA gap on the
shadow pairs 5.6 -> 6.8, target synthesis -0.4 dB)."""
LEVEL_CHANNEL = 1  # green


@dataclass(frozen=True)
class SkinPixels:
    """The face's pixels h calls skin, over all frames (model frame directions)."""

    srgb: np.ndarray  # [N, 3] in [0, 1]
    normals: np.ndarray  # [N, 3] unit
    to_camera: np.ndarray  # [N, 3] unit, from the surface to the camera
    in_boxes: np.ndarray  # [N] bool: the cheeks and forehead (deface.models.ita.TONE_BOXES)
    frame: np.ndarray | None = None  # [N] int: the frame each pixel is in (None: all in one)

    def of_frames(self, frames: list[int]) -> SkinPixels:
        """The pixels of ``frames`` only."""
        if self.frame is None:
            return self
        chosen = np.isin(self.frame, frames)
        return SkinPixels(*(getattr(self, field.name)[chosen] for field in fields(self)))


def lights_scaled_to_white(lights: torch.Tensor, white: np.ndarray) -> torch.Tensor:
    """``lights`` [n, B*B, 3] scaled per channel so the brightest light's peak white response is ``white``."""
    peak = peak_white(lights, front_directions())  # [n, 3]
    brightest = peak[int((peak @ torch.as_tensor(LUMINANCE, dtype=torch.float32)).argmax())]
    if bool((brightest <= 0).any()):
        return lights
    return lights * (torch.as_tensor(white, dtype=lights.dtype) / brightest)


@torch.no_grad()
def face_skin(face, frames_srgb: list[np.ndarray], classifier) -> tuple[list[np.ndarray], SkinPixels]:
    """What h (``classifier``, T x [H, W]) calls skin on ``face`` (a :class:`~deface.fit.state.PosedFace`),
    from one ray cast per frame: per frame the [H, W] bool pixels of the cheeks and forehead, and the skin
    pixels of the whole face."""
    regions, parts = [], []
    for frame, h in enumerate(classifier):
        geometry, fragments = face.fragments(frame)
        mesh, covered = geometry.mesh, fragments.covered.numpy()
        skin_image = (fragments.mask.numpy() > 0) & (h.numpy() > 0.5)
        boxes_image = in_tone_boxes(pixel_uvs(fragments, mesh))
        regions.append(skin_image & boxes_image)
        skin = skin_image.reshape(-1)[covered]
        corners = mesh.vertices[mesh.triangles[fragments.covered_triangles]]  # [N, 3, 3]
        points = (fragments.covered_barycentrics[..., None] * corners).sum(1)
        normals = torch.nn.functional.normalize(mesh.face_normals()[fragments.covered_triangles], dim=-1)
        to_camera = torch.nn.functional.normalize(geometry.camera.center_in_model() - points, dim=-1)
        srgb = frames_srgb[frame].reshape(-1, 3)[covered]
        parts.append((srgb[skin], normals.numpy()[skin], to_camera.numpy()[skin],
                      boxes_image.reshape(-1)[covered][skin], np.full(int(skin.sum()), frame)))
    return regions, SkinPixels(*(np.concatenate([p[i] for p in parts]) for i in range(5)))


def lit_skin_albedo(pixels: SkinPixels, white: np.ndarray) -> np.ndarray | None:
    """Linear RGB [3]: the skin's colour in the key light over the white level ``white`` ([3], or [N, 3]: each
    pixel's photo's; the module doc); None when too little skin is seen."""
    envelope = key_light_envelope(pixels, white)
    if envelope is None:
        return None
    balanced, usable, lit, coef = envelope
    level = balanced[:, LEVEL_CHANNEL]
    unclipped = pixels.srgb < CLIPPED
    ratios = [_channel_ratio(balanced, level, unclipped[:, c], c, (lit, usable)) for c in range(3)]
    if not np.all(np.isfinite(ratios)):
        return None
    return np.quantile((_design(pixels) @ coef)[usable], KEY_QUANTILE) * np.asarray(ratios)


def key_light_envelope(pixels: SkinPixels, white: np.ndarray):
    """(balanced [N, 3], usable [N], lit [N], coefficients [4]): the skin's pixels over ``white`` ([3] or [N, 3])
    less the sheen, which are skin, which are lit, and the lit skin's envelope a0 + a . n of the green level
    (items 1-4 of the module doc); None when too little skin is seen."""
    balanced = srgb_to_linear(pixels.srgb) / np.asarray(white)
    unclipped = pixels.srgb < CLIPPED  # [N, 3]
    skin = _skin_coloured(balanced, unclipped, pixels.in_boxes)
    usable = skin & unclipped[:, LEVEL_CHANNEL]
    if usable.sum() < MIN_PIXELS:
        return None
    lit = _key_lit(balanced[:, LEVEL_CHANNEL], pixels, usable)
    if lit.sum() < MIN_PIXELS:
        return None
    balanced = _without_sheen(balanced, pixels, lit)
    return balanced, usable, lit, _least_squares(_design(pixels), balanced[:, LEVEL_CHANNEL], lit)


FACING_RATIO_RANGE = (0.8, 3.0)
"""The light a surface facing the key light gets over what one facing the camera gets: 1 with the key at the
camera, 1 / cos(angle) for a hard key light at that angle with no ambient; beyond this range the face's envelope is
not a light (a frontal face whose skin is clipped, a face lit from behind) and no correction is made."""


def facing_camera_ratio(pixels: SkinPixels, white: np.ndarray) -> float | None:
    """How much more light the skin facing the key light gets than a surface beside the face facing the camera:
    the lit skin's envelope a0 + a . n (the key light and the ambient as the face shows them, whatever the skin's
    tone: the envelope's shape is a ratio) at its ``KEY_QUANTILE`` over the skin's normals, which is where W is
    defined (the start's level, the level term's quantile), over the envelope at the direction to the camera.
    None when the face shows no usable envelope or the ratio leaves ``FACING_RATIO_RANGE``."""
    envelope = key_light_envelope(pixels, white)
    if envelope is None:
        return None
    _, usable, _, coef = envelope
    key = float(np.quantile((_design(pixels) @ coef)[usable], KEY_QUANTILE))
    towards_camera = pixels.to_camera[usable].mean(0)
    facing = float(coef[0] + coef[1:] @ (towards_camera / max(np.linalg.norm(towards_camera), 1e-9)))
    if key <= 0 or facing <= 0:
        return None
    ratio = key / facing
    return ratio if FACING_RATIO_RANGE[0] <= ratio <= FACING_RATIO_RANGE[1] else None


def _channel_ratio(balanced: np.ndarray, level: np.ndarray, unclipped: np.ndarray, channel: int,
                   pools: tuple[np.ndarray, ...]) -> float:
    """Median ratio of ``channel`` to the level over the first pool with enough pixels where it is not clipped:
    the lit skin, else all the skin (an overexposed photo clips a skin's red wherever the key light falls; the
    ratio does not depend on the shading)."""
    for pool in pools:
        chosen = pool & unclipped
        if chosen.sum() >= MIN_PIXELS:
            return float(np.median(balanced[chosen, channel] / level[chosen]))
    return float("nan")


def _skin_coloured(balanced: np.ndarray, unclipped: np.ndarray, in_boxes: np.ndarray) -> np.ndarray:
    """[N] bool: pixels whose colour, as log ratios of red and blue to green over the channels that are not
    clipped, is within SKIN_CHROMA of the cheeks' and forehead's median."""
    ratios = np.log(np.maximum(balanced, 1e-6)) - np.log(np.maximum(balanced[:, LEVEL_CHANNEL:LEVEL_CHANNEL + 1],
                                                                  1e-6))
    reference = unclipped.all(-1) & in_boxes & (balanced.sum(-1) > 1e-3)
    if reference.sum() < MIN_PIXELS:
        reference = unclipped.all(-1)
    if not reference.any():
        return np.zeros(len(balanced), dtype=bool)
    distance = np.where(unclipped, np.abs(ratios - np.median(ratios[reference], axis=0)), 0.0)
    return unclipped[:, LEVEL_CHANNEL] & (distance.max(-1) < SKIN_CHROMA)


def _without_sheen(balanced: np.ndarray, pixels: SkinPixels, lit: np.ndarray) -> np.ndarray:
    """``balanced`` [N, 3] less the skin's surface reflection of the ambient light, F0 A in every channel (module
    doc, item 4), A = ``SHEEN_AMBIENT``; none where the key light's envelope a0 + a . n over the ``lit`` pixels
    shows no ambient light (a0 <= 0: a hard light in a dark room) or no key light."""
    coef = _least_squares(_design(pixels), balanced[:, LEVEL_CHANNEL], lit)
    if coef[0] <= 0 or np.linalg.norm(coef[1:]) <= 0:
        return balanced
    return np.maximum(balanced - SKIN_F0 * SHEEN_AMBIENT, 1e-6)


def _key_lit(level: np.ndarray, pixels: SkinPixels, usable: np.ndarray, refits: int = 5) -> np.ndarray:
    """[N] bool: usable pixels on the key light's upper envelope over the normals, highlights left out."""
    design = _design(pixels)
    candidates = usable & (level >= 0.5 * np.quantile(level[usable], KEY_QUANTILE))
    if candidates.sum() < 4:
        return candidates
    coef = _upper_envelope(design[candidates], level[candidates])
    if coef[1:] @ pixels.to_camera[candidates].mean(0) <= 0:
        # brighter away from the camera: no light in front of the face; the top of the cloud is something else
        coef = _least_squares(design, level, candidates)
    for _ in range(refits + 1):
        ratio = level / np.maximum(design @ coef, 1e-6)
        lit = candidates & (ratio > LIT_BAND[0]) & (ratio < LIT_BAND[1]) & ~_highlight(coef[1:], pixels)
        if lit.sum() < 4:
            return lit
        coef = _least_squares(design, level, lit)
    return lit


def _design(pixels: SkinPixels) -> np.ndarray:
    """[N, 4]: 1 and the normal, the envelope a0 + a . n's regressors."""
    return np.concatenate([np.ones((len(pixels.normals), 1)), pixels.normals], 1)


def _least_squares(design: np.ndarray, level: np.ndarray, chosen: np.ndarray) -> np.ndarray:
    """[4]: the envelope fitted to the ``chosen`` pixels."""
    return np.linalg.lstsq(design[chosen], level[chosen], rcond=None)[0]


def _upper_envelope(design: np.ndarray, level: np.ndarray) -> np.ndarray:
    """[4]: the ``ENVELOPE_QUANTILE`` quantile regression of ``level`` on ``design`` (exact, by linear programming)
    over at most ``ENVELOPE_SAMPLE`` evenly spaced pixels: the linear program's time grows faster than its size
    (80k pixels of a clip: minutes), and four parameters need far fewer."""
    chosen = np.unique(np.linspace(0, len(level) - 1, min(len(level), ENVELOPE_SAMPLE)).astype(int))
    regression = QuantileRegressor(quantile=ENVELOPE_QUANTILE, alpha=0.0, fit_intercept=False, solver="highs-ipm")
    return regression.fit(design[chosen], level[chosen]).coef_


def _highlight(direction: np.ndarray, pixels: SkinPixels) -> np.ndarray:
    """[N] bool: pixels whose normal is within HIGHLIGHT_COS of the half vector of light ``direction``."""
    light = direction / max(np.linalg.norm(direction), 1e-9)
    half = light + pixels.to_camera
    half /= np.maximum(np.linalg.norm(half, axis=-1, keepdims=True), 1e-9)
    return (pixels.normals * half).sum(-1) >= HIGHLIGHT_COS


def start_from_scene(face, target, classifier, illuminants: tuple[IlluminantEstimate, ...], config,
                     log) -> SceneLight:
    """Scale ``face.scene``'s initial lights to the scene's white level (each photo's lights to its own,
    ``illuminants``: one per frame) and start the tone at the photo's (in place); returns the scene light the
    scene-light terms hold the fit to (a card's reading corrected for how it faces: :func:`facing_illuminant`)."""
    regions, pixels = face_skin(face, target.frames_srgb, classifier)
    illuminants = facing_illuminants(illuminants, pixels, config.tone.illuminant, log)
    groups = target.lights_of_frames(config.lights.per_photo)
    scene = face.scene
    with torch.no_grad():
        for group, lights in enumerate(torch.chunk(scene.lights, len(set(groups)))):
            lights.copy_(lights_scaled_to_white(lights, illuminants[groups.index(group)].white))
    kept = tuple(torch.as_tensor(r) for r in regions) if sum(int(r.sum()) for r in regions) >= MIN_PIXELS else None
    read = (config.tone.free_tone or config.tone.skin_chroma) and not grayscale(pixels.srgb)
    whites = np.stack([estimate.white for estimate in illuminants])[pixels.frame]  # [N, 3]: each pixel's photo's
    skin = lit_skin_albedo(pixels, whites) if read else None
    if config.tone.free_tone:
        _start_tone(face, pixels, skin, config, log)
    return SceneLight(illuminants, kept, skin)


def facing_illuminants(illuminants: tuple[IlluminantEstimate, ...], pixels: SkinPixels, settings,
                       log) -> tuple[IlluminantEstimate, ...]:
    """Each distinct estimate of ``illuminants`` (one per frame) corrected by :func:`facing_illuminant` on its
    frames' skin."""
    corrected = list(illuminants)
    for first in first_of_each(illuminants):
        estimate = illuminants[first]
        frames = [t for t, other in enumerate(illuminants) if other is estimate]
        fixed = facing_illuminant(estimate, pixels.of_frames(frames), settings, log)
        for frame in frames:
            corrected[frame] = fixed
    return tuple(corrected)


def facing_illuminant(illuminant: IlluminantEstimate, pixels: SkinPixels, settings, log) -> IlluminantEstimate:
    """A card's or checker's reading (``settings.reference_facing`` "camera"), or the scene's (white patch, grey
    world; ``settings.scene_facing``), corrected for facing the camera (:func:`facing_camera_ratio`), said in the
    log; any other estimate as it is."""
    card = illuminant.source in CARD_SOURCES
    if (card and settings.reference_facing != "camera") or (not card and (
            not settings.scene_facing or illuminant.scene_reading is None)):
        return illuminant
    ratio = facing_camera_ratio(pixels, illuminant.white)
    if ratio is None:
        log.info(f"the {illuminant.source}'s reading is used as it is: the face shows no key light to correct it for "
                 "facing the camera")
        return illuminant
    corrected = illuminant.facing_corrected(ratio)
    log.info(f"white level from {corrected.detail}: {np.round(corrected.white, 3).tolist()}")
    return corrected


def _start_tone(face, pixels: SkinPixels, albedo: np.ndarray | None, config, log) -> None:
    """Set ``face.scene.tone`` from the skin in the key light ``albedo`` (:func:`lit_skin_albedo`), or say in the
    log why it keeps the model's."""
    keeps = f"the tone stays at the model's mean skin (ITA {float(face.scene.tone.detach()):.1f})"
    if grayscale(pixels.srgb):
        log.info(f"a grayscale photo does not show skin tone: {keeps}")
        return
    if albedo is None:
        log.info(f"too little lit skin to read the skin tone from: {keeps}")
        return
    ita = ita_of_srgb(linear_to_srgb(np.clip(albedo, 0.0, 1.0))[None])
    with torch.no_grad():
        face.scene.tone.fill_(ita)
    face.model.albedo.tone.clamp_(face.scene.tone, config.tone.ita_range)
    log.info(f"skin tone starts at ITA {float(face.scene.tone.detach()):.1f} (the skin in the key light under "
             "the scene's white level)")
