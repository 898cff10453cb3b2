"""Named presets, each written as its differences from FitConfig's defaults (``PRESETS``: dotted paths, as
``config.override`` takes them). The defaults are the shipped method, ``deface``; each field's docstring says
why its value was chosen. The CLI's ``--preset`` picks one; switches override it; ``deface presets`` prints each
preset's differences from the default.

- ``deface``: the defaults. The paper's method with the changes the benchmarks chose (docs/design.md "Default
  preset", docs/textures.md, docs/skin-tone.md, BENCHMARKS.md): M_o = M_R h instead of the distilled field g;
  ACE's eps 0.09 and n = 3 initial lights; Fourier features on f's input; stage-3 maps as pyramids gated by the
  photos' pixels per texel, completed where unseen, stopped by held-out pixels, the diffuse map's chroma held to
  its luminance (deface/texture/chroma.py); the person's skin tone (free
  tone axis, lights held to the scene's illuminant); and what keeps the person's dark albedo in the albedo
  (docs/textures.md "The person's detail"): L_lan in units of the face, stage 2 weighing pixels by their
  shading evidence, an offline h that keeps pigment and the beard zone, and no GP, LP or smooth-departure term.
- ``paper``: Table 6 of the paper (w0..w7 = 2e3, 1e-3, 1.5e2, 0.5, 25, 2e3, 2.0, 1.0; iter_0 = 100,
  stage-2/3 iterations 400/200; eps = 0.17; n = 5; gamma_i = 2(i/n) - 1): ``PAPER``.
- ``code-images`` / ``code-video`` / ``code-portrait``: the authors' code configs (VoxCeleb2 images,
  VoxCeleb2 videos, portrait-shadow set): the paper's, with L = 1.5 / 1.5 / 1.0 with gamma_i = -L + 2L(i+1)/n,
  their eps, w1, w2, w4, SH learning rate and stage-2 length (``../shared/docs/method-facts.md``).
- ``nextface``: the single-illumination baseline: one light, no f, no g, no GP/LP/HP; the photometric
  loss covers the whole render mask.
- ``nextface-star``: ``nextface`` restricted to the face region h (NextFace* of the paper).
- ``no-cast-shadows``: ``deface`` for photos without cast shadows (a studio, an even or a single key light; no hat brim,
  hair, leaves or hand over the face): stage 2's shading evidence at strength 0.4 instead of 1.5, over the whole
  face rather than the hair zone, so the lights fit fewer of the pixels with fine texture and a beard, stubble,
  freckles and moles stay in the maps. The lights then explain less of the face's own shading (dark eye sockets
  under a key from above, a seam down the nose under a side key), and a cast shadow's edge goes into the map:
  docs/textures.md "Photos without cast shadows".
- ``fast``: ``deface`` with fewer iterations, a 192-px working image and 256-px textures, for previews and
  tests.
- ``deface-mean-skin``: ``deface`` before it kept the tone (the earlier default exactly, with L_pho's clipped
  channels as values again): the model's mean skin with free lights, so every
  person gets nearly the same pale texture. Its texture transfer between a shadowed and a clean photo of one
  person is higher (both fits give the same skin whatever the person's), so it stays for comparison with
  earlier figures (BENCHMARKS.md), not for use.
- ``default``: the preset ``deface fit`` uses when none is given (see DEFAULT_PRESET).
"""

from __future__ import annotations

from dataclasses import replace

from deface.fit.config import PAPER, RENAMED, FitConfig, override
from deface.fit.config_values import check_value, field_type

# Chosen by the evaluation benchmark (BENCHMARKS.md records the comparison).
DEFAULT_PRESET = "deface"


def _code(*, num_lights: int, epsilon: float, w1: float, w2: float, w4: float, scale: float, sh_lr: float,
          stage2: int) -> dict:
    """An authors' code config: the paper's, with their light start, eps, w1, w2, w4, SH step and stage-2 length
    (all given, also where they equal the paper's)."""
    # The code's w0 = 1000 with a factor 2 inside L_pho: 2e3 in the paper's units, the default.
    return {**PAPER, "lights.num_lights": num_lights, "lights.init": "code", "lights.init_scale": scale,
            "decouple.epsilon": epsilon, "weights.landmarks": w1, "weights.segmentation": w2, "weights.binary": w4,
            "iterations.stage2": stage2, "learning_rates.lights": sh_lr}


NEXTFACE = {**PAPER, "lights.num_lights": 1, "decouple.light_masks": False, "decouple.face_region": False,
            "decouple.restrict_to_face": False, "priors.global_prior": False, "priors.local_prior": False,
            "priors.human_prior": False}
"""The single-illumination baseline: the paper's settings with one light, no f, no g, no GP/LP/HP, L_pho over
the whole render mask."""


