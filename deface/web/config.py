"""What `deface serve` (and a hosted ``app.py``) runs with: :class:`WebConfig`, and the fit configuration of a job
(the page's preset and grey card on top of the operator's settings)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from deface.fit import user_options
from deface.fit.config import FitConfig

PAGE_PRESETS = ("default", "no-cast-shadows", "fast", "paper", "nextface")
"""The presets the page offers (issue 42): the default, the default for photos without cast shadows (keeps more of
a beard), a quick preview, the paper's method and the one-light baseline; `deface presets` describes them."""

CARD_REFLECTANCES = {"grey card (18 %)": 0.18, "white paper (90 %)": 0.9}
"""The reference surfaces the page names, with their reflectance (tone.illuminant.reference_reflectance)."""


@dataclass(frozen=True)
class WebConfig:
    """How the app listens, where it writes and what it allows; `deface serve --help` sets each field."""

    output: Path
    """Every upload, fit, zip and Gradio's own upload cache are written under this folder, nowhere else (one
    sub-folder per job: ``OUT/<job>/<input name>/`` holds what `deface fit` writes)."""
    host: str = "127.0.0.1"
    """Interface to listen on: localhost only unless the operator says otherwise (``0.0.0.0``: every interface)."""
    port: int = 7860
    """TCP port (Gradio's usual one)."""
    models: Path | None = None
    """Model files folder, the only one searched when given (default: DEFACE_MODELS, then the cache)."""
    workers: int = 0
    """Fits at once, each in its own worker process with 1 torch thread (0 = one per core), as `deface fit --jobs`;
    the photos of one job share them, jobs run one after another."""
    presets: tuple[str, ...] = PAGE_PRESETS
    """Presets offered on the page, the first being the page's default."""
    iterations: str | None = None
    """The operator's ``S1,S2,S3`` step counts for every fit (``--iterations``; None: the preset's)."""
    resolution: int | None = None
    """The operator's working resolution for every fit (``--resolution``; None: the preset's)."""
    texture_size: int | None = None
    """The operator's UV map side for every fit (``--texture-size``; None: the preset's)."""
    settings: tuple[str, ...] = ()
    """The operator's ``PATH=VALUE`` settings for every fit, applied after the preset and the shortcuts above."""
    max_file_mb: float = 100.0
    """Largest upload accepted, per file (Gradio refuses bigger ones before they are written)."""
    max_files: int = 16
    """Most files in one job."""
    keep_jobs: int | None = None
    """Keep only the newest this many finished jobs' folders (a hosted demo's disk); None keeps everything."""

    def fit_config(self, preset: str, card_box: tuple[float, float, float, float] | None = None,
                   card_reflectance: float | None = None) -> FitConfig:
        """The configuration of one job: ``preset``, the operator's settings, then the grey card (if any).
        Raises :class:`deface.fit.user_options.UsageError` (one line) for a bad value."""
        if preset not in self.presets:
            raise user_options.UsageError(f"preset must be one of {', '.join(self.presets)}, got '{preset}'")
        sets = list(self.settings)
        if card_box is not None:
            sets.append("tone.illuminant.reference_box=" + ",".join(f"{v:.4f}" for v in card_box))
            if card_reflectance is not None:
                sets.append(f"tone.illuminant.reference_reflectance={card_reflectance}")
        return user_options.fit_config(preset, None, sets, iterations=self.iterations, resolution=self.resolution,
                                  texture_size=self.texture_size)

    def check(self) -> None:
        """Usage errors before the server starts: an unknown preset, a bad setting, limits out of range."""
        user_options.check_ranges({"--jobs": self.workers})
        user_options.check_models_dir(self.models)
        user_options.check_output(self.output)
        if not 1 <= self.port <= 65535:
            raise user_options.UsageError(f"--port must be from 1 to 65535, got {self.port}")
        if not 0 < self.max_file_mb <= 10_000:
            raise user_options.UsageError(f"--max-file-mb must be from 0 to 10000 MB, got {self.max_file_mb}")
        if not 1 <= self.max_files <= 1000:
            raise user_options.UsageError(f"--max-files must be from 1 to 1000, got {self.max_files}")
        if self.keep_jobs is not None and self.keep_jobs < 1:
            raise user_options.UsageError(f"--keep-jobs must be at least 1, got {self.keep_jobs}")
        if not self.presets:
            raise user_options.UsageError("the page needs at least one preset")
        for preset in self.presets:
            self.fit_config(preset)
