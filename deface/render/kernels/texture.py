"""Bilinear texture lookup (``sample_texture``: grid_sample semantics, align_corners=False, border
padding, row 0 of a map is v = 1) and the texel scatter of its gradient.

Reference: ``torch.nn.functional.grid_sample``. Fast: one loop per sample; the texture gradient is
scattered from the N samples only, on one thread (``_bilinear_scatter``) or, for the shading kernel's
three maps, by texel-row ranges that each scan the samples in order (``_scatter_texel_grads``); both
sum every texel's contributions in sample order, whatever the thread count.
"""

from __future__ import annotations

import numpy as np
import torch

from deface.render.kernels.base import _array, _pick, enabled, njit, prange, register, serial_and_parallel


# -- torch reference --------------------------------------------------------------------------------
def _sample_texture_reference(texture: torch.Tensor, uv: torch.Tensor) -> torch.Tensor:
    """texture [Ht, Wt, C] at uv [N, 2] -> [N, C] with ``grid_sample``."""
    grid = torch.stack([uv[:, 0] * 2 - 1, 1 - uv[:, 1] * 2], -1).to(texture.dtype)  # [N, 2]
    image = texture.permute(2, 0, 1)[None]  # [1, C, Ht, Wt]
    sampled = torch.nn.functional.grid_sample(
        image, grid[None, None], mode="bilinear", padding_mode="border", align_corners=False
    )  # [1, C, 1, N]
    return sampled[0, :, 0].T


# -- fast path ----------------------------------------------------------------------------------------
def bilinear_forward(texture: torch.Tensor, uv: torch.Tensor) -> torch.Tensor:
    """``sample_texture``'s lookup: texture [Ht, Wt, C], uv [N, 2] -> [N, C] (border padding)."""
    out = np.empty((uv.shape[0], texture.shape[2]), dtype=_array(texture).dtype)
    _pick(_bilinear_forward)(_array(texture), _array(uv), out)
    return torch.from_numpy(out)


def bilinear_backward(texture: torch.Tensor, uv: torch.Tensor, grad: torch.Tensor, need_texture: bool, need_uv: bool):
    """Gradients of ``bilinear_forward`` to the texture [Ht, Wt, C] and uv [N, 2] (None where not needed)."""
    tex, coords, g = _array(texture), _array(uv), _array(grad)
    grad_texture = grad_uv = None
    if need_texture:
        grad_texture = np.zeros(tex.shape, dtype=g.dtype)
        _bilinear_scatter(coords, g, grad_texture)
    if need_uv:
        grad_uv = np.empty(coords.shape, dtype=g.dtype)
        _pick(_bilinear_grad_uv)(tex, coords, g, grad_uv)
    return (
        None if grad_texture is None else torch.from_numpy(grad_texture),
        None if grad_uv is None else torch.from_numpy(grad_uv),
    )


class _BilinearLookup(torch.autograd.Function):
    """The numba path of ``sample_texture``: the texture gradient is scattered from the N samples only."""

    @staticmethod
    def forward(ctx, texture, uv):
        ctx.save_for_backward(texture, uv)
        return bilinear_forward(texture, uv)

    @staticmethod
    def backward(ctx, grad):
        texture, uv = ctx.saved_tensors
        return bilinear_backward(texture, uv, grad, ctx.needs_input_grad[0], ctx.needs_input_grad[1])


@njit(inline="always")
def _texel_axis(coordinate, size):
    """grid_sample (align_corners=False, border) along one axis: texel x0, fraction, d(coord)/d(input)."""
    position = coordinate * size - 0.5
    slope = float(size)
    if position <= 0.0:
        position, slope = 0.0, 0.0
    elif position >= size - 1:
        position, slope = float(size - 1), 0.0
    start = min(int(np.floor(position)), size - 1)
    return start, position - start, slope


