"""Fitting configuration: one dataclass per component, every field documented.

Named presets live in :mod:`deface.fit.presets`; the resolved config is written to ``params.json``.
Weights are named after the paper's Alg. 1 (w0..w7) and Table 6.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields, is_dataclass, replace
from typing import Any, Literal

from deface.priors.illuminant import IlluminantConfig
from deface.texture.completion import CompletionConfig
from deface.texture.pyramid import PyramidConfig


@dataclass(frozen=True)
class LightConfig:
    num_lights: int = 5
    """n: light conditions at the start (ACE may drop some). 1 = a single global light (NextFace)."""
    bands: int = 9
    """B: SH bands per light (B*B coefficients per colour)."""
    init: Literal["paper", "code"] = "paper"
    """Initial coefficients: paper gamma_i = 2(i/n) - 1 (i = 1..n); code gamma_i = -L + 2L(i+1)/n (i = 0..n-1).
    Either value is written into every coefficient of light i."""
    init_scale: float = 1.0
    """L of the code's formula (1.5 in most of the authors' configs); the paper's formula is L = 1."""


@dataclass(frozen=True)
class DecoupleConfig:
    light_masks: bool = True
    """Use the light-mask field f (off: every kept light covers the whole face, i.e. one light when n = 1)."""
    face_region: bool = True
    """Use the face-region field g (off: M_o is the classifier h itself if `restrict_to_face`, else M_R)."""
    restrict_to_face: bool = True
    """Without g, restrict the photometric loss to the face-region classifier h (NextFace*); else to M_R."""
    epsilon: float = 0.17
    """ACE threshold on a light mask's area fraction."""
    ace_iteration: int = 100
    """iter_0: the stage-2 iteration at which ACE selects the kept lights."""
    area_normaliser: Literal["render_mask", "image"] = "render_mask"
    """ACE area over the render mask (authors' code) or over all pixels (paper's formula)."""
    loss_form: Literal["code", "paper"] = "code"
    """Formulas of L_area / L_bin / L_seg / L_pho as in the authors' code or as printed in the paper."""
    hidden: tuple[int, ...] = (16, 64, 64)
    """Hidden widths of f (the authors' 3->16->64->64->n)."""
    fourier_frequencies: int = 0
    """Octaves of sin/cos(2^k pi p) features on f's input (0 = the authors' raw (x, y, t)); more let the
    masks follow sharper, thinner shadows."""
    face_region_source: Literal["auto", "skin", "bisenet", "none"] = "auto"
    """Classifier h distilled into g: BiSeNet with the user's checkpoint when present ("auto"), else the
    project's skin-colour model ("skin"); "none" uses the render mask."""


@dataclass(frozen=True)
class Weights:
    photometric: float = 2e3  # w0
    landmarks: float = 1e-3  # w1
    segmentation: float = 1.5e2  # w2
    area: float = 0.5  # w3
    binary: float = 25.0  # w4
    global_prior: float = 2e3  # w5
    local_prior: float = 2.0  # w6
    human_prior: float = 1.0  # w7
    sh_regulariser: float = 1e-4
    """mean(SH^2) in stage 2 (authors' code)."""
    albedo_prior: float = 1.0
    """mean(delta^2) of the albedo-model coefficients in stage 2."""
    identity_prior: float = 1e-3
    expression_prior: float = 1e-3
    texture_regulariser: float = 0.2
    """Scale of the stage-3 NextFace texture regularisers (deface/losses/texture.py; 0.2 in the authors' code)."""


@dataclass(frozen=True)
class Iterations:
    stage1: int = 300
    """Landmark fit (the paper's iter_1 = 2000 counts an unvectorised GPU loop; 300 Adam steps converge here)."""
    stage2: int = 400
    """Statistical fit with light decoupling (iter_2)."""
    stage3: int = 200
    """Per-texel refinement (iter_3)."""


@dataclass(frozen=True)
class LearningRates:
    lights: float = 0.007
    light_masks: float = 0.007
    face_region: float = 0.007
    identity: float = 0.01
    albedo: float = 0.007
    expression: float = 0.01
    pose: float = 1e-4
    stage3_diffuse: float = 0.005
    stage3_specular: float = 0.005
    stage3_roughness: float = 0.01
    stage3_light_masks: float = 0.001
    stage3_lights: float = 0.001


@dataclass(frozen=True)
class PriorConfig:
    global_prior: bool = True
    """GP: K-means palette of T^0's diffuse (4 x 4 = 16 colours)."""
    local_prior: bool = True
    """LP: 5 x 5 local variations against T^0."""
    human_prior: bool = True
    """HP: FaceNet (VGGFace2) identity confidence; runs only when the user has the weights."""
    palette_size: int = 16


