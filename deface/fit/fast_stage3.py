"""Stage 3's texture-space and screen-space terms as ops (deface/render/kernels registers them): the torch
references and fused numba kernels as their fast paths.

A stage-3 step spent most of its time not in shading but in the regularisers of its 512² maps and in the
5x5 local prior: each is a few dozen element-wise torch ops over ~0.8M values, and their backward twice as
many (profile of a 256² default fit, 1 thread: ~400 of ~790 ms per step; benchmarks/history.md). Here each
term is one loop that computes the value *and* its gradient at once; the autograd functions return the
stored gradient times the incoming one.

- ``texture_terms``: ``regulariser_weight`` x NextFace's texture regularisers
  (:func:`deface.losses.texture.texture_regularisers`) plus ``prior_weight`` x GP
  (:func:`deface.priors.global_prior.global_prior`, squared distance, masked mean), with the two parts'
  values for the loss log, so both paths log the same terms.
- ``local_prior_l1``: LP with the 5x5 window and the L1 norm (:func:`deface.priors.local_prior.local_prior`),
  replicate padding.

The fast paths compute the references' formulas (tests/test_render_kernels.py compares values and gradients
in float64). Sums are accumulated in float64 in a fixed order on one thread, so results are deterministic
and do not depend on the thread count; they differ from torch's float32 reductions only by rounding. Where a
term is not differentiable (|0|, a tie between palette colours) the kernels take torch's choices: sign(0) = 0,
the first nearest colour. They run for CPU tensors of one float dtype when the registry's switch allows
(numba importable, ``DEFACE_RENDER_KERNELS`` not ``torch``).
"""

from __future__ import annotations

from functools import cached_property

import numpy as np
import torch

from deface.losses.texture import PAPER_WEIGHTS, RGB_TO_XYZ, MapWeights, texture_regularisers
from deface.priors.global_prior import global_prior
from deface.priors.local_prior import local_prior
from deface.render import kernels
from deface.render.mesh import Textures

try:
    from numba import njit
except ImportError:  # pragma: no cover - exercised only where numba is missing
    njit = None

MAP_NAMES = ("diffuse", "specular", "roughness")


def _fused(*tensors: torch.Tensor) -> bool:
    """Whether the fused kernels handle these tensors (the renderer's kernel switch, one float dtype)."""
    return kernels.enabled(*tensors) and len({t.dtype for t in tensors}) == 1


class TextureTerms:
    """The texture-space part of the stage-3 loss for fixed T^0, UV mask and palette: call it with the
    current :class:`Textures` for (total, regularisers, GP), total = ``regulariser_weight`` x regularisers +
    ``prior_weight`` x GP, the scalar to optimise, and its two parts' values (no gradient) to log; GP is 0
    without a palette. The op ``texture_terms`` with these constants.

    initial: T^0; mask [Ht, Wt] the UV face mask; palette [k, 3] GP's colours (None = no GP).
    """

    def __init__(self, initial: Textures, mask: torch.Tensor, palette: torch.Tensor | None,
                 regulariser_weight: float, prior_weight: float,
                 map_weights: dict[str, MapWeights] = PAPER_WEIGHTS):
        self.initial, self.mask, self.palette = initial, mask, palette
        self.regulariser_weight, self.prior_weight, self.map_weights = regulariser_weight, prior_weight, map_weights

    def __call__(self, textures: Textures) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        return texture_terms(textures.diffuse, textures.specular, textures.roughness, self)

    def tensors(self) -> tuple[torch.Tensor, ...]:
        """The constant tensors the fast path reads (T^0's maps, the mask)."""
        return self.initial.diffuse, self.initial.specular, self.initial.roughness, self.mask

    @cached_property
    def arrays(self) -> _FusedConstants:
        """The fast path's numpy constants, computed once (on its first call)."""
        return _FusedConstants(self)


