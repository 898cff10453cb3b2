"""Command-line options shared by the commands that fit, declared once (``Annotated`` aliases), and their
checks: every numeric option's documented range, checked before any work starts, so a bad value is a usage
error (exit 2) naming the option, never a failure of each input.

A fitting command's configuration is built by ``fit_config`` in one order: the preset (or ``--config``, a
finished run's params.json), then the shortcut options (``--lights``, ``--iterations``, ...: each is a named
config path, ``SHORTCUTS``), then every ``--set PATH=VALUE`` in the order given. Every setting of FitConfig
is reachable with ``--set``; ``settings_help`` lists them from the config's docstrings.

The ranges bound what a CPU fit can do in reasonable memory and time; README ("When things go wrong")
lists them.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.markup import escape

from deface.fit import presets
from deface.fit.config import FitConfig, documentation, from_dict, override, set_from_text


class UsageError(ValueError):
    """A command-line value is invalid; the message names the option (one line)."""


@dataclass(frozen=True)
class Range:
    """Allowed values of an integer option and what they mean, for the error message."""

    low: int
    high: int
    what: str

    def check(self, option: str, value: int | None) -> None:
        if value is not None and not self.low <= value <= self.high:
            raise UsageError(f"{option} must be {self.what} from {self.low} to {self.high}, got {value}")


# Working image: below 32 px the face has too few pixels for the fields; above 2048 px one fit needs
# several GB and hours. Lights and bands: each light adds a render per step, each band 2B+1 coefficients.
RANGES = {
    "--resolution": Range(32, 2048, "a number of pixels (the working image's longest side at most)"),
    "--texture-size": Range(16, 4096, "a number of texels (side of the UV maps)"),
    "--lights": Range(1, 16, "a number of light conditions"),
    "--bands": Range(1, 16, "a number of SH bands"),
    "--max-frames": Range(1, 256, "a number of frames"),
    "--frame-stride": Range(1, 10_000, "a frame step"),
    "--face-index": Range(0, 63, "a face number (0 = largest)"),
    "--threads": Range(0, 256, "a number of torch threads (0 = torch's default)"),
    "--seed": Range(0, 2**32 - 1, "a seed"),
    "--jobs": Range(0, 256, "a number of worker processes (0 = one per core)"),
}
ITERATIONS = Range(1, 100_000, "a step count")
FACE_MODELS = ("ict", "bfm")


def check_ranges(values: dict[str, int | None]) -> None:
    """Check option values by option name (e.g. ``{"--lights": 3}``); None means not given."""
    for option, value in values.items():
        RANGES[option].check(option, value)


def parse_iterations(text: str) -> tuple[int, int, int]:
    """``S1,S2,S3`` -> three step counts, each within :data:`ITERATIONS`."""
    try:
        values = tuple(int(part) for part in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 3:
        raise UsageError(f"--iterations takes three positive integers S1,S2,S3, got '{text}'")
    for value in values:
        ITERATIONS.check("--iterations (each of S1,S2,S3)", value)
    return values


def check_choice(option: str, value: str, choices: tuple[str, ...]) -> None:
    if value not in choices:
        raise UsageError(f"{option} must be one of {', '.join(choices)}, got '{value}'")


def check_face_model(name: str) -> None:
    if name not in FACE_MODELS:
        raise UsageError(f"--model (config: model) must be one of {', '.join(FACE_MODELS)}, got '{name}'")


def check_models_dir(path: Path | None) -> None:
    """``--models DIR`` must be an existing folder (it is the only place searched)."""
    if path is not None and not path.is_dir():
        raise UsageError(f"--models {path}: no such folder")


def check_output(path: Path) -> None:
    """``-o OUT`` must be a folder or not exist yet (it is created)."""
    if path.exists() and not path.is_dir():
        raise UsageError(f"-o {path}: exists and is not a folder; name a folder (it is created if missing)")


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
Threads = Annotated[int | None, typer.Option(help="Torch threads (default 1: bit-exact results per seed). "
                                                  "(config: threads)")]

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

SHORTCUTS = {
    "--model": "model",
    "--seed": "seed",
    "--resolution": "resolution",
    "--texture-size": "texture_size",
    "--max-frames": "max_frames",
    "--frame-stride": "frame_stride",
    "--face-index": "face_index",
    "--threads": "threads",
    "--lights": "lights.num_lights",
    "--bands": "lights.bands",
    "--light-masks": "decouple.light_masks",
    "--face-region": "decouple.face_region",
    "--card-reflectance": "tone.illuminant.reference_reflectance",
}
TEXT_SHORTCUTS = {
    "--card": "tone.illuminant.reference_box",
    "--card-facing": "tone.illuminant.reference_facing",
    "--checker": "tone.illuminant.checker",
}
"""Options whose text is parsed as the config path's type (as ``--set`` parses it); ``--white`` also takes a run."""
"""Options that set one config path each (``--priors`` and ``--iterations`` set several, see ``fit_config``)."""


