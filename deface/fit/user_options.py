"""The options a user gives a fit (``deface fit``, ``deface eval``, the web page), checked, and the FitConfig they
make: every numeric option's documented range, checked before any work starts, so a bad value is a usage error
naming the option, never a failure of each input.

A fit's configuration is built by ``fit_config`` in one order: the preset (or ``--config``, a finished run's
params.json), then the shortcut options (``--lights``, ``--iterations``, ...: each is a named config path,
``SHORTCUTS``), then every ``--set PATH=VALUE`` in the order given. Every setting of FitConfig is reachable
with ``--set``.

The ranges bound what a CPU fit can do in reasonable memory and time; README ("When things go wrong") lists them.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from deface.fit import presets
from deface.fit.config import FitConfig, from_dict, override, set_from_text


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
