"""Named presets: each a documented FitConfig. The CLI's ``--preset`` picks one; switches override it.

- ``paper``: Table 6 of the paper (w0..w7 = 2e3, 1e-3, 1.5e2, 0.5, 25, 2e3, 2.0, 1.0; iter_0 = 100,
  stage-2/3 iterations 400/200; eps = 0.17; n = 5; gamma_i = 2(i/n) - 1).
- ``code-images`` / ``code-video`` / ``code-portrait``: the authors' code configs (VoxCeleb2 images,
  VoxCeleb2 videos, portrait-shadow set): L = 1.5 / 1.5 / 1.0 with gamma_i = -L + 2L(i+1)/n, their eps,
  w1, w2, w4, SH learning rate and stage-2 length (``../shared/docs/method-facts.md``).
- ``nextface``: the single-illumination baseline: one light, no f, no g, no GP/LP/HP; the photometric
  loss covers the whole render mask.
- ``nextface-star``: ``nextface`` restricted to the face region h (NextFace* of the paper).
- ``fast``: ``deface`` with fewer iterations, a 192-px working image and 256-px textures, for previews and
  tests.
- ``deface``: the paper's method with the changes the benchmarks chose (each field's choice and its figures:
  docs/design.md "Default preset", docs/textures.md, docs/skin-tone.md, BENCHMARKS.md):
  M_o = M_R h instead of the distilled field g; ACE's eps 0.09 and n = 3 initial lights; Fourier features on
  f's input; stage-3 maps as pyramids gated by the photos' pixels per texel, completed where unseen, stopped by
  held-out pixels; the person's skin tone (free tone axis, lights held to the scene's illuminant); and what keeps
  the person's dark albedo in the albedo (docs/textures.md "The person's detail"): L_lan in units of the face,
  stage 2 weighing pixels by their shading evidence, an offline h that keeps pigment and the beard zone, and no
  GP, LP or smooth-departure term.
- ``deface-mean-skin``: ``deface`` before it kept the tone (the earlier default exactly, with L_pho's clipped
  channels as values again): the model's mean skin with free lights, so every
  person gets nearly the same pale texture. Its texture transfer between a shadowed and a clean photo of one
  person is higher (both fits give the same skin whatever the person's), so it stays for comparison with
  earlier figures (BENCHMARKS.md), not for use.
- ``default``: the preset ``deface fit`` uses when none is given (see DEFAULT_PRESET).
"""

from __future__ import annotations

from dataclasses import replace

from deface.fit.config import (
    DecoupleConfig,
    FitConfig,
    Iterations,
    LearningRates,
    LightConfig,
    PriorConfig,
    ToneConfig,
    Weights,
    override,
)
from deface.models.albedo_prior import AlbedoPriorConfig
from deface.priors.face_region import SkinClassifierConfig
from deface.priors.shading_evidence import ShadingEvidenceConfig
from deface.texture.completion import CompletionConfig
from deface.texture.pyramid import PyramidConfig

# Chosen by the evaluation benchmark (BENCHMARKS.md records the comparison).
DEFAULT_PRESET = "deface"


def _paper() -> FitConfig:
    return FitConfig(preset="paper")


def _code(name: str, *, num_lights: int, epsilon: float, w1: float, w2: float, w4: float,
          scale: float, sh_lr: float, stage2: int) -> FitConfig:
    return FitConfig(
        preset=name,
        lights=LightConfig(num_lights=num_lights, init="code", init_scale=scale),
        decouple=DecoupleConfig(epsilon=epsilon),
        # The code's w0 = 1000 with a factor 2 inside L_pho: 2e3 in the paper's units.
        weights=Weights(landmarks=w1, segmentation=w2, binary=w4),
        iterations=Iterations(stage2=stage2),
        learning_rates=LearningRates(lights=sh_lr),
    )


def _nextface(name: str, restrict_to_face: bool) -> FitConfig:
    return FitConfig(
        preset=name,
        lights=LightConfig(num_lights=1),
        decouple=DecoupleConfig(light_masks=False, face_region=False, restrict_to_face=restrict_to_face),
        priors=PriorConfig(global_prior=False, local_prior=False, human_prior=False),
    )


# Octaves of Fourier features on f's (x, y, t) in the default preset: sharp shadow edges (blinds, leaves) need
# them; more octaves let the masks follow a beard (docs/design.md "Default preset").
FOURIER_OCTAVES = 4