@serial_and_parallel
def _bilinear_forward(texture, uv, out):
    height, width, channels = texture.shape
    for p in prange(uv.shape[0]):
        x0, fx, _ = _texel_axis(uv[p, 0], width)
        y0, fy, _ = _texel_axis(1.0 - uv[p, 1], height)  # row 0 is v = 1
        x1, y1 = min(x0 + 1, width - 1), min(y0 + 1, height - 1)
        for c in range(channels):
            top = texture[y0, x0, c] * (1.0 - fx) + texture[y0, x1, c] * fx
            bottom = texture[y1, x0, c] * (1.0 - fx) + texture[y1, x1, c] * fx
            out[p, c] = top * (1.0 - fy) + bottom * fy


@njit(cache=True)
def _bilinear_scatter(uv, grad, grad_texture):
    height, width, channels = grad_texture.shape
    for p in range(uv.shape[0]):  # serial: texels are shared between pixels
        x0, fx, _ = _texel_axis(uv[p, 0], width)
        y0, fy, _ = _texel_axis(1.0 - uv[p, 1], height)
        x1, y1 = min(x0 + 1, width - 1), min(y0 + 1, height - 1)
        for c in range(channels):
            g = grad[p, c]
            grad_texture[y0, x0, c] += g * (1.0 - fx) * (1.0 - fy)
            grad_texture[y0, x1, c] += g * fx * (1.0 - fy)
            grad_texture[y1, x0, c] += g * (1.0 - fx) * fy
            grad_texture[y1, x1, c] += g * fx * fy


@serial_and_parallel
def _bilinear_grad_uv(texture, uv, grad, grad_uv):
    height, width, channels = texture.shape
    for p in prange(uv.shape[0]):
        x0, fx, slope_x = _texel_axis(uv[p, 0], width)
        y0, fy, slope_y = _texel_axis(1.0 - uv[p, 1], height)
        x1, y1 = min(x0 + 1, width - 1), min(y0 + 1, height - 1)
        d_fx = 0.0
        d_fy = 0.0
        for c in range(channels):
            t00, t01 = texture[y0, x0, c], texture[y0, x1, c]
            t10, t11 = texture[y1, x0, c], texture[y1, x1, c]
            d_fx += grad[p, c] * ((t01 - t00) * (1.0 - fy) + (t11 - t10) * fy)
            d_fy += grad[p, c] * ((t10 - t00) * (1.0 - fx) + (t11 - t01) * fx)
        grad_uv[p, 0] = d_fx * slope_x
        grad_uv[p, 1] = -d_fy * slope_y  # y = (1 - v) * Ht - 0.5


@njit(inline="always")
def _bilinear_setup(uv0, uv1, height, width):
    """Texels, fractions and slopes of a bilinear lookup at (u, v) (sample_texture's convention)."""
    x0, fx, slope_x = _texel_axis(uv0, width)
    y0, fy, slope_y = _texel_axis(1.0 - uv1, height)
    return x0, min(x0 + 1, width - 1), fx, slope_x, y0, min(y0 + 1, height - 1), fy, slope_y


@njit(inline="always")
def _bilinear_sample(texture, x0, x1, fx, y0, y1, fy, c):
    return _bilinear_mix(_texel_corners(texture, x0, x1, y0, y1, c), fx, fy)


@njit(inline="always")
def _bilinear_mix(texels, fx, fy):
    """Bilinear blend of the texels (t00, t01, t10, t11) at (y0, x0), (y0, x1), (y1, x0), (y1, x1)."""
    t00, t01, t10, t11 = texels
    top = t00 * (1.0 - fx) + t01 * fx
    bottom = t10 * (1.0 - fx) + t11 * fx
    return top * (1.0 - fy) + bottom * fy


@njit(inline="always")
def _bilinear_slopes(texels, fx, fy):
    """d blend / d fx and d blend / d fy of ``_bilinear_mix``."""
    t00, t01, t10, t11 = texels
    return (t01 - t00) * (1.0 - fy) + (t11 - t10) * fy, (t10 - t00) * (1.0 - fx) + (t11 - t01) * fx