class _FusedConstants:
    def __init__(self, terms: TextureTerms):
        dtype = terms.initial.diffuse.dtype
        self.references = tuple(_array(getattr(terms.initial, name)) for name in MAP_NAMES)
        self.mask = _array(terms.mask.to(dtype))
        self.palette = _array(terms.palette.to(dtype)) if terms.palette is not None else None
        map_weights = terms.map_weights
        self.weights = tuple(
            np.array([map_weights[name].symmetry, map_weights[name].reference, map_weights[name].chromaticity,
                      map_weights[name].smoothness, map_weights[name].grey], dtype=np.float64)
            * terms.regulariser_weight
            for name in MAP_NAMES
        )
        self.prior_weight = float(terms.prior_weight)
        self.xyz = RGB_TO_XYZ.double().numpy()
        # chromaticity of T^0 is a constant of the fit
        self.reference_xy = tuple(_xy(reference, self.xyz) if reference.shape[-1] == 3 else None
                                  for reference in self.references)


def _texture_terms_reference(diffuse, specular, roughness, terms: TextureTerms):
    """The torch path: deface/losses/texture.py's regularisers plus GP, summed in that order."""
    regularisers = terms.regulariser_weight * texture_regularisers(
        Textures(diffuse, specular, roughness), terms.initial, terms.mask, terms.map_weights)
    if terms.palette is None:
        return regularisers, regularisers.detach(), torch.zeros_like(regularisers.detach())
    prior = terms.prior_weight * global_prior(diffuse, terms.palette, terms.mask)
    return regularisers + prior, regularisers.detach(), prior.detach()


class _TextureTerms(torch.autograd.Function):
    @staticmethod
    def forward(ctx, terms: TextureTerms, diffuse, specular, roughness):
        constants = terms.arrays
        total, regularisers, prior, grads = 0.0, 0.0, 0.0, []
        for index, texture in enumerate((diffuse, specular, roughness)):
            values = _array(texture)
            grad = np.zeros_like(values)
            reference_xy = constants.reference_xy[index]
            value = _map_terms(values, constants.references[index], constants.mask, constants.weights[index],
                               constants.xyz,
                               reference_xy if reference_xy is not None else np.zeros((1, 1, 2), values.dtype),
                               reference_xy is not None, grad)
            total += value
            regularisers += value
            if index == 0 and constants.palette is not None and constants.prior_weight:
                prior = _palette_term(values, constants.palette, constants.mask, constants.prior_weight, grad)
                total += prior
            grads.append(torch.from_numpy(grad))
        ctx.grads = grads
        parts = diffuse.new_tensor(regularisers), diffuse.new_tensor(prior)
        ctx.mark_non_differentiable(*parts)
        return diffuse.new_tensor(total), *parts

    @staticmethod
    def backward(ctx, grad_output, _grad_regularisers, _grad_prior):
        return (None, *(grad * grad_output for grad in ctx.grads))


texture_terms = kernels.register(
    "texture_terms",
    reference=_texture_terms_reference,
    fast=lambda diffuse, specular, roughness, terms: _TextureTerms.apply(terms, diffuse, specular, roughness),
    supports=lambda diffuse, specular, roughness, terms: _fused(diffuse, specular, roughness, *terms.tensors()),
)
"""(diffuse, specular, roughness, :class:`TextureTerms`) -> (total, regularisers, GP): see TextureTerms."""


