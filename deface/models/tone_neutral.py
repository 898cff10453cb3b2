"""Albedo coefficients that leave the skin tone to the tone axis.

With a free tone (docs/skin-tone.md) two parts of the albedo model can move the skin's ITA: the tone axis, set
from the scene's key-lit skin, and the prior's own components, whose constant melanin and brightness terms
darken or lighten the whole face (about -5.5 and +1.4 degrees of ITA per unit coefficient on the ICT prior).
Stage 2 trades those components against the key light's level as freely as it would the tone, so they undo
the start by several degrees, and differently for the same person under another light. :func:`keep_tone_`
projects the coefficients, after each step, onto the set where the texture's ITA over the cheeks and forehead
(:data:`deface.models.ita.TONE_BOXES`) is the one the tone axis alone gives; every other change (redness,
the spatial structure, lightness and chroma along the ITA ray) stays free.

The tone is read as the benchmark reads it (deface/models/ita.py), up to the order of median and CIELAB: the
ITA of the per-channel median linear colour of the boxes' texels, a piecewise linear function of the
coefficients before the CIELAB conversion. The constraint is solved by Gauss-Newton steps in coefficient space
(the metric of the coefficients' N(0, 1) prior: the smallest change that keeps the tone).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from skimage.color import rgb2lab

from deface.io.images import linear_to_srgb
from deface.models.base import AlbedoModel
from deface.models.ita import ita_degrees, texture_tone_mask

COLOUR_STEP = 1e-3  # linear-colour step of the central differences
NEWTON_STEPS = 10


@dataclass(frozen=True)
class ToneBoxColours:
    """The albedo model's diffuse map on the tone boxes' texels: their colours are mean + coeffs @ basis."""

    mean: np.ndarray  # [N, 3] linear RGB of the mean map
    basis: np.ndarray  # [Ka, N * 3] linear RGB per unit coefficient

    @staticmethod
    def of(albedo: AlbedoModel) -> ToneBoxColours:
        boxes = texture_tone_mask(*albedo.diffuse_mean.shape[:2])
        basis = albedo.diffuse_basis[:, boxes]
        return ToneBoxColours(albedo.diffuse_mean[boxes].astype(np.float64),
                              basis.reshape(len(basis), -1).astype(np.float64))

    def median(self, coeffs: np.ndarray, scale: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The boxes' per-channel median linear colour [3] at ``coeffs`` [Ka] and the tone's ``scale`` [3], and
        d colour / d coeffs [Ka, 3] (each channel's median is one texel's value: linear in the coefficients)."""
        texels = (self.mean + (coeffs @ self.basis).reshape(self.mean.shape)) * scale
        middle = len(texels) // 2
        index = np.argpartition(texels, middle, axis=0)[middle]  # [3] the median texel of each channel
        colour = texels[index, np.arange(3)]
        basis = self.basis.reshape(len(self.basis), *self.mean.shape)
        return colour, basis[:, index, np.arange(3)] * scale

    def ita(self, coeffs: np.ndarray, scale: np.ndarray) -> float:
        """ITA (degrees) of the boxes' median colour."""
        return float(colour_ita(self.median(coeffs, scale)[0][None])[0])

    def gradient(self, coeffs: np.ndarray, scale: np.ndarray) -> np.ndarray:
        """[Ka] d ITA / d coeffs at ``coeffs`` [Ka] (the colour's CIELAB by central differences)."""
        colour, jacobian = self.median(coeffs, scale)
        steps = np.eye(3) * COLOUR_STEP
        itas = colour_ita(np.concatenate([colour + steps, colour - steps]))
        return jacobian @ ((itas[:3] - itas[3:]) / (2 * COLOUR_STEP))


def colour_ita(colours: np.ndarray) -> np.ndarray:
    """ITA (degrees) [N] of linear colours [N, 3], sRGB-encoded as the textures are written."""
    return ita_degrees(rgb2lab(linear_to_srgb(colours)[None])[0])


def keep_tone_(coeffs: torch.Tensor, colours: ToneBoxColours, scale: torch.Tensor) -> None:
    """Move ``coeffs`` [Ka] in place, by the least change, to where the boxes' ITA equals that of the mean
    map at the tone's ``scale`` [3] (:meth:`deface.models.skin_tone.SkinToneAxis.scale`)."""
    scale_np = scale.detach().double().numpy()
    target = colours.ita(np.zeros(len(colours.basis)), scale_np)
    current = coeffs.detach().double().numpy().copy()
    for _ in range(NEWTON_STEPS):
        error = colours.ita(current, scale_np) - target
        gradient = colours.gradient(current, scale_np)
        norm = float(gradient @ gradient)
        if abs(error) < 1e-4 or norm < 1e-12:
            break
        current -= gradient * error / norm
    with torch.no_grad():
        coeffs.copy_(torch.as_tensor(current, dtype=coeffs.dtype))