# Stage 3's early stop in `deface` and `fast`: less than 0.5 % loss decrease per 20 steps (Iterations): the last
# steps of a fixed schedule hardly lowered the loss (benchmarks/history.md "Speed").
STAGE3_TOLERANCE = 0.005

# Stage 2's first half at half size in `deface` and `fast` (deface/fit/coarse.py): as good on the shadow pairs at
# half the cost (benchmarks/history.md "Speed").
STAGE2_COARSE_SHARE = 0.5

# The tone stays at its start in `deface` (ToneConfig.learning_rate; BENCHMARKS.md "Skin tone").
TONE_STEP = 0.0

# Levels of the stage-3 texture pyramid in the default preset (deface/texture/pyramid.py, BENCHMARKS.md).
TEXTURE_LEVELS = 5

# Stage 3's diffuse step and the diffuse map's regularisers scale with T^0's level in `deface`
# (LearningRates.stage3_diffuse_level, Weights.diffuse_level), so a dark skin is refined like a light one: the
# step of 0.005 is the one stage 3 was tuned with on the model's mean skin (green 0.33: Jensen et al. 2001's mean
# Rd, deface/models/albedo_prior.py; docs/textures.md).
DIFFUSE_STEP_LEVEL = AlbedoPriorConfig().skin_rgb[1]

# Stage 3 holds out 10 % of the face's pixels and keeps the step that predicts them best in `deface` and `fast`
# (Iterations.stage3_holdout, deface/fit/holdout.py): later steps fit colour noise (docs/textures.md).
STAGE3_HOLDOUT = 0.1


# Stage 2's L_lan weight in `deface` and `fast`, its distances in units of the face's size (Weights.landmark_units).
# With the paper's 1e-3 (squared working pixels) L_pho pulled the ICT blendshapes to their bounds (mouthClose 1 with
# the jaw shut folds the lips over the nose) and the photo's beard landed on the nose's texels; the weight was
# chosen on renders of known geometry (docs/textures.md "The person's detail").
STAGE2_LANDMARKS = 1e4

# Stage 2 in `deface` weighs pixels down where the photo has hair-like fine texture (deface/priors/shading_evidence.py):
# its albedo model has no room for a beard, so the lights and masks explained it. A lower strength keeps more of a
# beard and lets more of a shadow's edge into the map; 1.5 scored best against the true albedo (docs/textures.md
# "The person's detail").
SHADING_EVIDENCE = 1.5

# The offline face region h in `deface`: the hull of the landmarks grown by 6 % of the face's size (the skin model
# sets the face's edge), and the beard zone counted as face as face parsers count it (deface/priors/face_region.py).
SKIN_CLASSIFIER = SkinClassifierConfig(hull_margin=0.06, beard_zone=True)


def _deface() -> FitConfig:
    return FitConfig(
        preset="deface",
        lights=LightConfig(num_lights=3),
        decouple=DecoupleConfig(face_region=False, epsilon=0.09, fourier_frequencies=FOURIER_OCTAVES,
                                clipped_as_bound=True),
        iterations=Iterations(stage3_tolerance=STAGE3_TOLERANCE, stage2_coarse_share=STAGE2_COARSE_SHARE,
                              stage3_holdout=STAGE3_HOLDOUT),
        texture_pyramid=PyramidConfig(levels=TEXTURE_LEVELS),
        completion=CompletionConfig(enabled=True),
        tone=ToneConfig(free_tone=True, scene_light_prior=True, learning_rate=TONE_STEP),
        learning_rates=LearningRates(stage3_diffuse_level=DIFFUSE_STEP_LEVEL),
        weights=Weights(diffuse_level=DIFFUSE_STEP_LEVEL, landmarks=STAGE2_LANDMARKS, landmark_units="face"),
        priors=PriorConfig(global_prior=False, local_prior=False),
        shading_evidence=ShadingEvidenceConfig(strength=SHADING_EVIDENCE),
        skin_classifier=SKIN_CLASSIFIER,
    )


def _deface_mean_skin() -> FitConfig:
    return override(_deface(), preset="deface-mean-skin", tone=ToneConfig(),
                    **{"decouple.clipped_as_bound": False, "iterations.stage2_coarse_share": 0.0,
                       "iterations.stage3_holdout": 0.0,
                       "learning_rates.stage3_diffuse_level": 0.0, "weights.diffuse_level": 0.0})