def _local_prior_l1_reference(current: torch.Tensor, reference: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    return local_prior(current, reference, mask)


class _LocalPrior(torch.autograd.Function):
    @staticmethod
    def forward(ctx, current, reference, mask):
        difference = _array(current) - _array(reference)
        grad = np.zeros_like(difference)
        value = _local_prior_l1(difference, _array(mask.to(current.dtype)), 2, grad)
        ctx.grad = torch.from_numpy(grad)
        return current.new_tensor(value)

    @staticmethod
    def backward(ctx, grad_output):
        return ctx.grad * grad_output, None, None


local_prior_l1 = kernels.register(
    "local_prior_l1",
    reference=_local_prior_l1_reference,
    fast=_LocalPrior.apply,
    supports=lambda current, reference, mask: _fused(current, reference, mask),
)
"""LP (5x5 window, L1) of current vs reference [H, W, C] under pixel weights mask [H, W] (the fast path has
no gradient to the reference or the mask; stage 3's are constants)."""


def _array(tensor: torch.Tensor) -> np.ndarray:
    return tensor.detach().contiguous().numpy()


def _xy(rgb: np.ndarray, xyz_matrix: np.ndarray) -> np.ndarray:
    """CIE xy of linear RGB [H, W, 3] as :func:`deface.losses.texture.chromaticity`."""
    xyz = rgb.astype(np.float64) @ xyz_matrix.T
    return (xyz[..., :2] / (1.0 + np.clip(xyz, 0, None).sum(-1, keepdims=True))).astype(rgb.dtype)


if njit is not None:

    @njit(cache=True)
    def _map_terms(texture, reference, mask, weights, xyz, reference_xy, use_chroma, grad):
        """Value of one map's regularisers (deface/losses/texture.py: map_regulariser) and its gradient,
        added into grad [Ht, Wt, C]. weights = (symmetry, reference, chromaticity, smoothness, grey), scaled."""
        height, width, channels = texture.shape
        numel = height * width * channels
        w_sym, w_ref, w_chr, w_smooth, w_grey = weights[0], weights[1], weights[2], weights[3], weights[4]
        chroma = use_chroma and w_chr != 0.0 and channels == 3
        total = 0.0
        for i in range(height):
            row = 0.0
            for j in range(width):
                m = mask[i, j]
                mirror = width - 1 - j
                both = m * mask[i, mirror]
                mean = 0.0
                for c in range(channels):
                    mean += texture[i, j, c]
                mean /= channels
                for c in range(channels):
                    t = texture[i, j, c]
                    g = 0.0
                    # symmetry: |T - mirror(T)| both / numel, counted at (i, j) and at its mirror
                    d = t - texture[i, mirror, c]
                    row += w_sym * abs(d) * both / numel
                    g += 2.0 * w_sym * np.sign(d) * both / numel
                    # reference: |T - T0| m / numel
                    d = t - reference[i, j, c]
                    row += w_ref * abs(d) * m / numel
                    g += w_ref * np.sign(d) * m / numel
                    # smoothness: squared differences to the right and lower neighbours, both inside the mask
                    if j + 1 < width:
                        pair = m * mask[i, j + 1]
                        d = texture[i, j + 1, c] - t
                        row += w_smooth * d * d * pair
                        g -= 2.0 * w_smooth * d * pair
                    if j > 0:
                        g += 2.0 * w_smooth * (t - texture[i, j - 1, c]) * m * mask[i, j - 1]
                    if i + 1 < height:
                        pair = m * mask[i + 1, j]
                        d = texture[i + 1, j, c] - t
                        row += w_smooth * d * d * pair
                        g -= 2.0 * w_smooth * d * pair
                    if i > 0:
                        g += 2.0 * w_smooth * (t - texture[i - 1, j, c]) * m * mask[i - 1, j]
                    # grey: (T_c - mean_c T)^2 m (the mean's own terms cancel in the gradient)
                    if w_grey != 0.0:
                        d = t - mean
                        row += w_grey * d * d * m
                        g += 2.0 * w_grey * d * m
                    grad[i, j, c] += g
                if chroma:
                    # |xy(T) - xy(T0)| m / (Ht Wt 2), xy = (X, Y) / (1 + sum max(XYZ, 0))
                    big_x, big_y, big_z = 0.0, 0.0, 0.0
                    for c in range(3):
                        big_x += xyz[0, c] * texture[i, j, c]
                        big_y += xyz[1, c] * texture[i, j, c]
                        big_z += xyz[2, c] * texture[i, j, c]
                    px = 1.0 if big_x >= 0.0 else 0.0  # clamp_min(0)'s gradient gate
                    py = 1.0 if big_y >= 0.0 else 0.0
                    pz = 1.0 if big_z >= 0.0 else 0.0
                    s = 1.0 + max(big_x, 0.0) + max(big_y, 0.0) + max(big_z, 0.0)
                    x, y = big_x / s, big_y / s
                    scale = w_chr * m / (height * width * 2)
                    sx, sy = np.sign(x - reference_xy[i, j, 0]), np.sign(y - reference_xy[i, j, 1])
                    row += scale * (abs(x - reference_xy[i, j, 0]) + abs(y - reference_xy[i, j, 1]))
                    # d x / d XYZ = (1/s, 0, 0) - x / s * (px, py, pz), the same for y
                    common = -(sx * x + sy * y) / s
                    gx = scale * (sx / s + common * px)
                    gy = scale * (sy / s + common * py)
                    gz = scale * common * pz
                    for c in range(3):
                        grad[i, j, c] += gx * xyz[0, c] + gy * xyz[1, c] + gz * xyz[2, c]
            total += row
        return total

    @njit(cache=True)
    def _mask_total(mask):
        """Sum of a [H, W] mask, at least 1e-8 (the normaliser of the mask-weighted means)."""
        total = 0.0
        for i in range(mask.shape[0]):
            for j in range(mask.shape[1]):
                total += mask[i, j]
        return max(total, 1e-8)

    @njit(cache=True)
    def _palette_term(diffuse, palette, mask, weight, grad):
        """weight x GP (squared distance to the nearest palette colour, mask-weighted mean) and its gradient
        added into grad; distances in the reference's expanded form ||x||^2 - 2 x.c + ||c||^2."""
        height, width, channels = diffuse.shape
        weight_sum = _mask_total(mask)
        norms = np.zeros(palette.shape[0])
        for k in range(palette.shape[0]):
            for c in range(channels):
                norms[k] += palette[k, c] * palette[k, c]
        total = 0.0
        for i in range(height):
            row = 0.0
            for j in range(width):
                m = mask[i, j]
                if m == 0.0:
                    continue
                square = 0.0
                for c in range(channels):
                    square += diffuse[i, j, c] * diffuse[i, j, c]
                best, nearest = 0, np.inf
                for k in range(palette.shape[0]):
                    dot = 0.0
                    for c in range(channels):
                        dot += diffuse[i, j, c] * palette[k, c]
                    distance = square - 2.0 * dot + norms[k]
                    if distance < nearest:
                        best, nearest = k, distance
                if nearest > 0.0:
                    row += m * nearest
                    for c in range(channels):
                        grad[i, j, c] += weight * m * 2.0 * (diffuse[i, j, c] - palette[best, c]) / weight_sum
            total += row
        return weight * total / weight_sum

    @njit(cache=True)
    def _local_prior_l1(difference, mask, radius, grad):
        """LP = sum_p w(p) d(p) / sum_p w(p), d(p) = mean over channels and the (2r+1)^2 - 1 offsets o of
        |D(p) - D(clamp(p + o))| (replicate padding); its gradient to D into grad. Serial, pixel order."""
        height, width, channels = difference.shape
        weight_sum = _mask_total(mask)
        count = ((2 * radius + 1) ** 2 - 1) * channels
        total = 0.0
        for i in range(height):
            for j in range(width):
                m = mask[i, j]
                if m == 0.0:
                    continue
                scale = m / (count * weight_sum)
                pixel = 0.0
                for dy in range(-radius, radius + 1):
                    qi = min(max(i + dy, 0), height - 1)
                    for dx in range(-radius, radius + 1):
                        if dy == 0 and dx == 0:
                            continue
                        qj = min(max(j + dx, 0), width - 1)
                        for c in range(channels):
                            d = difference[i, j, c] - difference[qi, qj, c]
                            pixel += abs(d)
                            s = np.sign(d) * scale
                            grad[i, j, c] += s
                            grad[qi, qj, c] -= s
                total += m * pixel / count
        return total / weight_sum
