"""The scene-light prior: the kept SH lights stay consistent with the scene's illuminant estimate
(:mod:`deface.priors.illuminant`), so that skin colour cannot be traded for light colour or strength.

White response of light k at normal n (what a white Lambertian surface shows): W_k(n) = E_k(n) / pi
= sum_lm (A_l / pi) c_lm Y_lm(n) (Ramamoorthi & Hanrahan 2001). Its *peak* P_k [3] is W_k at the normal,
among ``directions`` (the front hemisphere), where its luminance is largest.
- colour: every light's peak chromaticity (log RGB minus its mean) matches the estimate's, weighted by the
  light's share of the brightest light's luminance (a dim light - a shadowed condition of f - matters
  less; lights with no positive luminance not at all);
- exposure: the brightest light's level on the face (:func:`key_light_level`: the 90th percentile over the
  skin of the cheeks and forehead of its white response at their normals) matches the estimate's level. Holding
  a light's peak over all directions instead leaves the fit free to turn the lobe away from the face and so
  to brighten the skin.
Each is a squared log-ratio (the caller divides by sigma^2). Positive parts use softplus (sharpness 20) so
lights that start negative (the paper's initialisation) still get gradients.
"""

from __future__ import annotations

import math

import torch

from deface.io.images import LUMINANCE
from deface.render.sh import bands_of, cosine_lobe_coefficients, radiance, sh_basis

SHARPNESS = 20.0
KEY_QUANTILE = 0.9
"""Which quantile of the key light's level over the cheeks and forehead stands for "facing the light"."""


def front_directions(count: int = 256) -> torch.Tensor:
    """[count, 3] unit vectors spread evenly (Fibonacci) over the hemisphere z >= 0 (towards the viewer)."""
    index = torch.arange(count, dtype=torch.float64) + 0.5
    z = 1.0 - index / count
    radius = torch.sqrt(1.0 - z * z)
    angle = index * math.pi * (3.0 - math.sqrt(5.0))
    return torch.stack([radius * torch.cos(angle), radius * torch.sin(angle), z], -1).float()


def white_response(lights: torch.Tensor, directions: torch.Tensor) -> torch.Tensor:
    """[K, N, 3] W_k(n) of lights [K, B*B, 3] at unit normals [N, 3]."""
    bands = bands_of(lights)
    basis = sh_basis(directions.to(lights.dtype), bands) * cosine_lobe_coefficients(bands).to(lights) / math.pi
    return torch.einsum("nj,kjc->knc", basis, lights)


def peak_white(lights: torch.Tensor, directions: torch.Tensor) -> torch.Tensor:
    """[K, 3] each light's white response at its brightest normal."""
    response = white_response(lights, directions)  # [K, N, 3]
    luminance = response @ torch.as_tensor(LUMINANCE, dtype=lights.dtype)
    best = luminance.argmax(1)
    return response[torch.arange(len(lights)), best]


def _positive(values: torch.Tensor) -> torch.Tensor:
    return torch.nn.functional.softplus(values * SHARPNESS) / SHARPNESS + 1e-6


def _log_chromaticity(rgb: torch.Tensor) -> torch.Tensor:
    """[..., 3] log of each channel less their mean: the colour without its level (positive-clamped first)."""
    log_rgb = torch.log(_positive(rgb))
    return log_rgb - log_rgb.mean(-1, keepdim=True)


def light_colour_term(lights: torch.Tensor, white: torch.Tensor, directions: torch.Tensor) -> torch.Tensor:
    """Squared log-chromaticity distance of kept lights [K, B*B, 3] from ``white`` [3], weighted by each
    light's share of the brightest light's peak luminance."""
    peak = peak_white(lights, directions)  # [K, 3]
    luminance = peak @ torch.as_tensor(LUMINANCE, dtype=peak.dtype)
    target = torch.log(white.to(peak.dtype))
    chroma = _log_chromaticity(peak) - (target - target.mean())
    share = (luminance / luminance.max().clamp_min(1e-6)).clamp(0, 1).detach()
    return (share * chroma.pow(2).sum(-1)).sum() / share.sum().clamp_min(1e-6)