@dataclass(frozen=True)
class ToneConfig:
    """Keeping the person's skin tone (docs/skin-tone.md): a free tone axis and lights held to the scene."""

    free_tone: bool = False
    """Stage 2 optimises the skin tone (ITA) along the albedo model's tone axis, flat prior over the human
    range (deface/models/skin_tone.py); off: the model's mean skin, as the paper's AlbedoMM fit."""
    scene_light_prior: bool = False
    """Hold the lights' colour and the brightest light's white level to the scene's illuminant estimate
    (deface/priors/illuminant.py, deface/losses/illuminant.py) in stages 2 and 3."""
    weight: float = 1.0
    """Weight of the scene-light terms (each a squared log-ratio over its sigma^2)."""
    colour_sigma: float = 0.05
    """Allowed log-ratio spread of a light's chromaticity around the estimate's."""
    exposure_sigma: float = 0.1
    """Allowed log-ratio spread of the brightest light's white level around the estimate's."""
    learning_rate: float = 0.3
    """Adam step of the tone (degrees of ITA)."""
    ita_range: tuple[float, float] = (-50.0, 72.0)
    """Where the tone's flat prior is (degrees of ITA): human skin, from the darkest skins measured (about -50;
    Del Bino et al. 2006's dark group is below -30) to the lightest (about 70; their very light group is above
    55). A fit that would leave it is explaining exposure, not skin."""
    illuminant: IlluminantConfig = field(default_factory=IlluminantConfig)
    """How the scene's illuminant is estimated."""


@dataclass(frozen=True)
class FitConfig:
    """Everything one fit uses. Build from a preset: ``presets.get("default")``."""

    preset: str = "custom"
    """Name of the preset this config came from (recorded in params.json)."""
    model: str = "ict"
    """Face model: "ict" (embedded default) or "bfm" (BFM 2017 + AlbedoMM, user-supplied)."""
    resolution: int = 256
    """Longest side of the working image in pixels (the paper evaluates at 256)."""
    texture_size: int = 512
    """UV texture resolution of the outputs."""
    lights: LightConfig = field(default_factory=LightConfig)
    decouple: DecoupleConfig = field(default_factory=DecoupleConfig)
    weights: Weights = field(default_factory=Weights)
    iterations: Iterations = field(default_factory=Iterations)
    learning_rates: LearningRates = field(default_factory=LearningRates)
    priors: PriorConfig = field(default_factory=PriorConfig)
    tone: ToneConfig = field(default_factory=ToneConfig)
    texture_pyramid: PyramidConfig = field(default_factory=PyramidConfig)
    """How stage 3 parametrises the UV maps (deface/texture/pyramid.py): levels gated by the photos' pixels per
    texel, so no texel is freer than the photos make it."""
    completion: CompletionConfig = field(default_factory=CompletionConfig)
    """Filling the texels no frame showed, after stage 3 (deface/texture/completion.py)."""
    supersampling: int = 2
    """Stage 3 renders s x s samples per pixel and box-filters them (deface/render/supersample.py): the
    render becomes the pixel's area integral, so texel refinement cannot hide a checkerboard between
    pixel centres (the paper's path tracer averaged several samples per pixel too). 1 = one sample."""
    render_blur: bool = False
    """L_pho compares a 3x3-Gaussian-blurred render with the photo, as the authors' code does (it smoothed
    their path tracer's noise). Off: our render has no noise, and the blur leaves a pixel-scale checkerboard
    almost invisible to the loss, which stage 3 then bakes into the texture (BENCHMARKS.md)."""
    shadows: bool = True
    """Ray-traced self-shadowing in the renderer."""
    shadow_rays: int = 128
    """Rays per vertex for the shadow transfer."""
    shadow_refresh_every: int = 50
    """Stage 2 refreshes the shadow transfer at most this often (geometry moves slowly)."""
    seed: int = 0
    threads: int = 1
    """Torch CPU threads for the fit. 1 makes fits bit-exact for a seed (multi-threaded reductions change
    the summation order); more threads trade that for speed. Batches parallelise better across processes."""
    max_frames: int = 8
    """Video: frames used (evenly spread over the clip, after `frame_stride`)."""
    frame_stride: int = 1
    """Video: take every k-th frame before choosing `max_frames`."""
    face_index: int = 0
    """Which face when several are found (0 = largest)."""


def to_dict(config: Any) -> dict:
    """A JSON-ready dict of a (nested) config."""
    return asdict(config)


def override(config: Any, **changes: Any) -> Any:
    """A copy with dotted-path changes: ``override(cfg, **{"lights.num_lights": 3})``."""
    for path, value in changes.items():
        config = _set_path(config, path.split("."), value)
    return config


def _set_path(config: Any, parts: list[str], value: Any) -> Any:
    if not is_dataclass(config):
        raise ValueError(f"cannot set '{'.'.join(parts)}' on a non-config value")
    names = {f.name for f in fields(config)}
    if parts[0] not in names:
        raise ValueError(f"unknown config field '{parts[0]}' (known: {', '.join(sorted(names))})")
    if len(parts) == 1:
        return replace(config, **{parts[0]: value})
    return replace(config, **{parts[0]: _set_path(getattr(config, parts[0]), parts[1:], value)})
