"""Pixel shading under K SH lights: every screen buffer of the covered pixels from per-vertex values, UV
maps and per-vertex specular band sums (the renderer's pixel stage when the specular lobe is on).

Per covered pixel p with corners i (barycentrics b_i): the per-vertex values ``plain`` [U, PLAIN] (named
slices ``PLAIN_SLICES``: irradiance [3K], normal [3], camera z [1], visibility [1]) and band sums S
[U, B, 3K] are interpolated; the three maps are looked up bilinearly at the interpolated uv; the Phong
filter Lambda_l(roughness) gives lit = sum_l Lambda_l S_l, and
    image_k = irradiance_k * diffuse / pi + lit_k * visibility * specular.

Reference: the ops ``interpolate``, ``filtered_interpolation``, ``sample_texture`` and torch products.
Fast: one fused pass per pixel (``_shade_forward``); its backward is one pass over the pixels that also
scatters the per-vertex gradients, in pixel order into _SCATTER_PARTS per-range buffers summed in order,
and the texel gradients through ``texture._scatter_texel_grads``: the same result for any thread count.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from deface.render.kernels.base import _array, _pick, enabled, njit, prange, register, serial_and_parallel, thread_count
from deface.render.kernels.interpolation import _interpolate_row, filtered_interpolation, interpolate
from deface.render.kernels.texture import (
    _bilinear_sample,
    _bilinear_setup,
    _bilinear_slopes,
    _scatter_texel_grads,
    _texel_corners,
    _uv_at,
    sample_textures,
)

SCREEN_CHANNELS = (2, 3, 1, 3, 3, 1)
"""Channels of the screen buffers ``shade`` writes besides the images: uv, normals, depth, diffuse,
specular, roughness."""

SCREEN_BUFFERS = ("uv", "normals", "depth", "diffuse", "specular", "roughness")
"""Names of those buffers (RenderOutput's fields), in ``shade``'s output order after the images."""


_NORMAL, _DEPTH, _VISIBILITY = 0, 3, 4
"""Offsets of the normal [3], camera z [1] and visibility [1] columns of ``plain`` after the 3K irradiance
columns (the kernels read them as values[3K + offset])."""


def plain_slices(lights: int) -> dict[str, slice]:
    """Named column slices of the per-vertex ``plain`` values for ``lights`` lights."""
    irradiance = 3 * lights
    return {
        "irradiance": slice(0, irradiance),
        "normal": slice(irradiance + _NORMAL, irradiance + _NORMAL + 3),
        "depth": slice(irradiance + _DEPTH, irradiance + _DEPTH + 1),
        "visibility": slice(irradiance + _VISIBILITY, irradiance + _VISIBILITY + 1),
    }


def plain_values(irradiance, normal, depth, visibility) -> torch.Tensor:
    """The per-vertex ``plain`` [U, 3K + 5] from its named parts (layout of ``plain_slices``)."""
    return torch.cat([irradiance, normal, depth, visibility], 1)


def to_screen(values: torch.Tensor, covered: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
    """Covered pixels' values [N, C] -> [H, W, C], zeros elsewhere."""
    height, width = size
    full = torch.zeros(height * width, values.shape[1], dtype=values.dtype, device=values.device)
    return full.index_copy(0, covered, values).reshape(height, width, -1)


# -- torch reference --------------------------------------------------------------------------------
def radiance(irradiance, diffuse, lit, visibility, specular) -> torch.Tensor:
    """Diffuse plus shadowed specular radiance of the covered pixels, [N, K*3]:
    irradiance [N, K*3] * diffuse [N, 3] / pi + lit [N, K*3] * visibility [N, 1] * specular [N, 3]."""
    num = irradiance.shape[0]
    diffuse_part = irradiance.reshape(num, -1, 3) * (diffuse / math.pi)[:, None]
    return (diffuse_part + (lit * visibility).reshape(num, -1, 3) * specular[:, None]).reshape(num, -1)


def phong_lobe_filter(roughness: torch.Tensor, bands: int) -> torch.Tensor:
    """SH filter of a normalised Phong lobe around the reflection direction, [...] -> [..., bands].

    Lambda_l = exp(-l² / (2 s)) (Ramamoorthi & Hanrahan 2001, "A signal-processing framework for
    inverse rendering", Phong BRDF in frequency space), with the Phong exponent from the Beckmann
    roughness alpha by s = 2 / alpha² - 2 (Walter et al. 2007, "Microfacet models for refraction").
    Lambda_0 = 1, so a constant environment L reflects k_s L. alpha is clamped to [1e-3, 1].
    """
    alpha = roughness.clamp(1e-3, 1.0)
    exponent = (2.0 / (alpha * alpha) - 2.0).clamp_min(1e-4)  # [...]
    l_sq = torch.arange(bands, dtype=roughness.dtype, device=roughness.device) ** 2
    return torch.exp(-l_sq / (2.0 * exponent[..., None]))


def _shade_reference(plain, bands_v, uvs, bary, diffuse_map, specular_map, roughness_map, pixels, size):
    """``shade`` in torch ops (the arguments and outputs of ``shade``)."""
    covered, corners, uv_corners = pixels
    num_channels, bands = bands_v.shape[2], bands_v.shape[1]
    parts = plain_slices(num_channels // 3)
    values = interpolate(plain, corners, bary)  # [N, 3K + 5]
    normals = values[:, parts["normal"]]
    normals = normals / normals.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    uv = interpolate(uvs, uv_corners, bary)  # [N, 2]
    diffuse, specular, roughness = sample_textures([diffuse_map, specular_map, roughness_map], uv)
    lobe = phong_lobe_filter(roughness[:, 0], bands).to(plain.dtype)  # [N, B], per-texel roughness
    lit = filtered_interpolation(bands_v.reshape(bands_v.shape[0], -1), corners, bary, lobe)  # [N, K*3]
    shaded = radiance(values[:, parts["irradiance"]], diffuse, lit, values[:, parts["visibility"]], specular)
    height, width = size
    images = to_screen(shaded, covered, size).reshape(height, width, -1, 3).permute(2, 0, 1, 3)
    buffers = (uv, normals, values[:, parts["depth"]], diffuse, specular, roughness)
    screens = [to_screen(b, covered, size) for b in buffers]
    screens[2] = screens[2][..., 0]  # depth is [H, W]
    return (images, *screens)


# -- fast path ----------------------------------------------------------------------------------------
def shade_forward(plain, bands_v, uvs, bary, textures, pixels, size):
    """Every screen buffer of the covered pixels in one pass (renderer._KernelShade has the formulas).

    plain [U, 3K+5] per-vertex (irradiance, normal, camera z, visibility), bands_v [U, B, 3K] specular
    band sums, uvs [Nuv, 2], bary [N, 3], textures (diffuse, specular, roughness) [Ht, Wt, C],
    pixels = (flat pixel index [N], vertex corners [N, 3], uv corners [N, 3]), size = (H, W).
    Returns images [K, H, W, 3] and the six screen buffers [H, W, C] of SCREEN_CHANNELS (0 elsewhere), and
    the filtered specular radiance per unit k_s [N, 3K] (float64 numpy) that ``shade_backward`` reuses.
    """
    arrays = [_array(t) for t in (plain, bands_v, uvs, bary, *textures)]
    covered, corners, uv_corners = (_array(t) for t in pixels)
    dtype = arrays[0].dtype
    height, width = size
    images = np.zeros((bands_v.shape[2] // 3, height, width, 3), dtype=dtype)
    screens = [np.zeros((height, width, c), dtype=dtype) for c in SCREEN_CHANNELS]
    lit = np.empty((bary.shape[0], bands_v.shape[2]))  # float64, exactly what the images used
    _pick(_shade_forward)(*arrays, covered, corners, uv_corners, images, *screens, lit)
    screens[2] = screens[2][..., 0]  # depth is [H, W]
    return [torch.from_numpy(a) for a in (images, *screens)], lit


def shade_backward(plain, bands_v, uvs, bary, textures, pixels, width, grads, need_textures, lit):
    """Gradients of ``shade_forward`` from the output gradients ``grads`` (None where unused); ``lit`` is
    what ``shade_forward`` returned with the images.

    Returns (grad plain [U, P], grad bands_v [U, B, 3K], grad bary [N, 3], texture grads (None where
    ``need_textures`` is False)). The per-vertex gradients are scattered from the pixels in pixel order
    into _SCATTER_PARTS buffers (one per contiguous range of pixels, summed in order afterwards), so
    they are the same for any number of threads.
    """
    arrays = [_array(t) for t in (plain, bands_v, uvs, bary, *textures)]
    covered, corners, uv_corners = (_array(t) for t in pixels)
    dtype = arrays[0].dtype
    num, bands, channels = bary.shape[0], bands_v.shape[1], bands_v.shape[2]
    given = np.array([g is not None for g in grads])
    outputs = [
        _array(g) if g is not None else np.zeros((1,) * ndim, dtype=dtype)
        for g, ndim in zip(grads, (4, 3, 3, 2, 3, 3, 3), strict=True)
    ]
    used = plain.shape[0]
    grad_plain = np.empty((_SCATTER_PARTS, used, plain.shape[1]), dtype=dtype)
    grad_bands = np.empty((_SCATTER_PARTS, used, bands * channels), dtype=dtype)
    grad_texels = np.empty((num, 7), dtype=dtype)  # d loss / d (diffuse, specular, roughness) samples
    grad_bary = np.empty((num, 3), dtype=dtype)
    scattered = (grad_plain, grad_bands, grad_texels, grad_bary)
    _pick(_shade_backward)(*arrays, covered, corners, uv_corners, width, given, *outputs, lit, *scattered)
    texture_grads = [
        np.empty(texture.shape if need else (0, 0, texture.shape[2]), dtype=dtype)  # zeroed by the scatter
        for texture, need in zip(arrays[4:], need_textures, strict=True)
    ]
    if any(need_textures):  # one pass for the three maps (they share the texel set-up)
        _pick(_scatter_texel_grads)(
            arrays[2], arrays[3], uv_corners, grad_texels, arrays[4].shape[:2], tuple(texture_grads), thread_count()
        )
    texture_grads = [torch.from_numpy(g) if g.size else None for g in texture_grads]
    grad_vertex, grad_bands = _sum_parts(grad_plain), _sum_parts(grad_bands).reshape(used, bands, channels)
    return torch.from_numpy(grad_vertex), torch.from_numpy(grad_bands), torch.from_numpy(grad_bary), texture_grads


_SCATTER_PARTS = 2
"""Contiguous pixel ranges whose per-vertex gradients are accumulated separately (in parallel on 2 threads)."""


def _sum_parts(parts: np.ndarray) -> np.ndarray:
    """parts [P, U, ...] summed in index order -> [U, ...] (into parts[0]; rows in parallel)."""
    flat = parts.reshape(parts.shape[0], parts.shape[1], -1)
    _pick(_sum_rows)(flat)
    return parts[0]


class _KernelShade(torch.autograd.Function):
    """The numba path of ``Renderer.shade``'s pixel stage, fused: per covered pixel it interpolates the
    per-vertex values, looks up the three maps, applies the Phong filter and writes every screen buffer;
    the backward is one pass over the pixels that also scatters the per-vertex gradients (shade_backward).

    Inputs: plain [U, K*3 + 5] (irradiance, normal, camera z, visibility per used vertex), bands_v
    [U, B, K*3], uvs [Nuv, 2], bary [N, 3], the diffuse / specular / roughness maps; pixels = (covered
    [N], corners [N, 3] into U, uv corners [N, 3]); size = (H, W). The formulas are those of the torch
    path of ``shade`` (the reference, compared in tests/test_render_kernels.py).
    """

    @staticmethod
    def forward(ctx, plain, bands_v, uvs, bary, diffuse, specular, roughness, pixels, size):
        ctx.set_materialize_grads(False)
        ctx.save_for_backward(plain, bands_v, uvs, bary, diffuse, specular, roughness)
        maps = (diffuse, specular, roughness)
        outputs, ctx.lit = shade_forward(plain, bands_v, uvs, bary, maps, pixels, size)
        ctx.pixels, ctx.width = pixels, size[1]
        return tuple(outputs)

    @staticmethod
    def backward(ctx, *grads):
        plain, bands_v, uvs, bary, *maps = ctx.saved_tensors
        grad_plain, grad_bands, grad_bary, grad_maps = shade_backward(
            plain, bands_v, uvs, bary, maps, ctx.pixels, ctx.width, grads, ctx.needs_input_grad[4:7], ctx.lit
        )
        return grad_plain, grad_bands, None, grad_bary, *grad_maps, None, None


@njit(inline="always")
def _pixel_inputs(plain, flat_bands, uvs, bary, roughness_map, p, corners, uv_corners, values, summed, lobe, lit):
    """What forward and backward both need at covered pixel p: the interpolated per-vertex values and
    band sums (into ``values``, ``summed``), the Phong filter and filtered specular (``lobe``, ``lit``);
    returns u, v, the bilinear set-up, the roughness, the exponent and d exponent / d roughness (one flat
    tuple: nested tuples trip numba's parfor analysis)."""
    _interpolate_row(plain, corners, bary, p, values)
    _interpolate_row(flat_bands, corners, bary, p, summed)
    u, v = _uv_at(uvs, bary, uv_corners, p)
    x0, x1, fx, slope_x, y0, y1, fy, slope_y = _bilinear_setup(u, v, roughness_map.shape[0], roughness_map.shape[1])
    roughness = _bilinear_sample(roughness_map, x0, x1, fx, y0, y1, fy, 0)
    exponent, d_exponent = _phong_lobe(roughness, lobe)
    _filter_bands(summed, lobe, lit)
    return u, v, x0, x1, fx, slope_x, y0, y1, fy, slope_y, roughness, exponent, d_exponent


@njit(inline="always")
def _phong_lobe(roughness, lobe):
    """phong_lobe_filter into ``lobe`` [B]; returns the exponent s and d s / d roughness."""
    alpha, d_alpha = roughness, 1.0
    if roughness < 1e-3:
        alpha, d_alpha = 1e-3, 0.0
    elif roughness > 1.0:
        alpha, d_alpha = 1.0, 0.0
    exponent = 2.0 / (alpha * alpha) - 2.0
    d_exponent = -4.0 / (alpha * alpha * alpha) * d_alpha
    if exponent < 1e-4:
        exponent, d_exponent = 1e-4, 0.0
    # lobe_l = q^(l²) with q = exp(-1 / (2 s)): one exp per pixel, then q^(2l - 1) step by step
    q = np.exp(-1.0 / (2.0 * exponent))
    lobe[0], step = 1.0, q
    for l in range(1, lobe.shape[0]):  # noqa: E741
        lobe[l] = lobe[l - 1] * step
        step *= q * q
    return exponent, d_exponent


@njit(inline="always")
def _filter_bands(summed, lobe, lit):
    """lit [C] = sum_l lobe[l] summed[l*C : (l+1)*C] (band-major rows, vectorised along C)."""
    channels = lit.shape[0]
    lit[:] = 0.0
    for l in range(lobe.shape[0]):  # noqa: E741
        weight = lobe[l]
        for j in range(channels):
            lit[j] += weight * summed[l * channels + j]


@serial_and_parallel
def _shade_forward(
    plain,
    bands_v,
    uvs,
    bary,
    diffuse_map,
    specular_map,
    roughness_map,
    covered,
    corners,
    uv_corners,
    images,
    uv_out,
    normal_out,
    depth_out,
    diffuse_out,
    specular_out,
    roughness_out,
    lit_out,
):
    num_channels, bands = bands_v.shape[2], bands_v.shape[1]
    lights = num_channels // 3
    width = images.shape[2]
    flat_bands = bands_v.reshape(bands_v.shape[0], bands * num_channels)
    for block in prange((bary.shape[0] + 255) // 256):
        values, summed = np.empty(plain.shape[1], plain.dtype), np.empty(bands * num_channels, plain.dtype)
        lobe, lit = np.empty(bands), np.empty(num_channels)
        diffuse, specular = np.empty(3), np.empty(3)
        for p in range(block * 256, min(bary.shape[0], (block + 1) * 256)):
            y, x = covered[p] // width, covered[p] % width
            u, v, x0, x1, fx, _, y0, y1, fy, _, roughness, _, _ = _pixel_inputs(
                plain, flat_bands, uvs, bary, roughness_map, p, corners, uv_corners, values, summed, lobe, lit
            )
            visibility = values[num_channels + _VISIBILITY]
            lit_out[p, :] = lit
            for c in range(3):
                diffuse[c] = _bilinear_sample(diffuse_map, x0, x1, fx, y0, y1, fy, c)
                specular[c] = _bilinear_sample(specular_map, x0, x1, fx, y0, y1, fy, c)
                diffuse_out[y, x, c], specular_out[y, x, c] = diffuse[c], specular[c]
            # lights outside, channels inside: contiguous writes (a channel-outer loop was vectorised
            # across the lights into gathers and scatters, slow on this CPU)
            for k in range(lights):
                for c in range(3):
                    j = 3 * k + c
                    images[k, y, x, c] = values[j] * (diffuse[c] / np.pi) + lit[j] * visibility * specular[c]
            norm = np.sqrt(
                values[num_channels + _NORMAL] ** 2
                + values[num_channels + _NORMAL + 1] ** 2
                + values[num_channels + _NORMAL + 2] ** 2
            )
            norm = max(norm, 1e-12)
            for a in range(3):
                normal_out[y, x, a] = values[num_channels + _NORMAL + a] / norm
            uv_out[y, x, 0], uv_out[y, x, 1] = u, v
            depth_out[y, x, 0] = values[num_channels + _DEPTH]
            roughness_out[y, x, 0] = roughness


@serial_and_parallel
def _shade_backward(
    plain,
    bands_v,
    uvs,
    bary,
    diffuse_map,
    specular_map,
    roughness_map,
    covered,
    corners,
    uv_corners,
    width,
    given,
    g_images,
    g_uv,
    g_normal,
    g_depth,
    g_diffuse,
    g_specular,
    g_roughness,
    lit_saved,
    grad_plain,
    grad_bands,
    grad_texels,
    grad_bary,
):
    """One pass over the pixels; scatters the vertex gradients into grad_plain / grad_bands [parts, U, .]
    (part k holds the k-th contiguous range of pixels, accumulated in pixel order)."""
    num_channels, bands = bands_v.shape[2], bands_v.shape[1]
    lights, row = num_channels // 3, bands * num_channels
    flat_bands = bands_v.reshape(bands_v.shape[0], row)
    parts, num = grad_plain.shape[0], bary.shape[0]
    for part in prange(parts):
        grad_plain[part] = 0.0
        grad_bands[part] = 0.0
        values, g_values = np.empty(plain.shape[1]), np.empty(plain.shape[1])
        lobe, g_lit = np.empty(bands), np.empty(num_channels)
        # d loss / d summed[l*C + j] = lobe_l g_lit_j, and the same times l² (for d lobe / d exponent)
        g_summed, g_summed_l2 = np.empty(row), np.empty(row)
        spec_bary = np.empty(3)  # d loss / d bary through the specular band sums
        diffuse_pi, specular, g_irradiance, g_specular_c = np.empty(3), np.empty(3), np.empty(3), np.empty(3)
        for p in range(part * num // parts, (part + 1) * num // parts):
            y, x = covered[p] // width, covered[p] % width
            _interpolate_row(plain, corners, bary, p, values)
            u, v = _uv_at(uvs, bary, uv_corners, p)
            x0, x1, fx, slope_x, y0, y1, fy, slope_y = _bilinear_setup(
                u, v, roughness_map.shape[0], roughness_map.shape[1]
            )
            roughness = _bilinear_sample(roughness_map, x0, x1, fx, y0, y1, fy, 0)
            exponent, d_exponent = _phong_lobe(roughness, lobe)
            visibility = values[num_channels + _VISIBILITY]
            g_visibility = 0.0
            d_fx, d_fy = 0.0, 0.0  # d loss / d bilinear fractions, summed over the three maps
            for c in range(3):
                diffuse_pi[c] = _bilinear_sample(diffuse_map, x0, x1, fx, y0, y1, fy, c) / np.pi
                specular[c] = _bilinear_sample(specular_map, x0, x1, fx, y0, y1, fy, c)
                g_irradiance[c] = 0.0  # sum_k g * irradiance_k, times 1/pi below (one division per channel)
                g_specular_c[c] = g_specular[y, x, c] if given[5] else 0.0
            g_lit[:] = 0.0
            g_values[:num_channels] = 0.0
            if given[0]:  # lights outside, channels inside: contiguous, no gathers (see _shade_forward)
                for k in range(lights):
                    for c in range(3):
                        j = 3 * k + c
                        g = g_images[k, y, x, c]
                        g_values[j] = g * diffuse_pi[c]
                        g_irradiance[c] += g * values[j]
                        g_lit[j] = g * visibility * specular[c]
                        g_visibility += g * lit_saved[p, j] * specular[c]
                        g_specular_c[c] += g * lit_saved[p, j] * visibility
            for c in range(3):
                g_d = g_irradiance[c] / np.pi + (g_diffuse[y, x, c] if given[4] else 0.0)
                g_s = g_specular_c[c]
                grad_texels[p, c], grad_texels[p, 3 + c] = g_d, g_s
                slope_fx, slope_fy = _bilinear_slopes(_texel_corners(diffuse_map, x0, x1, y0, y1, c), fx, fy)
                d_fx, d_fy = d_fx + g_d * slope_fx, d_fy + g_d * slope_fy
                slope_fx, slope_fy = _bilinear_slopes(_texel_corners(specular_map, x0, x1, y0, y1, c), fx, fy)
                d_fx, d_fy = d_fx + g_s * slope_fx, d_fy + g_s * slope_fy
            for l in range(bands):  # noqa: E741
                for j in range(num_channels):
                    g_summed[l * num_channels + j] = lobe[l] * g_lit[j]
                    g_summed_l2[l * num_channels + j] = lobe[l] * g_lit[j] * (l * l)
            # normals: n / max(|n|, 1e-12)
            norm = np.sqrt(
                values[num_channels + _NORMAL] ** 2
                + values[num_channels + _NORMAL + 1] ** 2
                + values[num_channels + _NORMAL + 2] ** 2
            )
            clamped = max(norm, 1e-12)
            dot = 0.0
            for a in range(3):
                g_n = g_normal[y, x, a] if given[2] else 0.0
                g_values[num_channels + _NORMAL + a] = g_n / clamped
                dot += g_n * values[num_channels + _NORMAL + a]
            if norm >= 1e-12:
                for a in range(3):
                    n_a = values[num_channels + _NORMAL + a]
                    g_values[num_channels + _NORMAL + a] -= dot / (clamped * clamped) * n_a / norm
            g_values[num_channels + _DEPTH] = g_depth[y, x] if given[3] else 0.0
            g_values[num_channels + _VISIBILITY] = g_visibility
            # lobe_l = exp(-l² / (2 s)): d lobe_l / d s = lobe_l l² / (2 s²); the band sums are interpolated,
            # so d loss / d s = sum_i bary_i sum_lj S[corner_i, lj] lobe_l l² g_lit_j / (2 s²)
            g_exponent = 0.0
            for i in range(3):
                vertex = corners[p, i]
                to_bary, to_exponent = 0.0, 0.0
                for k in range(row):
                    to_bary += flat_bands[vertex, k] * g_summed[k]
                    to_exponent += flat_bands[vertex, k] * g_summed_l2[k]
                spec_bary[i] = to_bary
                g_exponent += bary[p, i] * to_exponent
            g_r = g_exponent / (2.0 * exponent * exponent) * d_exponent
            g_r += g_roughness[y, x, 0] if given[6] else 0.0
            grad_texels[p, 6] = g_r
            slope_fx, slope_fy = _bilinear_slopes(_texel_corners(roughness_map, x0, x1, y0, y1, 0), fx, fy)
            d_fx, d_fy = d_fx + g_r * slope_fx, d_fy + g_r * slope_fy
            g_u = d_fx * slope_x + (g_uv[y, x, 0] if given[1] else 0.0)
            g_v = -d_fy * slope_y + (g_uv[y, x, 1] if given[1] else 0.0)
            for i in range(3):
                vertex, weight = corners[p, i], bary[p, i]
                total = g_u * uvs[uv_corners[p, i], 0] + g_v * uvs[uv_corners[p, i], 1] + spec_bary[i]
                for c in range(plain.shape[1]):
                    total += plain[vertex, c] * g_values[c]
                    grad_plain[part, vertex, c] += weight * g_values[c]
                for k in range(row):
                    grad_bands[part, vertex, k] += weight * g_summed[k]
                grad_bary[p, i] = total


@serial_and_parallel
def _sum_rows(parts):
    """parts[0] += parts[1] + ... (in index order), [P, U, C], one row per iteration."""
    for u in prange(parts.shape[1]):
        for k in range(1, parts.shape[0]):
            for c in range(parts.shape[2]):
                parts[0, u, c] += parts[k, u, c]


# -- dispatch ---------------------------------------------------------------------------------------
def _shade_supported(plain, bands_v, uvs, bary, diffuse, specular, roughness, pixels, size) -> bool:
    """One dtype, one map size (one bilinear set-up serves the three maps), fixed uvs."""
    maps = (diffuse, specular, roughness)
    return (
        not uvs.requires_grad
        and enabled(plain, bary, *maps)
        and len({t.dtype for t in (plain, bands_v, bary, *maps)}) == 1
        and len({t.shape[:2] for t in maps}) == 1
    )


shade = register("shade", reference=_shade_reference, fast=_KernelShade.apply, supports=_shade_supported)
"""Every screen buffer of the covered pixels: plain [U, 3K+5] (``plain_slices``), bands_v [U, B, 3K]
specular band sums, uvs [Nuv, 2], bary [N, 3], the diffuse [Ht, Wt, 3], specular [Ht, Wt, 3] and
roughness [Ht, Wt, 1] maps, pixels = (flat pixel index [N], vertex corners [N, 3] into U, uv corners
[N, 3]), size = (H, W) -> images [K, H, W, 3] and the SCREEN_BUFFERS [H, W, C] (depth [H, W]), 0 where
no pixel is covered."""
