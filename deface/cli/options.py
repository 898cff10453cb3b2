"""Command-line option checks, in one place: every numeric option's documented range, checked before any
work starts, so a bad value is a usage error (exit 2) naming the option, never a failure of each input.

The ranges bound what a CPU fit can do in reasonable memory and time; README ("When things go wrong")
lists them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path


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
    "--resolution": Range(32, 2048, "a number of pixels (longest side of the working image)"),
    "--texture-size": Range(16, 4096, "a number of texels (side of the UV maps)"),
    "--lights": Range(1, 16, "a number of light conditions"),
    "--bands": Range(1, 16, "a number of SH bands"),
    "--max-frames": Range(1, 256, "a number of frames"),
    "--frame-stride": Range(1, 10_000, "a frame step"),
    "--face-index": Range(0, 63, "a face number (0 = largest)"),
    "--threads": Range(0, 256, "a number of torch threads (0 = torch's default)"),
    "--seed": Range(0, 2**32 - 1, "a seed"),
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


def check_face_model(name: str) -> None:
    if name not in FACE_MODELS:
        raise UsageError(f"--model must be one of {', '.join(FACE_MODELS)}, got '{name}'")


def check_models_dir(path: Path | None) -> None:
    """``--models DIR`` must be an existing folder (it is the only place searched)."""
    if path is not None and not path.is_dir():
        raise UsageError(f"--models {path}: no such folder")


def check_output(path: Path) -> None:
    """``-o OUT`` must be a folder or not exist yet (it is created)."""
    if path.exists() and not path.is_dir():
        raise UsageError(f"-o {path}: exists and is not a folder; name a folder (it is created if missing)")