def _fast() -> FitConfig:
    return override(_deface(), preset="fast", resolution=192, texture_size=256, **{"render.shadow_rays": 64},
                    iterations=Iterations(stage1=150, stage2=150, stage3=60, stage3_tolerance=STAGE3_TOLERANCE,
                                          stage2_coarse_share=STAGE2_COARSE_SHARE, stage3_holdout=STAGE3_HOLDOUT),
                    **{"decouple.ace_iteration": 50})


PRESETS = {
    "paper": _paper,
    "deface": _deface,
    "deface-mean-skin": _deface_mean_skin,
    "code-images": lambda: _code("code-images", num_lights=5, epsilon=0.15, w1=1.0, w2=120, w4=20,
                                 scale=1.5, sh_lr=0.007, stage2=500),
    "code-video": lambda: _code("code-video", num_lights=5, epsilon=0.15, w1=0.5, w2=150, w4=15,
                                scale=1.5, sh_lr=0.01, stage2=400),
    "code-portrait": lambda: _code("code-portrait", num_lights=7, epsilon=0.09, w1=1.0, w2=120, w4=5,
                                   scale=1.0, sh_lr=0.003, stage2=1500),
    "nextface": lambda: _nextface("nextface", restrict_to_face=False),
    "nextface-star": lambda: _nextface("nextface-star", restrict_to_face=True),
    "fast": _fast,
}


DESCRIPTIONS = {
    "paper": "The paper's Table 6: n = 5 lights, f and g, eps = 0.17, 400/200 stage-2/3 steps.",
    "deface": "The default: the paper's method with M_o = M_R h instead of g, eps = 0.09, n = 3, Fourier f; "
              "gated texture pyramid, completion of unseen texels, the person's detail (stage 2 weighs pixels by "
              "their shading evidence, no GP or LP) and skin tone (free tone axis, lights held to the scene's "
              "illuminant).",
    "deface-mean-skin": "deface with the model's mean skin and free lights (the earlier default; loses the "
                        "person's skin tone): for comparison only.",
    "code-images": "The authors' code config for VoxCeleb2 images (L = 1.5, eps = 0.15).",
    "code-video": "The authors' code config for VoxCeleb2 videos (L = 1.5, eps = 0.15).",
    "code-portrait": "The authors' code config for the portrait-shadow set (n = 7, eps = 0.09, 1500 stage-2 steps).",
    "nextface": "Single-light baseline: one light, no f, no g, no priors; L_pho over the whole render mask.",
    "nextface-star": "NextFace*: nextface with L_pho restricted to the face region h.",
    "fast": "deface with fewer steps, 192-px working image and 256-px textures: previews and tests.",
}
"""One line per preset (``deface presets``); the module docstring says why each differs from the paper."""


def names() -> list[str]:
    return ["default", *PRESETS]


def get(name: str) -> FitConfig:
    """The preset's config; ``default`` resolves to DEFAULT_PRESET (recorded under its real name)."""
    key = DEFAULT_PRESET if name == "default" else name
    if key not in PRESETS:
        raise ValueError(f"unknown preset '{name}' (choose from: {', '.join(names())})")
    return PRESETS[key]()


def with_ablation(config: FitConfig, *, num_lights: int | None = None, light_masks: bool | None = None,
                  face_region: bool | None = None, priors: str | None = None,
                  bands: int | None = None) -> FitConfig:
    """Apply the paper's ablation switches. ``priors``: comma list of gp, lp, hp, or "none"."""
    lights, decouple, prior_cfg = config.lights, config.decouple, config.priors
    if num_lights is not None:
        lights = replace(lights, num_lights=num_lights)
    if bands is not None:
        lights = replace(lights, bands=bands)
    if light_masks is not None:
        decouple = replace(decouple, light_masks=light_masks)
    if face_region is not None:
        decouple = replace(decouple, face_region=face_region)
    if priors is not None:
        chosen = {p.strip().lower() for p in priors.split(",") if p.strip()} - {"none", "na"}
        unknown = chosen - {"gp", "lp", "hp"}
        if unknown:
            raise ValueError(f"unknown prior(s) {sorted(unknown)}: use a comma list of gp, lp, hp, or none")
        prior_cfg = replace(prior_cfg, global_prior="gp" in chosen, local_prior="lp" in chosen,
                            human_prior="hp" in chosen)
    return replace(config, lights=lights, decouple=decouple, priors=prior_cfg)