@njit(inline="always")
def _texel_corners(texture, x0, x1, y0, y1, c):
    return texture[y0, x0, c], texture[y0, x1, c], texture[y1, x0, c], texture[y1, x1, c]


@njit(inline="always")
def _uv_at(uvs, bary, uv_corners, p):
    """Interpolated (u, v) of covered pixel p."""
    c0, c1, c2 = uv_corners[p, 0], uv_corners[p, 1], uv_corners[p, 2]
    b0, b1, b2 = bary[p, 0], bary[p, 1], bary[p, 2]
    return b0 * uvs[c0, 0] + b1 * uvs[c1, 0] + b2 * uvs[c2, 0], b0 * uvs[c0, 1] + b1 * uvs[c1, 1] + b2 * uvs[c2, 1]


@serial_and_parallel
def _scatter_texel_grads(uvs, bary, uv_corners, grad_texels, size, grad_maps, row_ranges):
    """Bilinear scatter of grad_texels [N, 7] (diffuse, specular, roughness columns) into the maps' gradients
    ``grad_maps`` (3 arrays [Ht, Wt, C], overwritten; empty ones are skipped). Texel rows are split into
    ``row_ranges`` ranges, one per thread; each zeroes its rows, then scans the pixels in order and adds
    only to its own rows, so every texel sums its pixels in pixel order whatever the number of ranges
    (texels are shared between pixels)."""
    height, width = size
    for part in prange(row_ranges):
        first, last = part * height // row_ranges, (part + 1) * height // row_ranges
        for m in range(len(grad_maps)):
            if grad_maps[m].shape[0] > 0:
                grad_maps[m][first:last] = 0.0
        for p in range(bary.shape[0]):
            u, v = _uv_at(uvs, bary, uv_corners, p)
            y0, fy, _ = _texel_axis(1.0 - v, height)
            y1 = min(y0 + 1, height - 1)
            top, bottom = first <= y0 < last, first <= y1 < last
            if not (top or bottom):
                continue
            x0, fx, _ = _texel_axis(u, width)
            x1 = min(x0 + 1, width - 1)
            column = 0
            for m in range(len(grad_maps)):
                grad_map = grad_maps[m]
                channels = grad_map.shape[2]
                if grad_map.shape[0] > 0:
                    for c in range(channels):
                        g = grad_texels[p, column + c]
                        if top:
                            grad_map[y0, x0, c] += g * (1.0 - fx) * (1.0 - fy)
                            grad_map[y0, x1, c] += g * fx * (1.0 - fy)
                        if bottom:
                            grad_map[y1, x0, c] += g * (1.0 - fx) * fy
                            grad_map[y1, x1, c] += g * fx * fy
                column += channels


# -- dispatch ---------------------------------------------------------------------------------------
sample_texture = register(
    "sample_texture",
    reference=_sample_texture_reference,
    fast=lambda texture, uv: _BilinearLookup.apply(texture, uv.to(texture.dtype)),
    supports=lambda texture, uv: enabled(texture, uv),
)
"""Bilinear lookup of ``texture`` [Ht, Wt, C] at ``uv`` [N, 2] -> [N, C] (v flipped: row 0 is v = 1)."""


def sample_textures(textures: list[torch.Tensor], uv: torch.Tensor) -> list[torch.Tensor]:
    """Bilinear lookups of several maps [Ht, Wt, C_j] (same size) at ``uv`` [N, 2] -> [N, C_j] each."""
    if all(sample_texture.use_fast(texture, uv) for texture in textures):
        return [sample_texture.fast(texture, uv) for texture in textures]
    # torch path: one grid_sample for all maps, its cost is mostly per sample, not per channel
    stacked = sample_texture(torch.cat(textures, -1), uv)
    return list(stacked.split([texture.shape[2] for texture in textures], 1))
