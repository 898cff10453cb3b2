"""Fitting configuration: one dataclass per component, every field documented.

The defaults are the shipped method (the default preset, ``deface``), each field's docstring saying why its value
was chosen; the other named presets (:mod:`deface.fit.presets`) are differences from them. The resolved config is
written to ``params.json``; reading and parsing values is :mod:`deface.fit.config_values`. Weights are named after
the paper's Alg. 1 (w0..w7) and Table 6.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

from deface.fit.config_values import (
    build,
    check_value,
    differences,
    documentation,
    field_type,
    flatten,
    parse_value,
    replace_path,
    split_assignment,
    to_dict,
)
from deface.landmarks.identity import SamePersonConfig
from deface.models.albedo_prior import AlbedoPriorConfig
from deface.models.registry import TONE_AXIS
from deface.priors.face_region import SkinClassifierConfig
from deface.priors.illuminant import IlluminantConfig
from deface.priors.occluders import HandConfig
from deface.priors.shading_evidence import ShadingEvidenceConfig
from deface.render.renderer import RenderConfig
from deface.texture.chroma import ChromaConfig
from deface.texture.completion import CompletionConfig
from deface.texture.pigment_gamut import PigmentGamutConfig
from deface.texture.pyramid import PyramidConfig
from deface.texture.registration import RegistrationConfig
from deface.texture.shade_level import ShadeLevelConfig

__all__ = [  # the value handling lives in config_values; callers import it from here with the schema
    "PAPER", "RENAMED", "CropConfig", "DecoupleConfig", "FitConfig", "Iterations", "LearningRates", "LightConfig",
    "PriorConfig", "RenderConfig", "Stage1Config", "ToneConfig", "Weights", "check_value", "differences",
    "documentation", "field_type", "flatten", "from_dict", "override", "parse_value", "set_from_text",
    "supports_free_tone", "to_dict",
]

MEAN_SKIN_GREEN = AlbedoPriorConfig().skin_rgb[1]
"""Linear green of the albedo model's mean skin (Jensen et al. 2001's mean Rd, deface/models/albedo_prior.py): the
diffuse level stage 3's step and regularisers were tuned at, the level ``learning_rates.stage3_diffuse_level`` and
``weights.diffuse_level`` refer to."""


@dataclass(frozen=True)
class LightConfig:
    """The light conditions: how many, how many SH bands, how they start."""

    num_lights: int = 3
    """n: light conditions at the start (ACE may drop some): a lit, a shadowed and a spare one (docs/design.md
    "Default preset"; the paper's 5 in ``paper``). 1 = a single global light (NextFace)."""
    bands: int = 9
    """B: SH bands per light (B*B coefficients per colour)."""
    init: Literal["paper", "code"] = "paper"
    """Initial coefficients: paper gamma_i = 2(i/n) - 1 (i = 1..n); code gamma_i = -L + 2L(i+1)/n (i = 0..n-1).
    Either value is written into every coefficient of light i."""
    init_scale: float = 1.0
    """L of the code's formula (1.5 in most of the authors' configs); the paper's formula is L = 1."""
    per_photo: bool = True
    """Several photos of one person (``deface fit --person``): each photo gets its own n lights, its masks choose
    among them only (its light is its own: the sun in one, a lamp in another). Off: the photos share n lights, as a
    clip's frames always do (the paper's video mode)."""


@dataclass(frozen=True)
class DecoupleConfig:
    """Light decoupling: the fields f (light masks) and g (face region), ACE and the losses' forms."""

    light_masks: bool = True
    """Use the light-mask field f (off: every kept light covers the whole face, i.e. one light when n = 1)."""
    face_region: bool = False
    """Use the face-region field g (off: M_o is the classifier h itself if `restrict_to_face`, else M_R). Off: g,
    trained to match h, also lowers L_pho by shrinking wherever the render fits badly, which left parts of the
    face unfitted (docs/design.md "Default preset"; the paper's g in ``paper``)."""
    restrict_to_face: bool = True
    """Without g, restrict the photometric loss to the face-region classifier h (NextFace*); else to M_R."""
    epsilon: float = 0.09
    """ACE threshold on a light mask's area fraction: the authors' portrait-shadow value. With the paper's 0.17 a
    shadow covering less of the face than that lost its light at ACE and was baked into the texture
    (docs/design.md "Default preset")."""
    ace_iteration: int = 100
    """iter_0: the stage-2 iteration at which ACE selects the kept lights."""
    area_normaliser: Literal["render_mask", "image"] = "render_mask"
    """ACE area over the render mask (authors' code) or over all pixels (paper's formula)."""
    loss_form: Literal["code", "paper"] = "code"
    """Formulas of L_area / L_bin / L_seg / L_pho as in the authors' code or as printed in the paper."""
    clipped_as_bound: bool = True
    """L_pho takes a clipped channel of the photo (sRGB >= 0.98) as a lower bound, not a value: a render above
    it costs nothing (deface/losses/photometric.py); a clipped channel says only that the skin is at least that
    bright, part of keeping the person's skin tone (docs/skin-tone.md). Off: the paper's loss."""
    render_blur: bool = False
    """L_pho compares a 3x3-Gaussian-blurred render with the photo, as the authors' code does (it smoothed
    their path tracer's noise). Off: our render has no noise, and the blur leaves a pixel-scale checkerboard
    almost invisible to the loss, which stage 3 then bakes into the texture (docs/decisions.md)."""
    hidden: tuple[int, ...] = (16, 64, 64)
    """Hidden widths of f (the authors' 3->16->64->64->n)."""
    fourier_frequencies: int = 4
    """Octaves of sin/cos(2^k pi p) features on f's input; more let the masks follow sharper, thinner shadows.
    On raw coordinates (0, the authors' (x, y, t)) f draws only smooth, blob-like masks, and the edges of blinds,
    fingers and leaves were baked into the texture; more octaves let the masks follow a beard (docs/design.md
    "Default preset")."""
    uniform_start: bool = False
    """f starts with every mask equal (its last layer zero), so the split of the face comes from the photo and not
    the seed. Off (the authors' code): PyTorch's random init draws random blobs, and where the photo says nothing
    of the shading (a beard, the mouth) the split stays where the seed drew it (nextface-s1's beard kept 0.60, 0.13
    or 0.38 with seeds 0, 1, 2; uniform 0.28-0.34). Off by default: from a uniform start f gave the whole face to
    one light on a held-out render, and its slanted brim went into the map (7 dB; docs/textures.md "f starts
    uniform")."""
    mask_fill: float = 0.0
    """Gaussian (share of the working image's longer side) over which a light mask, at a pixel with little
    shading evidence (``shading_evidence``: a beard, a mole, a shadow's edge band), is taken from the pixels
    around that have it (deface/decouple/fill.py), in stages 2 and 3; 0 = the masks f draws there. Off: it keeps
    more of a beard but blurs a dappled or finger-shaped shadow's masks (docs/textures.md "Where the beard
    goes")."""
    mask_fill_near: float = 0.0
    """Gaussian (share of the working image's longer side) within which evidence keeps a pixel's own mask: only
    pixels far from any evidence are filled (a beard's inside, not a shadow's edge band); 0 = every pixel in
    proportion to its lack of evidence."""
    face_region_source: Literal["auto", "skin", "bisenet", "none"] = "auto"
    """Classifier h distilled into g: BiSeNet with the user's checkpoint when present ("auto"), else the
    project's skin-colour model ("skin"); "none" uses the render mask."""


@dataclass(frozen=True)
class Weights:
    """Loss weights of stages 2 and 3 (the paper's w0..w7, Table 6)."""

    photometric: float = 2e3
    """w0: L_pho, the masked photometric loss."""
    landmarks: float = 1e4
    """w1: L_lan in stage 2 (mean squared distance in ``landmark_units``). With the paper's 1e-3 in squared
    working pixels, L_pho pulled the expression blendshapes to their bounds and the photo's beard landed on the
    nose's texels; this weight, in units of the face, was chosen on renders of known geometry (docs/textures.md
    "The person's detail")."""
    landmark_units: Literal["pixels", "face"] = "face"
    """Units of L_lan's distances in stage 2: working pixels (the authors' code: the balance with L_pho, a mean
    over pixels, then depends on the face's size in pixels), or the detected face's size (its landmarks' box
    diagonal), which keeps the balance whatever the working size and the face's share of the image."""
    segmentation: float = 1.5e2
    """w2: L_seg (g against the face-region classifier h)."""
    area: float = 0.5
    """w3: L_area of the light masks."""
    binary: float = 25.0
    """w4: L_bin (light masks pushed to 0 or 1)."""
    mask_variation: float = 0.0
    """Stage 2: L_var, the light masks' total variation over the face's size (deface/losses/decouple.py): an
    outline costs its length, so where the photo says nothing of the shading (a beard, stage 2's evidence near 0)
    a mask takes the light of the skin around rather than drawing the pigment's outline. 0 = off (the paper)."""
    global_prior: float = 2e3
    """w5: GP, the K-means palette prior (stage 3)."""
    local_prior: float = 2.0
    """w6: LP, local variations against T^0 (stage 3)."""
    human_prior: float = 1.0
    """w7: HP, FaceNet identity confidence (stage 3)."""
    sh_regulariser: float = 1e-4
    """mean(SH^2) in stage 2 (authors' code)."""
    light_colour_spread: float = 0.0
    """Stages 2 and 3: how much a light's colour may change with direction
    (:func:`deface.losses.illuminant.colour_spread`, the variance of its log-chromaticity over the front
    hemisphere). Free RGB SH coefficients let one light be neutral facing the camera and blue or yellow facing
    down; the map then takes the opposite colour where such a normal is (under the brows, along a mask's edge).
    It reads the lights as rendered with ``tone.colour_as_rendered``. 0 = off."""
    negative_radiance: float = 0.0
    """Stages 2 and 3: the kept lights' negative radiance beyond the ringing a sharp light needs
    (:func:`deface.losses.illuminant.negative_radiance_loss`). The renderer clamps what the fit makes negative, so
    without it a light can be mostly negative and render a colour that the colour terms, which read the raw SH,
    never see (the demo photo's green beard). 0 = off: at 100 held-out renders lost 1.4 dB, a warm key with a cool
    fill 4-5 (docs/textures.md "Lights without negative radiance")."""
    albedo_prior: float = 1.0
    """mean(delta^2) of the albedo-model coefficients in stage 2."""
    identity_prior: float = 1e-3
    """mean(alpha^2) of the identity coefficients in stage 2."""
    expression_prior: float = 1e-3
    """The expression prior in stage 2 (mean(beta) of blendshape weights, mean(beta^2) of PCA ones)."""
    texture_regulariser: float = 0.2
    """Scale of the stage-3 NextFace texture regularisers (deface/losses/texture.py; 0.2 in the authors' code)."""
    smooth_departure: float = 0.0
    """Stage 3: cost of the diffuse map's smooth departure from T^0 beyond one gain per channel
    (deface/losses/texture.py, SmoothDeparture); 0 = off, as in the paper."""
    smooth_departure_cells: int = 32
    """Cells per side over which smooth_departure compares the maps (256² maps: 8-texel blocks)."""
    diffuse_level: float = MEAN_SKIN_GREEN
    """Stage 3: the diffuse map's level (median linear green of T^0 over the face) at which the diffuse map's
    regularisers, GP and LP have their weights; they are then measured relative to T^0's own level (each weight
    times this level over T^0's, to the power of the map in its term): the model's mean skin, on which stage 3
    was tuned (docs/textures.md). 0 = absolute, as the paper's code.
    The photo pays the same for the same relative change of albedo whatever the skin's level (a darker albedo
    is lit by brighter lights), while an absolute L1 or L2 term costs a skin half as light a half or a quarter
    as much: dark skins' maps were regularised several times less than light ones' (deface/fit/stage3.py
    :func:`relative_scale`; ``learning_rates.stage3_diffuse_level`` does the same for the step)."""


@dataclass(frozen=True)
class Iterations:
    """Adam steps of each stage."""

    stage1: int = 300
    """Landmark fit (the paper's iter_1 = 2000 counts an unvectorised GPU loop; 300 Adam steps converge here)."""
    stage2: int = 400
    """Statistical fit with light decoupling (iter_2)."""
    stage3: int = 200
    """Per-texel refinement (iter_3)."""
    stage2_coarse_share: float = 0.5
    """Share of stage 2's steps run first at half the working size (deface/fit/coarse.py: a quarter of the
    per-pixel work; pose, shape, albedo coefficients, lights and f, g are not tied to the pixel grid); the rest
    refine at the working size: half, as good on the shadow pairs at half the cost (benchmarks/history.md
    "Speed"). 0 = every step at the working size; a share, so `--iterations` keeps it."""
    stage2_frames_per_step: int = 4
    """Stage 2 renders at most this many photos per step, a turn of them (deface/fit/frame_turns.py: each round
    of steps shows every photo once, in a new order), when each photo has its own lights (several photos of a
    person, ``lights.per_photo``), so a step costs no more than this many photos. 4: fits of up to four photos are
    unchanged; eight photos of one person in two thirds of the time, as close to the truth as with every photo at
    every step (BENCHMARKS.md `#person-turns`). Frames that share their lights (a clip) are all rendered at every step:
    shared lights stepped on a turn chase its frames (an 8-frame clip lost 0.7 dB on one of two Blender sets).
    0 = every frame at every step (the paper)."""
    coarse_min_side: int = 128
    """No half-size steps when the half size would be under this many pixels on its longer side."""
    stage2_tolerance: float = 0.0
    """Stage 2 stops before `stage2` steps once converged (deface/fit/convergence.py): when its mean loss over
    the last `convergence_window` steps fell by less than this fraction of the mean over the window before
    (tested from ACE + 2 windows on). 0 = always run `stage2` steps."""
    stage3_tolerance: float = 0.005
    """The same early stop for stage 3 (tested from 2 windows on): the last steps of a fixed schedule hardly
    lowered the loss (benchmarks/history.md "Speed"). 0 = always run `stage3` steps."""
    stage3_holdout: float = 0.1
    """Share of the face's pixels stage 3 holds out of the photometric term: it keeps the maps, lights and f of
    the step that predicted them best and stops once `convergence_window` steps have not improved on it
    (deface/fit/holdout.py: later steps fit colour noise, not the person; docs/textures.md). 0 = fit every pixel
    (the paper)."""
    convergence_window: int = 20
    """Steps per window of the early stops (window means smooth Adam's step-to-step noise)."""
    shadow_refresh_every: int = 50
    """Stage 2 refreshes the shadow transfer at most every this many steps (geometry moves slowly)."""


@dataclass(frozen=True)
class LearningRates:
    """Adam steps of stages 2 and 3 (stage 1 has its own in ``stage1``)."""

    lights: float = 0.007
    """Stage 2: the SH light coefficients."""
    light_masks: float = 0.002
    """Stage 2: the light-mask field f. The authors' 0.007 is for their f on raw (x, y, t); with the Fourier
    features (``decouple.fourier_frequencies``) f has nine times the inputs and Adam moves every weight by about
    its step, so at 0.007 f was the fastest way to change the whole render's level: in the first dozen steps it
    gave every pixel to one light, its softmax saturated, and ACE kept that light alone, baking blinds and a
    slanted brim into the map. At 0.002 the lights move first (docs/textures.md "One light for the whole
    face")."""
    face_region: float = 0.007
    """Stage 2: the face-region field g."""
    identity: float = 0.01
    """Stage 2: identity coefficients."""
    albedo: float = 0.007
    """Stage 2: albedo-model coefficients."""
    expression: float = 0.01
    """Stage 2: expression coefficients."""
    pose: float = 1e-4
    """Stage 2: rotation and translation."""
    stage3_diffuse: float = 0.005
    """Stage 3: the diffuse UV map (at the level ``stage3_diffuse_level`` when that is set)."""
    stage3_diffuse_level: float = MEAN_SKIN_GREEN
    """The diffuse map's level (median linear green of T^0 over the face) at which ``stage3_diffuse`` is the
    step; the step is then scaled by T^0's own level over this one: the model's mean skin, on which the step
    was tuned. 0 = one step for every map (the paper's).
    Adam moves each parameter by about its step whatever the gradient's size, so a fixed step is a fixed
    change of albedo per texel: twice as large a share of a skin half as light, and dark skins' textures
    carried several times the texel noise of light ones (docs/textures.md). Scaled, every tone gets the same
    relative refinement (deface/fit/stage3.py :func:`diffuse_step`)."""
    stage3_specular: float = 0.005
    """Stage 3: the specular UV map."""
    stage3_roughness: float = 0.01
    """Stage 3: the roughness UV map."""
    stage3_light_masks: float = 0.001
    """Stage 3: the light-mask field f."""
    stage3_lights: float = 0.001
    """Stage 3: the SH light coefficients."""


@dataclass(frozen=True)
class PriorConfig:
    """The stage-3 texture priors GP, LP and HP."""

    global_prior: bool = False
    """GP: K-means palette of T^0's diffuse (4 x 4 = 16 colours). Off (on in ``paper``): GP and LP held a
    beard and moles at the statistical skin (docs/textures.md "The person's detail")."""
    local_prior: bool = False
    """LP: 5 x 5 local variations against T^0 (off, as GP)."""
    human_prior: bool = True
    """HP: FaceNet (VGGFace2) identity confidence; runs only when the user has the weights."""
    palette_size: int = 16
    """GP: K-means clusters (palette colours)."""
    palette_samples: int = 8000
    """GP: texels of T^0 clustered (drawn with the fit's seed): the palette of a smooth T^0 is stable well
    below sklearn's defaults."""
    palette_restarts: int = 3
    """GP: K-means restarts (sklearn's n_init)."""
    local_prior_weights: tuple[float, float, float] = (5.0, 6.0, 1.0)
    """LP: weights of its diffuse, specular and roughness terms (the authors' 5 / 6 / 1)."""


@dataclass(frozen=True)
class ToneConfig:
    """Keeping the person's skin tone (docs/skin-tone.md): a free tone axis and lights held to the scene."""

    free_tone: bool = True
    """Stage 2 optimises the skin tone (ITA) along the albedo model's tone axis, flat prior over the human
    range (deface/models/skin_tone.py): the person's own tone, where the model's mean skin with free lights
    gave everybody nearly the same pale texture (docs/skin-tone.md). Off: the model's mean skin, as the paper's
    AlbedoMM fit (``paper``, ``deface-mean-skin``)."""
    scene_light_prior: bool = True
    """Hold the lights' colour and the brightest light's white level to the scene's illuminant estimate
    (deface/priors/illuminant.py, deface/losses/illuminant.py) in stages 2 and 3: with a free tone, what keeps
    the tone from trading against the lights' level (docs/skin-tone.md)."""
    weight: float = 1.0
    """Weight of the scene-light terms (each a squared log-ratio over its sigma^2)."""
    colour_sigma: float = 0.05
    """Allowed log-ratio spread of a light's chromaticity around the estimate's."""
    exposure_sigma: float = 0.1
    """Allowed log-ratio spread of the brightest light's white level around the estimate's."""
    level_as_rendered: bool = False
    """Read the level term's lights as the renderer renders them (negative radiance clamped,
    ``render.non_negative_lights``) rather than their raw SH. The raw SH is what the default holds, and the fits
    evade it: they hold the raw light near W and render one 1.6-2 times as bright through negative lobes, so the
    level is in effect free and the tone is the start's. Holding the rendered light keeps more of a beard on the
    renders of known albedo and costs the shadow pairs 0.7 dB (docs/skin-tone.md "The prior")."""
    colour_as_rendered: bool = False
    """Read the colour term's lights as the renderer renders them (negative radiance clamped,
    ``render.non_negative_lights``) rather than their raw SH. The raw SH's colour can be the estimate's at each
    light's peak while the clamped light the face is rendered with is another (a clean portrait's lights: neutral
    raw, red over green 1.4-2.1 as rendered); the map then takes the opposite tint (a paler skin, teal brows).
    The colour spread (``weights.light_colour_spread``) reads the same lights."""
    skin_chroma: bool = False
    """After stage 3, give the maps' skin the chroma of the skin in the key light over the scene's white level
    (the tone's start reading, deface/fit/scene_light.py), and the lights the inverse per channel, so every render
    is unchanged (deface/fit/texels.py :func:`skin_chroma_matched`). Light colour and skin colour trade freely in
    L_pho; the colour term that should settle it reads each light's raw SH at its peak, which the renderer's
    clamp evades (the clean portraits' lights render the skin 1.4-2.1 times redder than a neutral light, and
    the maps come out pale, their brows teal). Luminance and every fine chroma difference are kept."""
    learning_rate: float = 0.0
    """Adam step of the tone in stage 2 (degrees of ITA); 0: the tone stays where it starts, the skin in the key
    light under the scene's white level (deface/fit/scene_light.py). 0, as the tone trades freely against the
    key light's level: on the renders of known albedo stage 2 moved good starts far (a brim's shadow taken for
    darker skin, a warm light's clipped red for lighter; BENCHMARKS.md "Skin tone")."""
    neutral_albedo: bool = True
    """With a free tone, the albedo coefficients are projected after each stage-2 step so that they leave the
    skin's ITA over the cheeks and forehead where the tone axis puts it (deface/models/tone_neutral.py): the tone
    axis alone carries the tone, the other components what is not tone. Off: their constant melanin and
    brightness terms trade the tone against the key light's level (several degrees from the start)."""
    ita_range: tuple[float, float] = (-50.0, 72.0)
    """Where the tone's flat prior is (degrees of ITA): human skin, from the darkest skins measured (about -50;
    Del Bino et al. 2006's dark group is below -30) to the lightest (about 70; their very light group is above
    55). A fit that would leave it is explaining exposure, not skin."""
    white_per_photo: bool = True
    """Several photos of one person (``--person``, each with its own lights, ``lights.per_photo``): each photo's
    lights are held to its own white level, read off its own crop, or its own colour checker (photos from other
    cameras, exposures, white balances or places). Off: one white level read off all the photos together, the
    first photo's checker fixing every photo's (one camera under one light). The user's W (``--white``) is every
    photo's either way; a card's box (``--card``) is refused with several photos (one box does not place the card in
    the others' crops). A clip's frames share one white level (they share their lights)."""
    illuminant: IlluminantConfig = field(default_factory=IlluminantConfig)
    """How the scene's illuminant is estimated."""


@dataclass(frozen=True)
class Stage1Config:
    """Stage 1, the landmark fit (deface/fit/stage1.py); its length is ``iterations.stage1``."""

    rigid_iterations: int | None = None
    """First steps with identity and expression frozen (pose and focal only); None: a quarter of the steps,
    at most 80 (``rigid_steps``)."""
    lr_rotation: float = 0.01
    """Adam step for the axis-angle rotation (radians)."""
    lr_translation: float = 0.005
    """Adam step for the translation, as a fraction of the initial camera distance."""
    lr_focal: float = 0.01
    """Adam step for log(focal)."""
    lr_identity: float = 0.05
    """Adam step for identity coefficients (N(0, 1) units)."""
    lr_expression: float = 0.02
    """Adam step for expression coefficients (blendshape weights in [0, 1])."""
    identity_weight: float = 1e-3
    """w_id of mean(alpha²) relative to L_lan (which is in units of the normalising size)."""
    expression_weight: float = 1e-3
    """w_ex of mean(beta) (blendshapes) or mean(beta²) (PCA expressions)."""
    initial_fov_degrees: float = 20.0
    """Field of view over the longest side of the whole photo (not of the crop around the face the fit works on)
    that sets the initial focal length."""
    optimise_focal: bool = True
    """Fit the focal length (shared by all frames); off: keep the initial one."""
    normalise_by: Literal["face", "image"] = "face"
    """Size dividing pixel distances in L_lan: the detected landmarks' bounding-box diagonal ("face";
    the weights then also do not depend on how much of the photo the face fills) or max(W, H) ("image")."""

    def rigid_steps(self, iterations: int) -> int:
        """The rigid steps of a stage 1 of ``iterations`` steps."""
        if self.rigid_iterations is None:
            return min(80, max(1, iterations // 4))
        return self.rigid_iterations


@dataclass(frozen=True)
class CropConfig:
    """The crop around the face that the fit works on (deface/fit/framing.py); everything written refers back
    to the whole photo."""

    enabled: bool = True
    """Crop each frame to a square around the face's landmarks (a clip: one crop around every frame's face);
    off: the whole frame, as before issue 39."""
    margin: float = 2.0
    """Side of the crop over the larger side of the landmarks' box (chin to forehead top, temple to temple):
    2 keeps the hair above the forehead, the neck below the chin and about half a face of background beside
    each cheek (the framing of CelebAMask-HQ and FFHQ's faces). The crop is cut to the frame."""

    def __post_init__(self) -> None:
        if not self.margin >= 1.0:
            raise ValueError(f"crop.margin must be at least 1 (the crop holds the whole face), got {self.margin}")


@dataclass(frozen=True)
class FitConfig:
    """Everything one fit uses; its defaults are the default preset's values, ``preset`` aside. Build from a
    preset: ``presets.get("default")``."""

    preset: str = "custom"
    """Name of the preset this config came from (recorded in params.json; "custom": none)."""
    model: str = "ict"
    """Face model: "ict" (embedded default) or "bfm" (BFM 2017 + AlbedoMM, user-supplied)."""
    resolution: int = 512
    """Cap on the longest side of the working image, the crop around the face (``crop``), in pixels: the fit
    works at the photo's own scale up to this, never upsampled. 512 puts a face of up to about 256 pixels
    across in the working image (the paper's 256² crops hold faces of about 150); stage 2 runs at
    ``stage2_resolution`` or less, stage 3 at this size."""
    clip_resolution: int = 256
    """The same cap for a clip of several frames (with ``resolution`` if that is smaller): every frame's pixels
    cost the fit again, and the frames together constrain the shared maps. 8 frames of 480² at 480 instead of 256
    took stage 3 ~3.5x the time and memory (BENCHMARKS.md)."""
    crop: CropConfig = field(default_factory=CropConfig)
    """The crop around the face."""
    stage2_resolution: int = 256
    """Stage 2 fits at the working size halved until its longer side is at most this (deface/fit/coarse.py;
    pose, shape, albedo coefficients, lights and f, g are not tied to the pixel grid); stage 3 refines the maps
    at the full working size. 0 = stage 2 at the working size. Its ``iterations.stage2_coarse_share`` halves
    once more."""
    texture_size: int | None = None
    """Side of the UV maps of the outputs and of stage 3; None: what the face's pixels support, about one
    working pixel per texel where the face is seen (deface/fit/framing.py), a power of two within
    ``texture_size_range``."""
    texture_size_range: tuple[int, int] = (512, 1024)
    """Smallest and largest side of the UV maps when ``texture_size`` is None. 512 (the earlier fixed default)
    is the smallest: a smaller face's maps hold no more detail at 512 (stage 3's pyramid gates the levels finer
    than its pixels) but viewers and the benchmarks keep their size."""
    stage2_texture_size: int = 128
    """UV resolution of the albedo model's maps T^0 in stage 2 (the albedo model's native resolution: stage
    2's textures are smooth by design)."""
    stage1: Stage1Config = field(default_factory=Stage1Config)
    """Stage 1, the landmark fit."""
    lights: LightConfig = field(default_factory=LightConfig)
    """The light conditions."""
    decouple: DecoupleConfig = field(default_factory=DecoupleConfig)
    """Light decoupling (f, g, ACE)."""
    weights: Weights = field(default_factory=Weights)
    """Loss weights."""
    iterations: Iterations = field(default_factory=Iterations)
    """Steps per stage."""
    learning_rates: LearningRates = field(default_factory=LearningRates)
    """Adam steps of stages 2 and 3."""
    priors: PriorConfig = field(default_factory=PriorConfig)
    """Texture priors of stage 3."""
    tone: ToneConfig = field(default_factory=ToneConfig)
    """Skin tone and the scene's light."""
    texture_pyramid: PyramidConfig = field(default_factory=PyramidConfig)
    """How stage 3 parametrises the UV maps (deface/texture/pyramid.py): levels gated by the photos' pixels per
    texel, so no texel is freer than the photos make it."""
    completion: CompletionConfig = field(default_factory=CompletionConfig)
    """Filling the texels no frame showed, after stage 3 (deface/texture/completion.py)."""
    same_person: SamePersonConfig = field(default_factory=SamePersonConfig)
    """Several photos of one person: a photo of another person left out (deface/landmarks/identity.py)."""
    registration: RegistrationConfig = field(default_factory=RegistrationConfig)
    """The frames of several photos or a clip brought into register in UV before stage 3
    (deface/texture/registration.py)."""
    shade_level: ShadeLevelConfig = field(default_factory=ShadeLevelConfig)
    """The texels the render lights dimly moved to the lit skin's level and colour around them, after stage 3 and
    before the chroma filter (deface/texture/shade_level.py)."""
    chroma: ChromaConfig = field(default_factory=ChromaConfig)
    """The diffuse map's chroma held to its luminance after stage 3, before completion (deface/texture/chroma.py)."""
    pigment_gamut: PigmentGamutConfig = field(default_factory=PigmentGamutConfig)
    """The diffuse map's hues held to those of skin, hair and lip pigments, after the chroma filter and before
    completion (deface/texture/pigment_gamut.py)."""
    skin_classifier: SkinClassifierConfig = field(default_factory=SkinClassifierConfig)
    """The offline face-region classifier h (deface/priors/face_region.py), used without BiSeNet's weights."""
    hands: HandConfig = field(default_factory=HandConfig)
    """Hands over the face (MediaPipe's hand landmarks) left out of h (deface/priors/occluders.py)."""
    shading_evidence: ShadingEvidenceConfig = field(default_factory=ShadingEvidenceConfig)
    """Which pixels stage 2 fits its lights, masks and geometry to (deface/priors/shading_evidence.py): less
    where the photo has hair-like fine texture."""
    render: RenderConfig = field(default_factory=RenderConfig)
    """How frames are rendered (deface/render/renderer.py :class:`~deface.render.renderer.RenderConfig`)."""
    seed: int = 0
    """Seed of every random choice of the fit (torch, numpy, shadow rays, K-means)."""
    threads: int = 1
    """Torch CPU threads for the fit and for writing its files. A seed and a thread count give bit-identical fits on
    one machine in any engine; another count changes torch's summation order (rounding only).
    Batches parallelise better across processes."""
    max_frames: int = 8
    """Video: frames used (evenly spread over the clip, after `frame_stride`)."""
    frame_stride: int = 1
    """Video: take every k-th frame before choosing `max_frames`."""
    face_index: int = 0
    """Which face when several are found (0 = largest)."""

    def __post_init__(self) -> None:
        low, high = self.texture_size_range
        if not 16 <= low <= high <= 4096:
            raise ValueError(f"texture_size_range must be two sizes with 16 <= smallest <= largest <= 4096, got "
                             f"{self.texture_size_range}")
        if min(self.resolution, self.clip_resolution) < 1 or self.stage2_resolution < 0:
            raise ValueError("resolution and clip_resolution must be positive and stage2_resolution at least 0, got "
                             f"{self.resolution}, {self.clip_resolution} and {self.stage2_resolution}")


RENAMED = {
    "shadows": "render.shadows",
    "shadow_rays": "render.shadow_rays",
    "shadow_refresh_every": "iterations.shadow_refresh_every",
    "render.shadow_refresh_every": "iterations.shadow_refresh_every",
    "supersampling": "render.supersampling",
    "render_blur": "decouple.render_blur",
    "render.render_blur": "decouple.render_blur",
}
"""Settings that moved into a sub-config, old path -> new: ``override`` and ``from_dict`` still take the old
paths (scripts, and the params.json of runs made before the move)."""


def override(config: Any, **changes: Any) -> Any:
    """A copy with dotted-path changes: ``override(cfg, **{"lights.num_lights": 3})`` (old paths of RENAMED
    are accepted)."""
    for path, value in changes.items():
        config = replace_path(config, RENAMED.get(path, path), value)
    return config


def set_from_text(config: Any, assignment: str) -> Any:
    """``config`` with one ``dotted.path=value`` (as ``--set`` takes it) applied, value parsed by the field's
    type; old paths of RENAMED are accepted."""
    path, text = split_assignment(assignment)
    path = RENAMED.get(path, path)
    return override(config, **{path: parse_value(text, field_type(type(config), path), path)})


def from_dict(data: dict, cls: type = None) -> Any:
    """The config (``cls``, default FitConfig) a ``to_dict`` dict describes, e.g. params.json's "config":
    every value is checked against its field's type (lists become tuples); an unknown field is an error.

    Settings the dict leaves out (a params.json written before they existed) take the values fits ran with
    then: for a FitConfig the paper's where the shipped method departs from them (``PAPER``, the
    defaults until issue 41 made the shipped method the defaults), so that an old run replays as it ran;
    for another class its defaults."""
    cls = cls or FitConfig
    if not isinstance(data, dict):
        raise ValueError(f"a config must be a JSON object, got {type(data).__name__}")
    data, moved = _moved_settings(data) if cls is FitConfig else (data, {})
    base = _former_defaults() if cls is FitConfig else cls()
    return override(build(base, data), **moved)


def _moved_settings(data: dict) -> tuple[dict, dict]:
    """``data`` without the old paths of RENAMED (top-level or nested, e.g. ``{"render": {"render_blur": ..}}``),
    and those settings by old path."""
    data = {key: dict(value) if isinstance(value, dict) else value for key, value in data.items()}
    moved = {}
    for old in RENAMED:
        *parent, name = old.split(".")
        holder = data.get(parent[0]) if parent else data
        if isinstance(holder, dict) and name in holder:
            moved[old] = holder.pop(name)
    return data, moved


PAPER = {
    "lights.num_lights": 5,
    "decouple.face_region": True,
    "decouple.epsilon": 0.17,
    "decouple.clipped_as_bound": False,
    "decouple.fourier_frequencies": 0,
    "weights.landmarks": 1e-3,
    "weights.landmark_units": "pixels",
    "weights.diffuse_level": 0.0,
    "iterations.stage2_coarse_share": 0.0,
    "iterations.stage2_frames_per_step": 0,
    "iterations.stage3_tolerance": 0.0,
    "iterations.stage3_holdout": 0.0,
    "learning_rates.stage3_diffuse_level": 0.0,
    "priors.global_prior": True,
    "priors.local_prior": True,
    "tone.free_tone": False,
    "tone.scene_light_prior": False,
    "tone.learning_rate": 0.3,
    "texture_pyramid.levels": 1,
    "completion.enabled": False,
    "chroma.enabled": False,
    "shade_level.enabled": False,
    "pigment_gamut.enabled": False,
    "skin_classifier.occluders.enabled": False,
    "skin_classifier.mouth_opening": False,
    "skin_classifier.eye_opening": False,
    "hands.enabled": False,
    "skin_classifier.beard_zone": False,
    "skin_classifier.hull_margin": 0.0,
    "shading_evidence.strength": 0.0,
    "learning_rates.light_masks": 0.007,
}
"""The paper's method (Table 6 and the authors' code) where the shipped method, FitConfig's defaults, departs
from it (each field's docstring says why). Fits made before the shipped method became FitConfig's defaults ran
with these values, so a params.json that leaves a setting out ran with its value here (``config.from_dict``)."""


def _former_defaults() -> FitConfig:
    """FitConfig's former defaults, before the shipped method became them: the paper's values, no preset ("custom")."""
    return override(FitConfig(), **PAPER)


def supports_free_tone(config: FitConfig) -> FitConfig:
    """``config`` as a fit with its model runs it: ``tone.free_tone`` off for a model without a tone axis
    (``deface.models.registry.TONE_AXIS``)."""
    if not config.tone.free_tone or TONE_AXIS.get(config.model, True):
        return config
    return override(config, **{"tone.free_tone": False})