def fit_config(preset: str | None = None, config_file: Path | None = None, sets: list[str] | None = None,
               **shortcuts: Any) -> FitConfig:
    """The configuration of a fitting command: the preset (default: "default") or ``config_file``, then the
    shortcut options by option name without dashes (``lights=3``, ``iterations="300,400,200"``, ``priors``;
    None = not given), then ``sets`` (``PATH=VALUE``, in order). Raises UsageError naming the option."""
    given = {f"--{name.replace('_', '-')}": value for name, value in shortcuts.items() if value is not None}
    unknown = set(given) - set(SHORTCUTS) - set(TEXT_SHORTCUTS) - {"--iterations", "--priors", "--white"}
    if unknown:
        raise TypeError(f"fit_config: no shortcut option {', '.join(sorted(unknown))}")
    check_ranges({option: value for option, value in given.items() if option in RANGES})
    if "--model" in given:
        check_face_model(given["--model"])
    if config_file is not None and preset is not None:
        raise UsageError("give --preset or --config, not both (--config replays a run, preset included)")
    config = load_config_file(config_file) if config_file is not None else _preset(preset or "default")
    changes = {SHORTCUTS[option]: value for option, value in given.items() if option in SHORTCUTS}
    if "--iterations" in given:
        stages = parse_iterations(given["--iterations"])
        changes.update({f"iterations.stage{k + 1}": steps for k, steps in enumerate(stages)})
    try:
        config = override(config, **changes)
    except ValueError as error:
        raise UsageError(str(error)) from None
    for option, path in TEXT_SHORTCUTS.items():
        if option in given:
            config = _set_option(config, option, f"{path}={given[option]}")
    if "--white" in given:
        config = _set_option(config, "--white", f"tone.illuminant.white={white_level(given['--white'])}")
    if "--priors" in given:
        try:
            config = presets.with_ablation(config, priors=given["--priors"])
        except ValueError as error:
            raise UsageError(f"--priors: {error}") from None
    for assignment in sets or []:
        try:
            config = set_from_text(config, assignment)
        except ValueError as error:
            raise UsageError(f"--set {assignment}: {error}") from None
    check_face_model(config.model)
    return config


def _set_option(config: FitConfig, option: str, assignment: str) -> FitConfig:
    """``config`` with a shortcut's ``PATH=VALUE``; UsageError naming the option."""
    try:
        return set_from_text(config, assignment)
    except ValueError as error:
        raise UsageError(f"{option}: {error}") from None


def white_level(text: str) -> str:
    """``--white``'s value as ``R,G,B``: as given, or the white level a finished fit recorded (its folder or
    params.json: ``illuminant.white``). UsageError (one line) for a run without one."""
    path = Path(text)
    if not path.exists():
        return text
    file = path / "params.json" if path.is_dir() else path
    try:
        white = json.loads(file.read_text())["illuminant"]["white"]
    except (OSError, ValueError, KeyError, TypeError):
        raise UsageError(f"--white {text}: not a finished fit with a white level (params.json's illuminant.white; "
                         "the default preset records it)") from None
    return ",".join(f"{float(v):.5f}" for v in white)


def _preset(name: str) -> FitConfig:
    try:
        return presets.get(name)
    except ValueError as error:
        raise UsageError(f"--preset: {error}") from None


def load_config_file(path: Path) -> FitConfig:
    """The FitConfig recorded in a run's params.json (``path`` is the file or the run's folder), or in a JSON
    file holding a config alone; UsageError (one line) when it is missing or not a valid config."""
    file = path / "params.json" if path.is_dir() else path
    try:
        data = json.loads(file.read_text())
    except FileNotFoundError:
        raise UsageError(f"--config {path}: no such file" + (" (no params.json in that folder)" if path.is_dir()
                                                            else "")) from None
    except (OSError, UnicodeDecodeError) as error:
        raise UsageError(f"--config {file}: cannot read it ({error})") from None
    except json.JSONDecodeError as error:
        raise UsageError(f"--config {file}: not JSON ({error})") from None
    if isinstance(data, dict) and "config" in data:
        data = data["config"]
    try:
        return from_dict(data)
    except ValueError as error:
        raise UsageError(f"--config {file}: {error}") from None


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
