"""Perspective-correct barycentrics of the covered pixels' centres in their triangles (2-D edge functions
at the pixel centre, divided by the corners' camera depths), differentiable in the projected vertices and
their depths.

Reference: torch gathers and products. Fast: one loop per pixel for the values and the per-pixel corner
gradients, then one serial scatter to the vertices in pixel order (deterministic).
"""

from __future__ import annotations

import numpy as np
import torch

from deface.render.kernels.base import _array, _pick, enabled, njit, prange, register, serial_and_parallel


# -- torch reference --------------------------------------------------------------------------------
def _barycentrics_reference(pixels: torch.Tensor, depth: torch.Tensor, covered: tuple) -> torch.Tensor:
    """Barycentrics [N, 3] from the vertices projected to ``pixels`` [V, 2] with camera ``depth`` [V];
    covered = (triangles [F, 3], triangle id [N] and flat index y * W + x [N] per pixel, (H, W))."""
    triangles, tri, flat_index, (_, width) = covered
    corners = triangles.index_select(0, tri)  # [N, 3]
    q = torch.stack([flat_index % width, flat_index // width], -1).to(pixels.dtype) + 0.5  # [N, 2]
    flat = corners.reshape(-1)
    p = pixels.index_select(0, flat).reshape(-1, 3, 2)  # [N, 3, 2]
    z = depth.index_select(0, flat).reshape(-1, 3)  # [N, 3]

    def cross2(a, b):
        return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]

    d0, d1, d2 = p[:, 0] - q, p[:, 1] - q, p[:, 2] - q
    screen = torch.stack([cross2(d1, d2), cross2(d2, d0), cross2(d0, d1)], -1)  # [N, 3] ~ 2 x areas
    area = screen.sum(-1, keepdim=True)
    tiny = torch.finfo(p.dtype).tiny
    area = torch.where(area.abs() < tiny, torch.full_like(area, tiny), area)
    weights = screen / area / z  # perspective correction: screen barycentrics / depth
    return weights / weights.sum(-1, keepdim=True)


# -- fast path ----------------------------------------------------------------------------------------
def barycentrics_forward(pixels, depth, covered) -> torch.Tensor:
    """Perspective-correct barycentrics [N, 3] (renderer._barycentrics' formula) of the covered pixels'
    centres in their triangles, from the vertices projected to ``pixels`` [V, 2] with camera depths ``depth``
    [V]; covered = (triangles [F, 3], triangle id [N] and flat index y * W + x [N] per pixel, (H, W))."""
    p = _array(pixels)
    args = _barycentric_inputs(p, covered)
    out = np.empty((args[1].shape[0], 3), dtype=p.dtype)
    _pick(_barycentrics_forward)(p, _array(depth), *args, np.finfo(p.dtype).tiny, out)
    return torch.from_numpy(out)


def _barycentric_inputs(pixels: np.ndarray, covered) -> tuple:
    """(triangles, triangle ids, flat indices, pixel-centre coordinates x + 0.5 [max(H, W)] in the pixels'
    dtype (the centres' arithmetic stays in that dtype, as in the torch path), W) for the kernels."""
    triangles, tri, flat, (height, width) = covered
    centres = (np.arange(max(height, width)) + 0.5).astype(pixels.dtype)
    return _array(triangles), _array(tri), _array(flat), centres, width


def barycentrics_backward(pixels, depth, covered, grad) -> tuple[torch.Tensor, torch.Tensor]:
    """Gradients of ``barycentrics_forward`` to the projected vertices [V, 2] and their depths [V].

    Per-pixel gradients first (in parallel), then one serial scatter in pixel order (deterministic)."""
    p, z = _array(pixels), _array(depth)
    args = _barycentric_inputs(p, covered)
    num = args[1].shape[0]
    grad_p, grad_z = np.empty((num, 3, 2), dtype=p.dtype), np.empty((num, 3), dtype=z.dtype)
    _pick(_barycentrics_backward)(p, z, *args, np.finfo(p.dtype).tiny, _array(grad), grad_p, grad_z)
    grad_pixels, grad_depth = np.zeros(p.shape, dtype=p.dtype), np.zeros(z.shape, dtype=z.dtype)
    _scatter_corners(args[0], args[1], grad_p, grad_z, grad_pixels, grad_depth)
    return torch.from_numpy(grad_pixels), torch.from_numpy(grad_depth)


class _KernelBarycentrics(torch.autograd.Function):
    """The numba path of ``_barycentrics``: projected vertices [V, 2], their depths [V], and the pixels =
    (triangles [F, 3], triangle id [N] and flat index [N] of each covered pixel, image (H, W)); corners and
    pixel centres are looked up (and the corner gradients scattered) in the kernels."""

    @staticmethod
    def forward(ctx, pixels, depth, covered):
        ctx.save_for_backward(pixels, depth)
        ctx.covered = covered
        return barycentrics_forward(pixels, depth, covered)

    @staticmethod
    def backward(ctx, grad):
        return (*barycentrics_backward(*ctx.saved_tensors, ctx.covered, grad), None)


@njit(inline="always")
def _edge_functions(p, triangles, tri, flat, centres, width, n):
    """Corner indices (i0, i1, i2) of pixel n's triangle, corner offsets d_i = p[i] - q from its centre q
    and s_i = cross(d_{i+1}, d_{i+2}) (~2 x sub-areas), as one flat tuple (i0, i1, i2, d0x, d1x, d2x,
    d0y, d1y, d2y, s0, s1, s2): scalars only, no per-pixel arrays."""
    qx, qy = centres[flat[n] % width], centres[flat[n] // width]
    f = tri[n]
    i0, i1, i2 = triangles[f, 0], triangles[f, 1], triangles[f, 2]
    d0x, d1x, d2x = p[i0, 0] - qx, p[i1, 0] - qx, p[i2, 0] - qx
    d0y, d1y, d2y = p[i0, 1] - qy, p[i1, 1] - qy, p[i2, 1] - qy
    return (
        i0, i1, i2, d0x, d1x, d2x, d0y, d1y, d2y,
        d1x * d2y - d1y * d2x, d2x * d0y - d2y * d0x, d0x * d1y - d0y * d1x,
    )  # fmt: skip


@serial_and_parallel
def _barycentrics_forward(pixels, depth, triangles, tri, flat, centres, width, tiny, out):
    for n in prange(out.shape[0]):
        edges = _edge_functions(pixels, triangles, tri, flat, centres, width, n)
        i0, i1, i2, s0, s1, s2 = edges[0], edges[1], edges[2], edges[9], edges[10], edges[11]
        area = s0 + s1 + s2
        if abs(area) < tiny:
            area = tiny
        w0 = s0 / area / depth[i0]
        w1 = s1 / area / depth[i1]
        w2 = s2 / area / depth[i2]
        total = w0 + w1 + w2
        out[n, 0], out[n, 1], out[n, 2] = w0 / total, w1 / total, w2 / total


@serial_and_parallel
def _barycentrics_backward(pixels, depth, triangles, tri, flat, centres, width, tiny, grad, grad_p, grad_z):
    """Gradients to each pixel's corners: grad_p [N, 3, 2], grad_z [N, 3] (reciprocals: few divisions)."""
    for n in prange(grad.shape[0]):
        edges = _edge_functions(pixels, triangles, tri, flat, centres, width, n)
        d_x, d_y, s = edges[3:6], edges[6:9], edges[9:12]
        area = s[0] + s[1] + s[2]
        degenerate = abs(area) < tiny
        if degenerate:
            area = tiny
        inv_area = 1.0 / area
        inv_z = (1.0 / depth[edges[0]], 1.0 / depth[edges[1]], 1.0 / depth[edges[2]])
        w = (s[0] * inv_area * inv_z[0], s[1] * inv_area * inv_z[1], s[2] * inv_area * inv_z[2])
        inv_total = 1.0 / (w[0] + w[1] + w[2])
        mean = (grad[n, 0] * w[0] + grad[n, 1] * w[1] + grad[n, 2] * w[2]) * inv_total
        grad_area = 0.0
        for i in range(3):
            h = (grad[n, i] - mean) * inv_total  # d loss / d w_i
            grad_z[n, i] = -h * w[i] * inv_z[i]
            grad_area -= h * w[i] * inv_area
            grad_p[n, i, 0], grad_p[n, i, 1] = 0.0, 0.0
        if degenerate:
            grad_area = 0.0
        for i in range(3):  # s_i = d_j.x d_k.y - d_j.y d_k.x
            j, k = (i + 1) % 3, (i + 2) % 3
            g = (grad[n, i] - mean) * inv_total * inv_area * inv_z[i] + grad_area
            grad_p[n, j, 0] += g * d_y[k]
            grad_p[n, j, 1] -= g * d_x[k]
            grad_p[n, k, 0] -= g * d_y[j]
            grad_p[n, k, 1] += g * d_x[j]


@njit(cache=True)
def _scatter_corners(triangles, tri, grad_p, grad_z, grad_pixels, grad_depth):
    for n in range(tri.shape[0]):  # serial, pixel order: vertices are shared between pixels
        for i in range(3):
            v = triangles[tri[n], i]
            grad_pixels[v, 0] += grad_p[n, i, 0]
            grad_pixels[v, 1] += grad_p[n, i, 1]
            grad_depth[v] += grad_z[n, i]


# -- dispatch ---------------------------------------------------------------------------------------
barycentrics = register(
    "barycentrics",
    reference=_barycentrics_reference,
    fast=_KernelBarycentrics.apply,
    supports=lambda pixels, depth, covered: enabled(pixels, depth) and pixels.dtype == depth.dtype,
)
"""Perspective-correct barycentrics [N, 3]: (pixels [V, 2], depth [V], covered = (triangles [F, 3],
triangle id [N], flat pixel index [N], (H, W)))."""
