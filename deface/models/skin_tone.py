"""A skin-tone axis with a flat prior: skin colour as a function of the individual typology angle (ITA).

ITA (Chardon et al. 1991) is the angle of a colour in CIELAB's (b*, L*) plane around (b* 0, L* 50):
L* = 50 + R sin(ITA), b* = R cos(ITA). Human skin spans roughly ITA -50 to 70 degrees (Del Bino et al. 2006
groups: < -30 dark, -30-10 brown, 10-28 tan, 28-41 intermediate, 41-55 light, > 55 very light). The axis keeps
R and a* of the project's reference skin (the mean of Jensen et al. 2001's two skin samples, Table 1, the base
of the ICT albedo prior: L* 66.5, a* 10.9, b* 16.9, so ITA 44.3 and R 23.6) and moves along ITA only, so every
tone is the reference skin darkened or lightened along the direction ITA measures. It is a design choice,
not a measured locus: lightness and chroma off the axis come from the albedo prior's brightness and
haemoglobin components and from stage 3's per-texel maps.

Flat prior: the fit optimises the ITA itself, projected into the human range (``FitConfig.tone.ita_range``)
after each step, with no cost term, so no tone in the range costs more than another
(tests/test_fit_skin_tone.py).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import torch
from skimage.color import lab2rgb, rgb2lab

from deface.io.images import GAMMA

TABLE_STEP = 0.25  # degrees between tabulated tones (linear interpolation between them)


@dataclass(frozen=True)
class SkinToneAxis:
    """Linear-RGB skin colour as a differentiable function of ITA (degrees)."""

    radius: float
    """Distance of the skin colours from (b* 0, L* 50) in CIELAB."""
    a_star: float
    """Redness a* kept along the axis."""
    reference_ita: float
    """ITA of the albedo model's own mean skin (scale 1)."""
    min_ita: float = -60.0
    max_ita: float = 85.0
    """The tabulated range (a fit's range, FitConfig.tone.ita_range, lies inside it)."""

    @staticmethod
    def through(reference_linear_rgb) -> SkinToneAxis:
        """The axis through a reference skin colour (linear RGB, gamma 2.2 as the project's textures)."""
        srgb = np.asarray(reference_linear_rgb, dtype=np.float64) ** (1.0 / GAMMA)
        lightness, a_star, b_star = rgb2lab(srgb[None, None])[0, 0]
        radius = float(np.hypot(lightness - 50.0, b_star))
        ita = float(np.degrees(np.arctan2(lightness - 50.0, b_star)))
        return SkinToneAxis(radius=radius, a_star=float(a_star), reference_ita=ita)

    def lab(self, ita: np.ndarray) -> np.ndarray:
        """CIELAB [..., 3] of tones ``ita`` (degrees)."""
        angle = np.radians(np.asarray(ita, dtype=np.float64))
        lab = np.stack([50.0 + self.radius * np.sin(angle), np.full(angle.shape, self.a_star),
                        self.radius * np.cos(angle)], -1)
        return lab

    @cached_property
    def table(self) -> torch.Tensor:
        """[M, 3] linear RGB at min_ita, min_ita + TABLE_STEP, ..., max_ita."""
        grid = np.arange(self.min_ita, self.max_ita + TABLE_STEP / 2, TABLE_STEP)
        srgb = lab2rgb(self.lab(grid)[None])[0]
        return torch.as_tensor(np.clip(srgb, 0.0, 1.0) ** GAMMA, dtype=torch.float32)

    def linear_rgb(self, ita: torch.Tensor) -> torch.Tensor:
        """Linear RGB [..., 3] of ``ita`` [...] (degrees), piecewise linear, differentiable in ``ita``."""
        table = self.table.to(ita.dtype)
        position = ((ita - self.min_ita) / TABLE_STEP).clamp(0, len(table) - 1)
        index = position.detach().floor().long().clamp(max=len(table) - 2)
        frac = (position - index.to(position.dtype))[..., None]
        return table[index] * (1 - frac) + table[index + 1] * frac

    def scale(self, ita: torch.Tensor) -> torch.Tensor:
        """[3] per-channel factor taking the reference skin to tone ``ita`` (a scalar tensor)."""
        reference = self.linear_rgb(torch.tensor(self.reference_ita, dtype=ita.dtype))
        return self.linear_rgb(ita) / reference

    def clamp_(self, ita: torch.Tensor, ita_range: tuple[float, float] | None = None) -> None:
        """Project ``ita`` in place into ``ita_range`` (the flat prior's support; FitConfig.tone.ita_range),
        within the tabulated range."""
        low, high = ita_range or (self.min_ita, self.max_ita)
        with torch.no_grad():
            ita.clamp_(max(low, self.min_ita), min(high, self.max_ita))
