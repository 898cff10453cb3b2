"""Relighting in the page: the finished fit loaded back (``deface.load_fit``, no refit) and rendered by the project's
renderer under a preset light (deface.relight.lights: studio, sun, overcast, rim, neutral) turned by the page's
sliders and scaled by its exposure, as `deface relight --light P --rotate-light D --exposure EV` does."""

from __future__ import annotations

import dataclasses
import math
import threading
from collections import OrderedDict
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from deface.export.load import load_fit
from deface.fit.output import FitOutput
from deface.io.images import to_uint8
from deface.relight.lights import PRESETS, preset_lights, rotate_lights, yaw_matrix
from deface.relight.render import face_rgba

LIGHT_PRESETS = tuple(PRESETS)
KEEP_LOADED = 4  # fits kept loaded (a few MB each): switching between a batch's results stays quick


def light_rotation(turn: float, lift: float) -> np.ndarray:
    """[3, 3]: turn the light about the vertical axis by ``turn`` degrees (positive: towards the subject's left,
    as ``--rotate-light``), then raise it by ``lift`` degrees (positive: from above)."""
    raise_light = Rotation.from_rotvec([-math.radians(lift), 0.0, 0.0]).as_matrix()  # +z towards +y
    return raise_light @ yaw_matrix(turn)


class Relighter:
    """Loaded fits (the latest :data:`KEEP_LOADED`) and their renders under new light; one render at a time."""

    def __init__(self, models: Path | None = None):
        self.models = models
        self._loaded: OrderedDict[Path, FitOutput] = OrderedDict()
        self._lock = threading.Lock()

    def relight(self, folder: Path, light: str, turn: float = 0.0, lift: float = 0.0,
                exposure: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """The fit in ``folder`` (a clip's first frame) under ``light`` -> (the face composited into the photo,
        [H, W, 3] uint8 sRGB; the face alone with its coverage as alpha, [H, W, 4] uint8)."""
        with self._lock:
            fit = self._fit(Path(folder))
            lights = preset_lights(light, fit.lights.bands)
            if turn or lift:
                lights = rotate_lights(lights, light_rotation(turn, lift))
            rendered = fit.render(lights=lights * 2.0**exposure)[0]
            composite = to_uint8(fit.composite(rendered, 0).numpy(), srgb=True)
            return composite, face_rgba(rendered)

    def _fit(self, folder: Path) -> FitOutput:
        if folder in self._loaded:
            self._loaded.move_to_end(folder)
            return self._loaded[folder]
        fit = load_fit(folder, self.models)
        if fit.num_frames > 1:
            fit = dataclasses.replace(fit, frames=fit.frames[:1])
        self._loaded[folder] = fit
        while len(self._loaded) > KEEP_LOADED:
            self._loaded.popitem(last=False)
        return fit
