"""The scene's illuminant, estimated from the whole image outside the face: the evidence that separates a
person's skin tone from the light's colour and strength (the light/albedo ambiguity; Feng et al., "Towards
Racially Unbiased Skin Tone Estimation via Scene Disambiguation", ECCV 2022: the scene, not the face crop,
shows the illumination).

The estimate is the *white level* W [3]: the linear value a white Lambertian surface facing the key light
shows in the image. A fit whose brightest light shows W keeps the skin's own reflectance in the albedo.

Only pixels away from the face are used (the face's coverage, dilated by ``face_margin`` of its size), so the
estimate does not depend on the skin being measured; clipped (a channel >= ``clipped``) and near-black
pixels are left out. Evidence, in order:
- **White patch** (Land's retinex; max-RGB): near-white pixels (every sRGB channel >= ``white_threshold``)
  show a white surface: their median colour divided by ``white_reflectance`` is W (clipped pixels count as
  1.0 here: the photo's white point). A patch of ``white_fraction`` of the scene or more is trusted with
  ``white_patch_sigma``; a smaller one (a white shirt, a strip of wall) less, and it is used while it is
  surer than the grey world (down to about 0.8 % of the scene).
- **Grey world** otherwise (Buchsbaum 1980): the scene averages to ``scene_reflectance`` (18 %, the
  photographic mid-grey), so W's luminance is the mean luminance over ``scene_reflectance``, never below the
  99th percentile of the scene (no diffuse surface reflects more than white). The colour is the
  shades-of-grey Minkowski p-norm (Finlayson & Trezzi 2004, p = ``minkowski_p``). It reads only the scene's
  usable pixels; when most of the scene is black or clipped (a low-key portrait's backdrop, a blown-out
  window) what it reads is the part least like the rest, so its spread grows as 1 / sqrt(the usable share),
  as a small white patch's does, and W moves smoothly towards the photo's white point as that share shrinks
  to where the estimate falls back to it.
- **The photo's exposure**: a photo is exposed so that white is near its white point (W = 1). Scenes differ
  in mean reflectance by a stop or more (a white studio, a night street), so the scene's level is combined
  with this prior in log space, each weighted by 1 / sigma^2 (``white_patch_sigma``, ``grey_world_sigma``,
  ``exposure_sigma``): a white patch nearly decides, a grey world and the white point weigh the same.
- **Plausible illuminants**: the colour is projected onto the Planckian locus (correlated colour temperature
  via Ohno 2013, colour-science) and pulled towards the photo's own white point (``neutral_cct``, D65's
  6504 K: cameras white-balance) by how far the estimate lies off the locus (``duv_sigma``): a blue sea or a
  red brick wall is not taken for a blue or red light, a warm room light is.
With too few scene pixels (a tight crop) the estimate falls back to the photo's white point: W = 1, neutral.
Clips pool the pixels of all frames.

When the user knows the light, the estimate steps aside (:func:`known_illuminant`): a reference card in the photo
(``reference_box``: its median linear colour over ``reference_reflectance`` is W) or W itself (``white``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Literal

import numpy as np
from scipy import ndimage

from deface.io.images import LUMINANCE, srgb_to_linear


@dataclass(frozen=True)
class IlluminantConfig:
    """Settings of :func:`estimate_illuminant` (sources of the numbers in the module doc)."""

    face_margin: float = 0.25
    """Dilation of the face's coverage, as a fraction of the face's size, before the scene is read."""
    clipped: float = 0.98
    """sRGB value at which a channel counts as clipped."""
    dark: float = 0.02
    """Pixels with linear luminance below this are left out (no colour to read)."""
    white_threshold: float = 0.85
    """sRGB: a pixel whose every channel reaches this is near white. A white wall under a
    strongly coloured light (below ~6000 K its blue channel falls under this) is read by grey world instead."""
    white_fraction: float = 0.1
    """Fraction of the scene near white at which the white patch has ``white_patch_sigma``; a smaller patch's
    sigma grows as 1 / sqrt(its fraction), and the grey world is used instead once it is the surer (about 0.8 %).
    Measured on ../shared/data/skin-tone (start ITA against the photos' lit skin, benchmarks/tone_start.py): a
    hard 10 % threshold read a white top over turquoise water (3.8 % of the scene) by the water's grey world
    instead (W 1.6: 27 degrees too dark); with the sliding sigma MAE 11.6 -> 9.8, dark group 18.4 -> 13.2; no
    render of known albedo has a near-white pixel (unchanged)."""
    white_reflectance: float = 0.9
    """Reflectance of a white surface (paper, paint, a studio backdrop)."""
    scene_reflectance: float = 0.18
    """Mean reflectance of a scene (grey world; the photographic mid-grey)."""
    minkowski_p: float = 6.0
    """Shades-of-grey norm for the scene's colour (1 = grey world, inf = max-RGB)."""
    duv_sigma: float = 0.006
    """Distance from the Planckian locus (CIE 1960 uv) at which the scene's colour keeps exp(-1/2) weight."""
    neutral_cct: float = 6504.0
    """The photo's white point as a colour temperature (sRGB's D65)."""
    cct_range: tuple[float, float] = (2000.0, 12000.0)
    """Colour temperatures an estimate may take."""
    min_scene_fraction: float = 0.05
    """Below this fraction of usable scene pixels, fall back to the photo's white point."""
    exposure_sigma: float = 0.7
    """Spread (natural log) of a photo's white level around its white point W = 1: about a stop, as for the
    grey world (exposure is set by a camera or a person, neither of whom knew the scene's light), so the two
    weigh the same. Measured on the skin-tone sets: 0.5 (the white point counts 2x) made the renders of known
    albedo 12.1 degrees off on average, 0.7 9.5 and 1.0 7.0, while the photos' proxy went 9.7, 11.4, 13.4
    (the proxy itself is W = 1: the photo's lit skin taken as albedo; BENCHMARKS.md)."""
    white_patch_sigma: float = 0.2
    """Spread (natural log) of the white-patch level (white surfaces differ in reflectance and light)."""
    grey_world_sigma: float = 0.7
    """Spread (natural log) of the grey-world level when every scene pixel is usable (scenes' mean reflectance
    differs by about a stop); divided by sqrt(the usable share of the scene) otherwise. Measured on
    ../shared/data/skin-tone (start ITA against the photos' lit skin, benchmarks/tone_start.py): a man before a
    black backdrop, 80 % of it too dark to read, had W 0.50 from the grey world of its few lit pixels and a skin
    23 degrees lighter than his lit skin, 14 with the growing spread (W 0.80); MAE 9.8 -> 9.2; the renders of
    known albedo (every pixel usable) and the shadow pairs' gap (2.86) unchanged."""
    white: tuple[float, float, float] | None = None
    """W itself, when the capture says what it is (linear RGB a white surface facing the key light shows): a
    studio's calibration, or a card read in one photo (``reference_box``; its fit records W as ``illuminant.white``
    in params.json) for every photo taken under the same light. Used instead of the estimate."""
    reference_box: tuple[float, float, float, float] | None = None
    """Left, top, right, bottom of a grey or white card, or any flat matte surface of known reflectance, in the
    photo (``deface fit --card``): as fractions of its width and height when every value is at most 1 (a card at
    pixels 300-420 across and 900-1000 down a 1200 x 1600 photo: 0.25,0.5625,0.35,0.625), else as pixels of the
    input image (300,900,420,1000); in every frame of a clip (a fixed camera). W is its median linear colour over
    ``reference_reflectance``, corrected for how the card faces (``reference_facing``), used instead of the
    estimate."""
    reference_reflectance: float = 0.18
    """Reflectance of the reference surface: 0.18 for a photographic grey card, about 0.9 for white paper
    (``deface fit --card-reflectance``)."""
    reference_sigma: float = 0.15
    """Log spread of a card's or colour checker's level once corrected for how it faces: what is left of where it
    was held (a little below or beside the face, a little nearer or farther from the light) and of the face's
    lights that correct it. On the truth set's tune renders (benchmarks/tone_truth.py, studio and tungsten) the
    corrected card's level lies 0.06-0.2 below the key light's on the face (0.43 where the photo clipped the face),
    RMS 0.15. It sets the tone's interval for a card as ``level_sigma`` does for an estimate."""
    reference_facing: Literal["camera", "light"] = "camera"
    """How the card (or colour checker) was held. "camera": beside the face, facing the camera, as people hold
    one: it then receives the light a surface facing the camera gets, less than the skin facing the key light
    (on renders with the key 40-55 degrees off the camera: 15-30 % less), and W is its reading times the ratio of
    the skin's key-light envelope at the 90th percentile to the envelope at the camera's direction (the lights
    read off the face, deface/fit/scene_light.py; docs/skin-tone.md). "light": turned towards the key light; no
    correction."""
    scene_facing: bool = False
    """The scene's reading (a white patch's or the grey world's level) is of surfaces that mostly face the camera (a
    wall, a backdrop, a shirt), which get less of a key light off the camera's axis than the skin facing it, as a
    card held facing the camera does: correct the reading by the same ratio from the face's lights before it is
    combined with the photo's white point. Off by default: measured (tone starts, docs/skin-tone.md) it lowers the
    lightening where the backdrop is mid-grey (../shared/data/skin-tone-synth MAE 9.7 -> 7.3; the truth set's tune
    part mean signed +15.1 -> +11.9, MAE 27.4 -> 27.9) but darkens further where a pale backdrop already made W too
    bright (its report part MAE 15.9 -> 19.9, mean signed -12.9 -> -18.4; photos unchanged, 9.6): the grey world's
    own premise (18 %) is the larger error, and this correction does not fix it."""
    checker: Literal["auto", "on", "off"] = "auto"
    """Look for an X-Rite ColorChecker (Classic, Passport, Nano or SG) in the photo (deface/priors/checker.py,
    the ``checker`` extra: colour-checker-detection): its grey patches of known reflectance give W, corrected for
    its orientation as a card is. "auto": when the package is installed (the log says when it is not), and only
    a detection whose six grey patches read as a neutral ramp of the known reflectances counts; "on": an error
    when the package is missing or no checker is found; "off": never."""

    def __post_init__(self) -> None:
        if self.white is not None and min(self.white) <= 0:
            raise ValueError(f"tone.illuminant.white must be positive in every channel, got {self.white}")
        if self.reference_box is not None:
            left, top, right, bottom = self.reference_box
            if not (0.0 <= left < right and 0.0 <= top < bottom) or (
                    max(self.reference_box) <= 1.0 and not (right <= 1.0 and bottom <= 1.0)):
                raise ValueError("tone.illuminant.reference_box (--card) is left,top,right,bottom, as fractions of "
                                 "the image (0 <= left < right <= 1, 0 <= top < bottom <= 1) or as pixels, got "
                                 f"{','.join(f'{v:g}' for v in self.reference_box)}")
            if self.white is not None:
                raise ValueError("give the white level (--white, tone.illuminant.white) or a card (--card, "
                                 "tone.illuminant.reference_box), not both")
        if not 0.0 <= self.reference_sigma <= 2.0:
            raise ValueError(f"tone.illuminant.reference_sigma must be in [0, 2], got {self.reference_sigma}")
        if not 0.0 < self.reference_reflectance <= 1.0:
            raise ValueError("tone.illuminant.reference_reflectance must be in (0, 1], "
                             f"got {self.reference_reflectance}")


CARD_SOURCES = ("reference card", "colour checker")
"""Sources whose reading is of a surface in the photo held at the face, corrected for how it faces."""


@dataclass(frozen=True)
class IlluminantEstimate:
    """W and where it came from (written to params.json)."""

    white: np.ndarray  # [3] linear RGB a white surface facing the key light shows
    cct: float  # correlated colour temperature (K) of the light
    source: str  # "white patch", "grey world", "fallback", "given", "reference card" or "colour checker"
    colour_weight: float  # in [0, 1]: how much of the colour came from the scene (the rest: the white point)
    scene_pixels: int  # usable pixels outside the face
    level_sigma: float = 0.0  # natural-log spread of W's level: the estimate's one sigma (0: the user's W)
    orientation: float = 1.0  # a card's reading was multiplied by this for facing the camera (1: not corrected)
    detail: str = ""  # where the level came from, in words (the log and report.html say it)
    scene_reading: tuple[float, float, float] | None = None  # the scene's level, its log sigma and exposure_sigma
    # before the two were combined (white patch, grey world), so a facing correction can combine them again

    def record(self) -> dict:
        return {"white": [round(float(v), 5) for v in self.white], "cct": round(self.cct, 1),
                "source": self.source, "colour_weight": round(self.colour_weight, 4),
                "scene_pixels": self.scene_pixels, "level_sigma": round(self.level_sigma, 4),
                "orientation": round(self.orientation, 4), "detail": self.detail}

    @classmethod
    def from_record(cls, record: dict) -> IlluminantEstimate:
        """The estimate as :meth:`record` wrote it (rounded, without the scene's reading); fields an older record
        lacks take their defaults."""
        return cls(np.asarray(record["white"], dtype=np.float64), float(record["cct"]), record["source"],
                   float(record.get("colour_weight", 0.0)), int(record.get("scene_pixels", 0)),
                   float(record.get("level_sigma", 0.0)), float(record.get("orientation", 1.0)),
                   record.get("detail", ""))

    def facing_corrected(self, ratio: float) -> IlluminantEstimate:
        """A card's reading, or the scene's before it is combined with the photo's white point, times ``ratio``:
        the light a surface facing the key light gets over what one facing the camera gets. Any other estimate
        (given, the fallback) as it is."""
        detail = f"{self.detail}; x{ratio:.2f} for facing the camera rather than the key light"
        if self.source in CARD_SOURCES:
            return replace(self, white=self.white * ratio, orientation=self.orientation * ratio, detail=detail)
        if self.scene_reading is None:
            return self
        level, sigma, exposure_sigma = self.scene_reading
        combined, _ = _with_exposure_prior(level * ratio, sigma, exposure_sigma)
        white = self.white / float(self.white @ LUMINANCE) * combined
        return replace(self, white=white, orientation=self.orientation * ratio, detail=detail)


def estimate_illuminant(frames_srgb: list[np.ndarray], face_masks: list[np.ndarray],
                        config: IlluminantConfig = IlluminantConfig()) -> IlluminantEstimate:
    """Frames [H, W, 3] sRGB in [0, 1] and the face's coverage [H, W] per frame -> the white level W."""
    pixels = np.concatenate([_scene_pixels(f, m, config) for f, m in zip(frames_srgb, face_masks, strict=True)])
    total = sum(m.size for m in face_masks)
    linear = srgb_to_linear(pixels)
    usable = _readable(pixels, linear, config)
    if usable.sum() < config.min_scene_fraction * total:
        return IlluminantEstimate(np.ones(3), config.neutral_cct, "fallback", 0.0, int(usable.sum()),
                                  config.exposure_sigma, detail="the photo's white point (too little scene to read)")
    grey_sigma = grey_world_spread(usable, config)
    patch = _white_patch(pixels, linear, grey_sigma, config)
    if patch is not None:
        colour, level, sigma = patch
        source = "white patch"
    else:
        colour, level = grey_world(linear[usable], config)
        sigma, source = grey_sigma, "grey world"
    cct, weight = plausible_cct(colour, config)
    combined, level_sigma = _with_exposure_prior(level, sigma, config.exposure_sigma)
    detail = (f"the scene's {source} (level {level:.2f}, log sigma {sigma:.2f}) with the photo's white point "
              f"(log sigma {config.exposure_sigma:.2f})")
    return IlluminantEstimate(combined * planckian_rgb(cct, config.neutral_cct), cct, source, weight,
                              int(usable.sum()), level_sigma, detail=detail,
                              scene_reading=(level, sigma, config.exposure_sigma))


def known_illuminant(frames_srgb: list[np.ndarray], config: IlluminantConfig,
                     scale: float = 1.0) -> IlluminantEstimate | None:
    """W as given (``white``) or read off a reference card (``reference_box``) in frames [H, W, 3] sRGB (the
    working frames, ``scale`` times the input's size: a box in pixels is of the input image), or None when
    neither is set. ValueError (one line) when the box shows too little of the card to read. The card's reading
    is not yet corrected for how it faces (:meth:`IlluminantEstimate.facing_corrected`, from the face's lights)."""
    if config.white is not None:
        white = np.asarray(config.white, dtype=np.float64)
        return IlluminantEstimate(white, cct_of(white, config), "given", 1.0, 0, detail="given (tone.illuminant.white)")
    if config.reference_box is None:
        return None
    box = _fractions(config.reference_box, frames_srgb[0].shape, scale)
    shown = ",".join(f"{v:g}" for v in config.reference_box)
    pixels = np.concatenate([_box(frame, box).reshape(-1, 3) for frame in frames_srgb])
    linear = srgb_to_linear(pixels)
    usable = _readable(pixels, linear, config)
    if usable.mean() < 0.5:
        raise ValueError(f"the card's box {shown} (--card, tone.illuminant.reference_box): "
                         f"{100 * (1 - usable.mean()):.0f} % of it is clipped or nearly black; choose a part of the "
                         "card that is neither, or expose the photo so the card is not blown out")
    white = np.median(linear[usable], axis=0).astype(np.float64) / config.reference_reflectance
    detail = f"a card of {100 * config.reference_reflectance:.0f} % reflectance at {shown}"
    return IlluminantEstimate(white, cct_of(white, config), "reference card", 1.0, int(usable.sum()),
                              config.reference_sigma, detail=detail)


def _fractions(box: tuple[float, float, float, float], shape: tuple[int, ...],
               scale: float) -> tuple[float, float, float, float]:
    """``box`` as fractions of the image: as it is when every value is at most 1, else pixels of the input image
    (the working frame of ``shape`` is ``scale`` times its size). ValueError when the pixels lie outside it."""
    if max(box) <= 1.0:
        return box
    width, height = shape[1] / scale, shape[0] / scale
    left, top, right, bottom = box
    if right > width + 0.5 or bottom > height + 0.5:
        raise ValueError(f"the card's box {','.join(f'{v:g}' for v in box)} (--card, pixels) reaches beyond the "
                         f"{round(width)} x {round(height)} image")
    return left / width, top / height, min(right / width, 1.0), min(bottom / height, 1.0)


def _readable(pixels: np.ndarray, linear: np.ndarray, config: IlluminantConfig) -> np.ndarray:
    """[N] bool: sRGB ``pixels`` [N, 3] (``linear`` their linear values) neither clipped nor nearly black."""
    return (pixels.max(-1) < config.clipped) & (linear @ LUMINANCE >= config.dark)


def _box(frame: np.ndarray, box: tuple[float, float, float, float]) -> np.ndarray:
    """The part of ``frame`` [H, W, C] inside ``box`` (left, top, right, bottom as fractions), at least a pixel."""
    height, width = frame.shape[:2]
    x0, y0 = min(int(box[0] * width), width - 1), min(int(box[1] * height), height - 1)
    x1, y1 = max(x0 + 1, int(np.ceil(box[2] * width))), max(y0 + 1, int(np.ceil(box[3] * height)))
    return frame[y0:y1, x0:x1]


def grey_world(linear: np.ndarray, config: IlluminantConfig) -> tuple[np.ndarray, float]:
    """(colour [3], level) of the usable scene pixels ``linear`` [N, 3]: the shades-of-grey colour and the mean
    luminance over ``scene_reflectance``, never below the 99th percentile (module doc)."""
    luminance = linear @ LUMINANCE
    colour = np.power(np.mean(linear**config.minkowski_p, axis=0), 1.0 / config.minkowski_p)
    level = max(float(luminance.mean()) / config.scene_reflectance, float(np.percentile(luminance, 99)))
    return colour, level


def grey_world_spread(usable: np.ndarray, config: IlluminantConfig) -> float:
    """Log spread of the grey world's level read from the ``usable`` [N] bool scene pixels: ``grey_world_sigma``
    over sqrt(their share) (module doc)."""
    return config.grey_world_sigma / float(np.sqrt(usable.mean()))


def _white_patch(pixels: np.ndarray, linear: np.ndarray, grey_sigma: float, config: IlluminantConfig):
    """(colour [3], level, log sigma) of the scene's near-white pixels, or None when the grey world (log sigma
    ``grey_sigma``) is surer.
    A patch of ``white_fraction`` of the scene or more has sigma ``white_patch_sigma``, clipped pixels counting
    as the photo's white point (a blown-out white backdrop). A smaller patch is read from its unclipped pixels
    only (a small clipped spot is as likely a highlight or a lamp, whose level says nothing), and its sigma grows
    as 1 / sqrt(its share): a patch a quarter the size counts a quarter as much, the fewer the pixels the likelier
    they are a pale surface rather than a white one facing the light."""
    white = pixels.min(-1) >= config.white_threshold
    if white.mean() < config.white_fraction:
        white &= pixels.max(-1) < config.clipped
    share = max(float(white.mean()), 1e-9)
    sigma = config.white_patch_sigma * np.sqrt(max(config.white_fraction / share, 1.0))
    if sigma >= grey_sigma:
        return None
    colour = np.median(np.where(pixels[white] >= config.clipped, 1.0, linear[white]), axis=0)
    return colour, float(colour @ LUMINANCE) / config.white_reflectance, float(sigma)


def _with_exposure_prior(level: float, sigma: float, exposure_sigma: float) -> tuple[float, float]:
    """Precision-weighted mean in log space of the scene's level and the photo's white point (log 1 = 0), and its
    log spread (the two spreads combined as independent Gaussians)."""
    precision = sigma**-2 + exposure_sigma**-2
    return float(np.exp(sigma**-2 / precision * np.log(level))), float(precision**-0.5)


def _scene_pixels(frame: np.ndarray, face: np.ndarray, config: IlluminantConfig) -> np.ndarray:
    """[N, 3] sRGB pixels outside the dilated face."""
    face = np.asarray(face, dtype=bool)
    size = np.sqrt(max(face.sum(), 1.0))
    iterations = max(1, int(round(config.face_margin * size)))
    grown = ndimage.binary_dilation(face, iterations=iterations) if face.any() else face
    return frame[~grown].reshape(-1, 3)


def plausible_cct(linear_rgb: np.ndarray, config: IlluminantConfig) -> tuple[float, float]:
    """The colour temperature of a light of colour ``linear_rgb`` [3] and the weight the scene's colour got:
    the scene's CCT where it lies on the Planckian locus, the white point's where it lies far off it."""
    cct, duv = _cct_duv(linear_rgb, config)
    weight = float(np.exp(-0.5 * (duv / config.duv_sigma) ** 2))
    low, high = config.cct_range
    mired = weight * 1e6 / float(np.clip(cct, low, high)) + (1.0 - weight) * 1e6 / config.neutral_cct
    return 1e6 / mired, weight


def cct_of(linear_rgb: np.ndarray, config: IlluminantConfig) -> float:
    """The colour temperature (K, within ``cct_range``) nearest a light of colour ``linear_rgb`` [3]."""
    return float(np.clip(_cct_duv(linear_rgb, config)[0], *config.cct_range))


def _cct_duv(linear_rgb: np.ndarray, config: IlluminantConfig) -> tuple[float, float]:
    """(CCT, Duv) of a light of colour ``linear_rgb`` [3], the photo's neutral standing for ``neutral_cct``."""
    from colour import XYZ_to_xy, xy_to_UCS_uv
    from colour.temperature import uv_to_CCT_Ohno2013

    # The photo's neutral (1, 1, 1) stands for a Planckian light at neutral_cct (planckian_rgb's convention).
    absolute = np.maximum(np.asarray(linear_rgb, dtype=np.float64), 1e-6) * _planck_linear_rgb(config.neutral_cct)
    cct, duv = uv_to_CCT_Ohno2013(xy_to_UCS_uv(XYZ_to_xy(_rgb_to_xyz() @ absolute)))
    return float(cct), float(duv)


def planckian_rgb(cct: float, neutral_cct: float = 6504.0) -> np.ndarray:
    """[3] linear sRGB of a Planckian light at ``cct`` relative to one at ``neutral_cct`` (which is (1, 1, 1)),
    scaled to unit luminance."""
    rgb = _planck_linear_rgb(cct) / _planck_linear_rgb(neutral_cct)
    return rgb / float(rgb @ LUMINANCE)


def _planck_linear_rgb(cct: float) -> np.ndarray:
    from colour import UCS_uv_to_xy, xy_to_XYZ
    from colour.temperature import CCT_to_uv_Ohno2013

    xyz = xy_to_XYZ(UCS_uv_to_xy(CCT_to_uv_Ohno2013(np.array([cct, 0.0]))))
    return np.linalg.solve(_rgb_to_xyz(), xyz)


def _rgb_to_xyz() -> np.ndarray:
    from colour.models import RGB_COLOURSPACE_sRGB

    return np.asarray(RGB_COLOURSPACE_sRGB.matrix_RGB_to_XYZ, dtype=np.float64)
