"""Command-line options shared by the commands that fit, declared once (``Annotated`` aliases), and the settings'
help. What they mean and how they are checked and made into a FitConfig is deface/fit/user_options.py (the web
page uses it too); a bad value is a usage error (exit 2) naming the option.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer
from rich.markup import escape

from deface.fit import presets
from deface.fit.config import FitConfig, documentation

# -- the options of every fitting command (fit, eval pairs), declared once ----------------------------
Preset = Annotated[
    str | None, typer.Option(help=f"Preset: one of {', '.join(presets.names())} (`deface presets` shows them).")
]
ConfigFile = Annotated[
    Path | None,
    typer.Option("--config", help="Start from a finished run's configuration: its params.json (or its folder) "
                                  "replays the run exactly; instead of --preset."),
]
Set = Annotated[
    list[str] | None,
    typer.Option("--set", metavar="PATH=VALUE",
                 help="Set any config value, e.g. --set decouple.epsilon=0.12 (repeatable; applied last, in "
                      "order). The settings are listed below."),
]
Models = Annotated[
    Path | None,
    typer.Option("--models", help="Model files folder, the only one searched (default: DEFACE_MODELS, then the "
                                  "cache)."),
]
Model = Annotated[str | None, typer.Option("--model", help="Face model: ict (embedded) or bfm (BFM 2017 + "
                                                           "AlbedoMM). (config: model)")]
Seed = Annotated[int | None, typer.Option(help="Random seed (fits are deterministic for a seed). (config: seed)")]
Lights = Annotated[int | None, typer.Option(help="Ablation: initial number of light conditions n (1-16). "
                                                 "(config: lights.num_lights)")]
Bands = Annotated[int | None, typer.Option(help="Ablation: SH bands B per light (1-16). (config: lights.bands)")]
LightMasks = Annotated[bool | None, typer.Option("--light-masks/--no-light-masks",
                                                 help="Ablation: the light-mask field f. [config: "
                                                      "decouple.light_masks]")]
FaceRegion = Annotated[bool | None, typer.Option("--face-region/--no-face-region",
                                                 help="Ablation: the face-region field g. [config: "
                                                      "decouple.face_region]")]
Priors = Annotated[str | None, typer.Option(help="Ablation: priors to use, comma list of gp,lp,hp or none. "
                                                 "(config: priors.global_prior, local_prior, human_prior)")]
Resolution = Annotated[int | None, typer.Option(help="Cap on the working image's longest side (32-2048 px; the "
                                                     "image is the crop around the face at the photo's own "
                                                     "scale, never upsampled; default 512; a clip: also "
                                                     "clip_resolution, 256). (config: resolution)")]
TextureSize = Annotated[int | None, typer.Option("--texture-size", help="UV texture side (16-4096 texels; default: "
                                                                     "what the face's pixels support, 512-1024). "
                                                                     "(config: texture_size)")]
Iterations = Annotated[str | None, typer.Option(help="Iterations per stage as S1,S2,S3 (e.g. 300,400,200). "
                                                     "(config: iterations.stage1, stage2, stage3)")]
MaxFrames = Annotated[int | None, typer.Option(help="Video: number of frames used (evenly spread). "
                                                    "(config: max_frames)")]
FrameStride = Annotated[int | None, typer.Option(help="Video: take every k-th frame first. [config: "
                                                      "frame_stride]")]
FaceIndex = Annotated[int | None, typer.Option(help="Which face when several (0 = largest). [config: "
                                                    "face_index]")]
Threads = Annotated[int | None, typer.Option(help="Torch threads (default 1; a seed and a thread count give "
                                                  "bit-identical results on one machine). (config: threads)")]

Card = Annotated[str | None, typer.Option(
    "--card", metavar="X0,Y0,X1,Y1",
    help="A grey card (or white paper, --card-reflectance) in the photo: its box, left,top,right,bottom, as "
         "fractions of the image or as pixels. Its reading sets the light's level, corrected for facing the camera "
         "(hold it beside the face: docs/skin-tone.md). (config: tone.illuminant.reference_box)")]
CardReflectance = Annotated[float | None, typer.Option(
    "--card-reflectance", help="The card's reflectance: 0.18 for a grey card (default), about 0.9 for white paper. "
                               "(config: tone.illuminant.reference_reflectance)")]
CardFacing = Annotated[str | None, typer.Option(
    "--card-facing", help="How the card or colour checker was held: camera (default; corrected with the lights "
                          "the face shows) or light (turned towards the key light). (config: "
                          "tone.illuminant.reference_facing)")]
White = Annotated[str | None, typer.Option(
    "--white", metavar="R,G,B|RUN",
    help="The light's white level W, for photos taken under one setup: three numbers, or a finished fit (its folder "
         "or params.json) whose W to reuse, e.g. the fit of one photo with a card. (config: tone.illuminant.white)")]
Checker = Annotated[str | None, typer.Option(
    "--checker", help="Find a ColorChecker in the photo and read the light's level from its grey patches: auto "
                      "(default; when colour-checker-detection is installed), on (an error without one), off. "
                      "(config: tone.illuminant.checker)")]

def settings_help() -> str:
    """Every setting as ``path = default: docstring`` (for ``--help``; rich markup escaped)."""
    lines = ["Settings (--set PATH=VALUE; the defaults are the default preset's, the other presets change some: "
             "`deface presets`):"]
    lines += [f"  {path} = {show_value(default)}: {doc}" for path, default, doc in documentation(FitConfig)]
    return escape("\n".join(lines))


def show_value(value: Any) -> str:
    """A value as ``--set`` takes it."""
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, tuple):
        return ",".join(show_value(v) for v in value)
    return "none" if value is None else str(value)