def colour_spread(lights: torch.Tensor, directions: torch.Tensor) -> torch.Tensor:
    """How much each light's colour changes with direction: the variance of the log-chromaticity of its white
    response over ``directions`` [N, 3], each direction weighted by its luminance as a share of the light's
    brightest (dark directions colour little), mean over the lights [K, B*B, 3]. 0 for a light of one colour."""
    response = white_response(lights, directions)  # [K, N, 3]
    luminance = response @ torch.as_tensor(LUMINANCE, dtype=response.dtype)  # [K, N]
    weight = (luminance / luminance.max(1, keepdim=True).values.clamp_min(1e-6)).clamp(0, 1).detach()
    chroma = _log_chromaticity(response)  # [K, N, 3]
    total = weight.sum(1).clamp_min(1e-6)  # [K]
    mean = (weight[..., None] * chroma).sum(1) / total[:, None]  # [K, 3]
    spread = (weight * (chroma - mean[:, None]).pow(2).sum(-1)).sum(1) / total  # [K]
    return spread.mean()


RINGING_SHARE = 0.05
"""The negative share a sharp light needs: 9 SH bands fitted to a lobe of about 10 degrees (cos^64, the sharpest
they draw) ring below 0 with about this share (:func:`negative_share`), and the renderer's clamp keeps the lobe."""


def negative_share(lights: torch.Tensor) -> torch.Tensor:
    """[K] how much of each light's [K, B*B, 3] radiance is negative: per channel, the mean square of its negative
    part over the sphere as a share of its mean square, mean over the channels (0 for a light that is nowhere
    negative, 1 for one negative everywhere). The denominator is held fixed, so a gradient lowers the negative part
    rather than raising the rest."""
    values = radiance(lights)  # [K, N, 3]
    total = values.pow(2).mean(1).detach().clamp_min(1e-12)  # [K, 3]
    return (values.clamp_max(0).pow(2).mean(1) / total).mean(1)


def negative_radiance_loss(lights: torch.Tensor) -> torch.Tensor:
    """The lights' negative share beyond the ringing of a sharp light (RINGING_SHARE), mean over the lights. The
    renderer clamps negative radiance, so where a light is mostly negative its raw SH and what is rendered part, and
    the colour and level terms, which read the raw SH, miss what the map is lit by (a green beard on the demo photo)."""
    return (negative_share(lights) - RINGING_SHARE).clamp_min(0).mean()


def key_light_level(lights: torch.Tensor, normals: torch.Tensor, region: torch.Tensor,
                    quantile: float = KEY_QUANTILE) -> torch.Tensor:
    """The brightest light's level on the face: the ``quantile`` over the pixels ``region`` [H, W] (bool) of
    the luminance of each light's white response at the pixels' normals [H, W, 3], for lights [K, B*B, 3].
    The lights' own response, not the mask-weighted render: cast shadows belong to f; and not the render
    over the albedo, whose specular share grows as the skin darkens (a tone-dependent bias)."""
    response = white_response(lights, normals[region].detach())  # [K, N, 3]
    luminance = response @ torch.as_tensor(LUMINANCE, dtype=response.dtype)
    return torch.quantile(luminance, quantile, dim=1).max()


def exposure_term(level: torch.Tensor, target: float) -> torch.Tensor:
    """Squared log-ratio of a light level to its target."""
    return (torch.log(_positive(level)) - math.log(target)).pow(2)


def scene_light_colour_loss(lights: torch.Tensor, white, weight: float, sigma: float) -> torch.Tensor:
    """The scene-light colour term of the kept ``lights`` [K, B*B, 3] against the scene's ``white`` [3] (linear
    RGB): ``weight`` x :func:`light_colour_term` over the front hemisphere / ``sigma``²."""
    white = torch.as_tensor(white, dtype=torch.float32)
    return weight * light_colour_term(lights, white, front_directions()) / sigma**2


def scene_light_level_loss(lights: torch.Tensor, normals: torch.Tensor, region: torch.Tensor, white,
                           weight: float, sigma: float) -> torch.Tensor:
    """The scene-light level term of one frame: ``weight`` x :func:`exposure_term` of the brightest light's level
    on ``region`` [H, W] (the cheeks and forehead; ``normals`` [H, W, 3]) against the luminance of the scene's
    ``white`` [3] / ``sigma``²."""
    level = key_light_level(lights, normals, region)
    return weight * exposure_term(level, float(white @ LUMINANCE)) / sigma**2
