"""Real orthonormal spherical harmonics, any number of bands, differentiable in torch.

Convention (shared by the whole project): coefficient index ``l*l + l + m`` for band ``l`` and order
``-l <= m <= l``; no Condon-Shortley phase, so ``Y_1,-1 ∝ y``, ``Y_1,0 ∝ z``, ``Y_1,1 ∝ x``:

    Y_l0  = N_l0 P_l^0(z)
    Y_lm  = sqrt(2) N_lm P_l^m(z) cos(m phi)      m > 0
    Y_l-m = sqrt(2) N_lm P_l^m(z) sin(m phi)      m > 0
    N_lm  = sqrt((2l+1)/(4 pi) (l-m)!/(l+m)!)

Evaluation is stable for many bands: we run the *fully normalised* associated-Legendre recurrence
(Holmes & Featherstone 2002) on Q_l^m = N_lm P_l^m / sin^m(theta), a polynomial in z, and multiply by
sin^m(theta) cos/sin(m phi) = Re/Im((x + i y)^m), another polynomial. Everything is a polynomial in
(x, y, z), so gradients are finite everywhere, including the poles.

Radiance of an SH light: ``L(w) = sum_lm c_lm Y_lm(w)``, w the unit direction towards the light.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
import torch

from deface.render import kernels


def sh_basis(directions: torch.Tensor, bands: int) -> torch.Tensor:
    """Real orthonormal SH basis at unit ``directions`` [..., 3] -> [..., bands²] (index l*l + l + m).

    Differentiable once (analytic backward, see kernels/sh_bands.py).
    """
    if directions.shape[-1] != 3:
        raise ValueError(f"sh_basis: directions must have shape [..., 3], got {tuple(directions.shape)}")
    if bands < 1:
        raise ValueError(f"sh_basis: bands must be >= 1, got {bands}")
    basis = kernels.sh_basis(directions.reshape(-1, 3), bands, False)  # [N, B²], row-major
    return basis.reshape(*directions.shape[:-1], bands * bands)


def sh_basis_rows(directions: torch.Tensor, bands: int) -> torch.Tensor:
    """SH basis channel-first: unit directions [N, 3] -> [bands², N]; same values as :func:`sh_basis`.

    Every intermediate is a contiguous [m, N] block, and the backward pass is analytic (derivative
    recurrences) instead of autograd over ~100 small ops: both several times faster.
    """
    if directions.ndim != 2 or directions.shape[1] != 3:
        raise ValueError(f"sh_basis_rows: directions must be [N, 3], got {tuple(directions.shape)}")
    if bands < 1:
        raise ValueError(f"sh_basis: bands must be >= 1, got {bands}")
    return kernels.sh_basis(directions, bands, True)


def sh_band_sums(directions: torch.Tensor, coeffs: torch.Tensor) -> torch.Tensor:
    """Per-band sums S_l(w) = sum_m c_lm Y_lm(w): unit directions [N, 3], coeffs [B², C] -> [N, B, C].

    Any band-filtered radiance is sum_l f_l S_l(w) (irradiance: f_l = A_l; Phong specular: f_l =
    Lambda_l).
    """
    bands = math.isqrt(coeffs.shape[0])
    if bands < 1 or bands * bands != coeffs.shape[0] or directions.ndim != 2 or directions.shape[1] != 3:
        raise ValueError(f"sh_band_sums: got directions {tuple(directions.shape)}, coeffs {tuple(coeffs.shape)}")
    return kernels.sh_band_sums(directions, coeffs)


def cosine_lobe_band(l: int) -> float:  # noqa: E741
    """A_l of the clamped-cosine kernel max(cos, 0) (Ramamoorthi & Hanrahan 2001, "An efficient
    representation for irradiance environment maps", eq. 8-9): irradiance E_lm = A_l L_lm.

    A_0 = pi, A_1 = 2 pi / 3, A_l = 0 for odd l > 1, and for even l
    A_l = 2 pi (-1)^(l/2 - 1) / ((l + 2)(l - 1)) * l! / (2^l ((l/2)!)^2).
    """
    if l == 0:
        return math.pi
    if l == 1:
        return 2.0 * math.pi / 3.0
    if l % 2:
        return 0.0
    half = l // 2
    log_ratio = math.lgamma(l + 1) - l * math.log(2.0) - 2 * math.lgamma(half + 1)
    return 2.0 * math.pi * (-1) ** (half - 1) / ((l + 2) * (l - 1)) * math.exp(log_ratio)


def cosine_lobe_coefficients(bands: int) -> torch.Tensor:
    """A_l repeated for each m of band l -> [bands²] float32 (irradiance E(n) = sum A_l c_lm Y_lm(n))."""
    if bands < 1:
        raise ValueError(f"cosine_lobe_coefficients: bands must be >= 1, got {bands}")
    return torch.tensor(_cosine_lobe_values(bands), dtype=torch.float32)


@lru_cache(maxsize=64)
def _cosine_lobe_values(bands: int) -> tuple[float, ...]:
    """A_l per coefficient (computed once per band count: the renderer asks on every call)."""
    return tuple(cosine_lobe_band(l) for l in range(bands) for _ in range(2 * l + 1))


def fibonacci_sphere(count: int) -> np.ndarray:
    """[count, 3] float64 near-uniform unit directions (equal area each: 4 pi / count)."""
    i = np.arange(count) + 0.5
    z = 1.0 - 2.0 * i / count
    radius = np.sqrt(1.0 - z * z)
    phi = i * math.pi * (3.0 - math.sqrt(5.0))
    return np.stack([radius * np.cos(phi), radius * np.sin(phi), z], -1)


RADIANCE_SAMPLES = 2048
"""Directions at which :func:`non_negative` reads a light's radiance (about 4.5 degrees apart)."""


@lru_cache(maxsize=16)
def _radiance_basis(bands: int) -> tuple[torch.Tensor, torch.Tensor]:
    """The SH basis at RADIANCE_SAMPLES directions [N, B²] and its pseudo-inverse [B², N] (least squares)."""
    basis = sh_basis(torch.as_tensor(fibonacci_sphere(RADIANCE_SAMPLES)), bands)
    return basis, torch.linalg.pinv(basis)


def bands_of(lights: torch.Tensor) -> int:
    """B of lights [..., B², 3]; ValueError when that is not their shape."""
    if lights.ndim < 2 or lights.shape[-1] != 3:
        raise ValueError(f"SH lights must be [..., B², 3], got {tuple(lights.shape)}")
    bands = math.isqrt(lights.shape[-2])
    if bands < 1 or bands * bands != lights.shape[-2]:
        raise ValueError(f"SH lights: {lights.shape[-2]} coefficients is not a square number of bands")
    return bands


def radiance(lights: torch.Tensor) -> torch.Tensor:
    """[K, RADIANCE_SAMPLES, 3] the radiance of lights [K, B², 3] at RADIANCE_SAMPLES even directions."""
    basis, _ = _radiance_basis(bands_of(lights))
    return torch.einsum("nj,kjc->knc", basis.to(lights), lights)


def non_negative(lights: torch.Tensor) -> torch.Tensor:
    """Lights [K, B², 3] whose radiance is clamped at 0: the band-limited SH closest over the sphere (least
    squares) to max(L(w), 0), as NextFace clamps the environment map it renders its SH lights through. A light
    whose radiance is nowhere negative is returned as it is. Without it a fitted light's negative lobes
    subtract light (a specular reflection towards them darkens a downward-facing chin like a beard)."""
    values = radiance(lights)
    if bool((values >= 0).all()):
        return lights
    inverse = _radiance_basis(bands_of(lights))[1].to(lights)
    return torch.einsum("jn,knc->kjc", inverse, values.clamp_min(0))


def white_light(bands: int, ambient: float = 0.7) -> torch.Tensor:
    """[1, bands², 3] a neutral light: uniform plus a first-order lobe towards +z (the viewer in the model
    frame), scaled so a white Lambertian surface shows ``ambient`` sideways and exactly 1 facing +z
    (diffuse radiance E / pi with E = A_0 c_00 Y_00 + A_1 c_10 Y_10). Renders under it show the albedo itself
    where the surface faces the viewer."""
    coeffs = torch.zeros(bands * bands)
    y00, y10_scale = 0.5 / math.sqrt(math.pi), math.sqrt(3.0 / (4.0 * math.pi))
    coeffs[0] = ambient / y00  # (A_0 / pi) c_00 Y_00 = ambient
    if bands > 1:
        coeffs[2] = (1.0 - ambient) / (cosine_lobe_band(1) / math.pi * y10_scale)  # index l*l + l + m of (1, 0)
    return coeffs[None, :, None].expand(1, bands * bands, 3).clone()
