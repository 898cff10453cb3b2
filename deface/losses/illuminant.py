"""The scene-light prior: the kept SH lights stay consistent with the scene's illuminant estimate
(:mod:`deface.priors.illuminant`), so that skin colour cannot be traded for light colour or strength.

White response of light k at normal n (what a white Lambertian surface shows): W_k(n) = E_k(n) / pi
= sum_lm (A_l / pi) c_lm Y_lm(n) (Ramamoorthi & Hanrahan 2001). Its *peak* P_k [3] is W_k at the normal,
among ``directions`` (the front hemisphere), where its luminance is largest.
- colour: every light's peak chromaticity (log RGB minus its mean) matches the estimate's, weighted by the
  light's share of the brightest light's luminance (a dim light - a shadowed condition of f - matters
  less; lights with no positive luminance not at all);
- exposure: the brightest light's peak luminance matches the estimate's (shadowed conditions of f are
  dimmer by nature, so only the brightest is held).
Each term is a squared log-ratio over its sigma^2. Positive parts use softplus (sharpness 20) so lights
that start negative (the paper's initialisation) still get gradients.
"""

from __future__ import annotations

import math

import torch

from deface.render.sh import cosine_lobe_coefficients, sh_basis

LUMINANCE = (0.2126, 0.7152, 0.0722)
SHARPNESS = 20.0


def front_directions(count: int = 256) -> torch.Tensor:
    """[count, 3] unit vectors spread evenly (Fibonacci) over the hemisphere z >= 0 (towards the viewer)."""
    index = torch.arange(count, dtype=torch.float64) + 0.5
    z = 1.0 - index / count
    radius = torch.sqrt(1.0 - z * z)
    angle = index * math.pi * (3.0 - math.sqrt(5.0))
    return torch.stack([radius * torch.cos(angle), radius * torch.sin(angle), z], -1).float()


def white_response(lights: torch.Tensor, directions: torch.Tensor) -> torch.Tensor:
    """[K, N, 3] W_k(n) of lights [K, B*B, 3] at unit normals [N, 3]."""
    bands = int(round(math.sqrt(lights.shape[1])))
    basis = sh_basis(directions.to(lights.dtype), bands) * cosine_lobe_coefficients(bands).to(lights) / math.pi
    return torch.einsum("nj,kjc->knc", basis, lights)


def peak_white(lights: torch.Tensor, directions: torch.Tensor) -> torch.Tensor:
    """[K, 3] each light's white response at its brightest normal."""
    response = white_response(lights, directions)  # [K, N, 3]
    luminance = response @ torch.tensor(LUMINANCE, dtype=lights.dtype)
    best = luminance.argmax(1)
    return response[torch.arange(len(lights)), best]


def _positive(values: torch.Tensor) -> torch.Tensor:
    return torch.nn.functional.softplus(values * SHARPNESS) / SHARPNESS + 1e-6


def scene_light_terms(lights: torch.Tensor, white: torch.Tensor, directions: torch.Tensor,
                      colour_sigma: float, exposure_sigma: float) -> tuple[torch.Tensor, torch.Tensor]:
    """(colour, exposure) terms for kept lights [K, B*B, 3] and the estimated white level ``white`` [3]."""
    peak = peak_white(lights, directions)  # [K, 3]
    luminance = peak @ torch.tensor(LUMINANCE, dtype=peak.dtype)
    target = torch.log(white.to(peak.dtype))
    log_peak = torch.log(_positive(peak))
    chroma = (log_peak - log_peak.mean(-1, keepdim=True)) - (target - target.mean())
    share = (luminance / luminance.max().clamp_min(1e-6)).clamp(0, 1).detach()
    colour = (share * chroma.pow(2).sum(-1)).sum() / share.sum().clamp_min(1e-6) / colour_sigma**2
    brightest = torch.log(_positive(luminance.max()))
    exposure = (brightest - torch.log(white.to(peak.dtype) @ torch.tensor(LUMINANCE, dtype=peak.dtype))).pow(2)
    return colour, exposure / exposure_sigma**2