PRESETS: dict[str, dict] = {
    "paper": PAPER,
    "deface": {},
    # `deface` before it kept the tone (the earlier default): the model's mean skin with free lights, L_pho's clipped
    # channels as values, no half-size stage-2 steps nor turns of frames, no held-out pixels, one diffuse step and
    # absolute diffuse terms, no chroma filter, texels in the dark moved to the lit skin nor pigment hues.
    "deface-mean-skin": {"chroma.enabled": False, "shade_level.enabled": False, "pigment_gamut.enabled": False,
                         "tone.free_tone": False, "tone.scene_light_prior": False, "tone.learning_rate": 0.3,
                         "decouple.clipped_as_bound": False, "iterations.stage2_coarse_share": 0.0,
                         "iterations.stage2_frames_per_step": 0,
                         "iterations.stage3_holdout": 0.0, "learning_rates.stage3_diffuse_level": 0.0,
                         "weights.diffuse_level": 0.0},
    "code-images": _code(num_lights=5, epsilon=0.15, w1=1.0, w2=120, w4=20, scale=1.5, sh_lr=0.007, stage2=500),
    "code-video": _code(num_lights=5, epsilon=0.15, w1=0.5, w2=150, w4=15, scale=1.5, sh_lr=0.01, stage2=400),
    "code-portrait": _code(num_lights=7, epsilon=0.09, w1=1.0, w2=120, w4=5, scale=1.0, sh_lr=0.003, stage2=1500),
    "nextface": NEXTFACE,
    "nextface-star": {**NEXTFACE, "decouple.restrict_to_face": True},
    # Photos without cast shadows: stage 2 leaves fine texture (a beard, stubble, freckles) to the maps sooner,
    # over the whole face (no shadow's edge to fit outside the hair zone).
    "no-cast-shadows": {"shading_evidence.strength": 0.4, "shading_evidence.hair_zone": -1.0},
    "fast": {"resolution": 192, "texture_size": 256, "render.shadow_rays": 64, "iterations.stage1": 150,
             "iterations.stage2": 150, "iterations.stage3": 60, "decouple.ace_iteration": 50},
}
"""Each preset as dotted-path changes (``config.override``) of FitConfig's defaults, which are DEFAULT_PRESET's."""


DESCRIPTIONS = {
    "paper": "The paper's Table 6: n = 5 lights, f and g, eps = 0.17, 400/200 stage-2/3 steps.",
    "deface": "The default: the paper's method with M_o = M_R h instead of g, eps = 0.09, n = 3, Fourier f; "
              "gated texture pyramid, the map's chroma held to its luminance, completion of unseen texels, the "
              "person's detail (stage 2 weighs pixels by their shading evidence, no GP or LP) and skin tone (free "
              "tone axis, lights held to the scene's illuminant).",
    "deface-mean-skin": "deface with the model's mean skin and free lights (the earlier default; loses the "
                        "person's skin tone): for comparison only.",
    "code-images": "The authors' code config for VoxCeleb2 images (L = 1.5, eps = 0.15).",
    "code-video": "The authors' code config for VoxCeleb2 videos (L = 1.5, eps = 0.15).",
    "code-portrait": "The authors' code config for the portrait-shadow set (n = 7, eps = 0.09, 1500 stage-2 steps).",
    "nextface": "Single-light baseline: one light, no f, no g, no priors; L_pho over the whole render mask.",
    "nextface-star": "NextFace*: nextface with L_pho restricted to the face region h.",
    "no-cast-shadows": "deface for photos without cast shadows (hats, hair, leaves, hands): keeps a beard, stubble "
                       "and freckles (stage 2's shading evidence at 0.4, over the whole face), leaves more of the "
                       "face's own shading in the map.",
    "fast": "deface with fewer steps, 192-px working image and 256-px textures: previews and tests.",
}
"""One line per preset (``deface presets``); the module docstring says what each is for."""


def _checked(presets: dict[str, dict]) -> dict[str, dict]:
    """Every preset built once when this module is imported: a misspelt path or a value of the wrong type fails
    here, naming the preset, not when someone picks it."""
    for name, changes in presets.items():
        try:
            for path, value in changes.items():
                check_value(value, field_type(FitConfig, RENAMED.get(path, path)), path)
            override(FitConfig(preset=name), **changes)
        except ValueError as error:
            raise ValueError(f"preset {name!r}: {error}") from error
    return presets


PRESETS = _checked(PRESETS)


def names() -> list[str]:
    return ["default", *PRESETS]


def get(name: str) -> FitConfig:
    """The preset's config: the defaults with its PRESETS changes; ``default`` resolves to DEFAULT_PRESET
    (recorded under its real name)."""
    key = DEFAULT_PRESET if name == "default" else name
    if key not in PRESETS:
        raise ValueError(f"unknown preset '{name}' (choose from: {', '.join(names())})")
    return override(FitConfig(preset=key), **PRESETS[key])


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
