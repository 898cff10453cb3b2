"""Barycentric interpolation of per-vertex values to the covered pixels, plain (``interpolate``) and
band-filtered (``filtered_interpolation``: out[p] = sum_i bary[p, i] sum_l lobe[p, l] S[corner_i, l]).

Reference: ``index_select`` sums (plain) and a sparse CSR matrix (filtered). Fast: one loop per pixel;
the gradient to the values is gathered per vertex from a counting sort of the corners (thread-count exact).
"""

from __future__ import annotations

import warnings

import numpy as np
import torch

from deface.render.kernels.base import _array, _pick, enabled, njit, prange, register, serial_and_parallel


# -- torch reference --------------------------------------------------------------------------------
def _interpolate_reference(values: torch.Tensor, corners: torch.Tensor, bary: torch.Tensor) -> torch.Tensor:
    """sum_i bary_i values[corners_i]: values [V, C], corners [N, 3], bary [N, 3] -> [N, C]."""
    out = values.index_select(0, corners[:, 0]) * bary[:, :1]
    out = out + values.index_select(0, corners[:, 1]) * bary[:, 1:2]
    return out + values.index_select(0, corners[:, 2]) * bary[:, 2:3]


class _FilteredInterpolation(torch.autograd.Function):
    """Reference (torch) path of ``_filtered_interpolation``: a sparse [N, U*B] matrix with 3B weights
    bary[p, i] lobe[p, l] per pixel times S viewed as [U*B, C].

    No [N, B*C] per-pixel buffer is materialised in the forward pass (such buffers cost more in page
    faults than in arithmetic).
    """

    @staticmethod
    def forward(ctx, values, corners, bary, lobe):
        num, bands = lobe.shape
        channels = values.shape[1] // bands
        weights = (bary[:, :, None] * lobe[:, None, :]).reshape(-1)  # [N*3*B]
        columns = (corners[:, :, None] * bands + torch.arange(bands, device=corners.device)).reshape(-1)
        rows = torch.arange(0, weights.numel() + 1, 3 * bands, device=corners.device)
        matrix = _csr(rows, columns, weights, size=(num, values.shape[0] * bands))
        flat = values.reshape(-1, channels)  # [U*B, C]
        ctx.save_for_backward(values, corners, bary, lobe, rows, columns)
        return matrix @ flat

    @staticmethod
    def backward(ctx, grad):
        values, corners, bary, lobe, rows, columns = ctx.saved_tensors
        num, bands = lobe.shape
        grad = grad.contiguous()
        grad_values = grad_bary = grad_lobe = None
        if ctx.needs_input_grad[2] or ctx.needs_input_grad[3]:
            pattern = _csr(rows, columns, grad.new_zeros(columns.numel()), size=(num, values.shape[0] * bands))
            flat = values.reshape(-1, grad.shape[1])
            # d out[p] / d weight[p, i, l] = S[corner_i, l]: (grad @ S^T) sampled at the sparsity pattern
            grad_weights = torch.sparse.sampled_addmm(pattern, grad, flat.T, beta=0.0).values()
            grad_weights = grad_weights.reshape(num, 3, bands)
            grad_bary = (grad_weights * lobe[:, None, :]).sum(-1)
            grad_lobe = (grad_weights * bary[:, :, None]).sum(1)
        if ctx.needs_input_grad[0]:
            # grad S[v, l] = sum_{(p, i): corner_i(p) = v} bary[p, i] lobe[p, l] grad[p]: a [U, N] CSR
            # matrix of barycentrics (3 per pixel, sorted by vertex) times [N, B*C] lobe-weighted grads
            corner_flat = corners.reshape(-1)
            order = torch.argsort(corner_flat, stable=True)
            counts = torch.bincount(corner_flat, minlength=values.shape[0])
            crow = torch.cat([counts.new_zeros(1), counts.cumsum(0)])
            transpose = _csr(crow, order // 3, bary.reshape(-1)[order], size=(values.shape[0], num))
            weighted = (lobe[:, :, None] * grad[:, None, :]).reshape(num, -1)  # [N, B*C]
            grad_values = transpose @ weighted
        return grad_values, None, grad_bary, grad_lobe


def _csr(rows: torch.Tensor, columns: torch.Tensor, values: torch.Tensor, size: tuple) -> torch.Tensor:
    """A sparse CSR matrix; indices are built by this module, so torch's invariant checks are skipped."""
    with warnings.catch_warnings():  # torch warns that CSR support is "beta" on every construction
        warnings.filterwarnings("ignore", message="Sparse CSR tensor support is in beta state")
        return torch.sparse_csr_tensor(rows, columns, values, size=size, check_invariants=False)


# -- fast path ----------------------------------------------------------------------------------------
def interpolate_forward(values: torch.Tensor, corners: torch.Tensor, bary: torch.Tensor, lobe: torch.Tensor):
    """out[p] = sum_i bary[p, i] sum_l lobe[p, l] values[corners[p, i], l]: values [U, B, C] -> [N, C]."""
    out = np.empty((corners.shape[0], values.shape[2]), dtype=_array(values).dtype)
    _pick(_interpolate_forward)(_array(values), _array(corners), _array(bary), _array(lobe), out)
    return torch.from_numpy(out)


def interpolate_backward_corners(values, corners, bary, lobe, grad):
    """Gradients of ``interpolate_forward`` to bary [N, 3] and lobe [N, B]."""
    num, bands = lobe.shape
    grad_bary = np.empty((num, 3), dtype=_array(values).dtype)
    grad_lobe = np.empty((num, bands), dtype=grad_bary.dtype)
    _pick(_interpolate_backward_corners)(
        _array(values), _array(corners), _array(bary), _array(lobe), _array(grad), grad_bary, grad_lobe
    )
    return torch.from_numpy(grad_bary), torch.from_numpy(grad_lobe)


def interpolate_backward_values(num_vertices: int, corners, bary, lobe, grad):
    """Gradient of ``interpolate_forward`` to values: [U, B, C], gathered per vertex (thread-count exact)."""
    offsets, entries = _corners_by_vertex(_array(corners), num_vertices)
    out = np.empty((num_vertices, lobe.shape[1], grad.shape[1]), dtype=_array(grad).dtype)
    _pick(_interpolate_backward_values)(offsets, entries, _array(bary), _array(lobe), _array(grad), out)
    return torch.from_numpy(out)


class _KernelInterpolation(torch.autograd.Function):
    """The numba path of ``_filtered_interpolation`` (kernels.py); no sparse matrices, no [N, B*C] buffers."""

    @staticmethod
    def forward(ctx, values, corners, bary, lobe):
        ctx.save_for_backward(values, corners, bary, lobe)
        return interpolate_forward(values.reshape(values.shape[0], lobe.shape[1], -1), corners, bary, lobe)

    @staticmethod
    def backward(ctx, grad):
        values, corners, bary, lobe = ctx.saved_tensors
        per_band = values.reshape(values.shape[0], lobe.shape[1], -1)  # [U, B, C]
        grad_values = grad_bary = grad_lobe = None
        if ctx.needs_input_grad[2] or ctx.needs_input_grad[3]:
            grad_bary, grad_lobe = interpolate_backward_corners(per_band, corners, bary, lobe, grad)
        if ctx.needs_input_grad[0]:
            grad_values = interpolate_backward_values(per_band.shape[0], corners, bary, lobe, grad)
            grad_values = grad_values.reshape(values.shape)
        return grad_values, None, grad_bary, grad_lobe


@serial_and_parallel
def _interpolate_forward(values, corners, bary, lobe, out):
    bands, channels = values.shape[1], values.shape[2]
    for p in prange(corners.shape[0]):
        for c in range(channels):
            out[p, c] = 0.0
        for i in range(3):
            v = corners[p, i]
            for l in range(bands):  # noqa: E741
                weight = bary[p, i] * lobe[p, l]
                for c in range(channels):
                    out[p, c] += weight * values[v, l, c]


@serial_and_parallel
def _interpolate_backward_corners(values, corners, bary, lobe, grad, grad_bary, grad_lobe):
    bands, channels = values.shape[1], values.shape[2]
    for p in prange(corners.shape[0]):
        for l in range(bands):  # noqa: E741
            grad_lobe[p, l] = 0.0
        for i in range(3):
            v = corners[p, i]
            total = 0.0
            for l in range(bands):  # noqa: E741
                dot = 0.0
                for c in range(channels):
                    dot += values[v, l, c] * grad[p, c]
                total += lobe[p, l] * dot
                grad_lobe[p, l] += bary[p, i] * dot
            grad_bary[p, i] = total


@njit(cache=True)
def _corners_by_vertex(corners, num_vertices):
    """Counting sort of the flat corner slots p*3+i by vertex: (offsets [U+1], slots [3N]), stable."""
    flat = corners.reshape(-1)
    offsets = np.zeros(num_vertices + 1, dtype=np.int64)
    for k in range(flat.shape[0]):
        offsets[flat[k] + 1] += 1
    for v in range(num_vertices):
        offsets[v + 1] += offsets[v]
    fill = offsets[:-1].copy()
    slots = np.empty(flat.shape[0], dtype=np.int64)
    for k in range(flat.shape[0]):
        slots[fill[flat[k]]] = k
        fill[flat[k]] += 1
    return offsets, slots


@serial_and_parallel
def _interpolate_backward_values(offsets, slots, bary, lobe, grad, out):
    bands, channels = out.shape[1], out.shape[2]
    for v in prange(out.shape[0]):
        for l in range(bands):  # noqa: E741
            for c in range(channels):
                out[v, l, c] = 0.0
        for k in range(offsets[v], offsets[v + 1]):
            p, i = slots[k] // 3, slots[k] % 3
            for l in range(bands):  # noqa: E741
                weight = bary[p, i] * lobe[p, l]
                for c in range(channels):
                    out[v, l, c] += weight * grad[p, c]


@njit(inline="always")
def _interpolate_row(values, corners, bary, p, out):
    """out [C] = sum_i bary[p, i] values[corners[p, i]] for values [U, C] (contiguous, vectorised)."""
    v0, v1, v2 = corners[p, 0], corners[p, 1], corners[p, 2]
    b0, b1, b2 = bary[p, 0], bary[p, 1], bary[p, 2]
    for c in range(out.shape[0]):
        out[c] = b0 * values[v0, c] + b1 * values[v1, c] + b2 * values[v2, c]


# -- dispatch ---------------------------------------------------------------------------------------
def _fast_interpolate(values: torch.Tensor, corners: torch.Tensor, bary: torch.Tensor) -> torch.Tensor:
    return _KernelInterpolation.apply(values, corners, bary, bary.new_ones(bary.shape[0], 1))


interpolate = register(
    "interpolate",
    reference=_interpolate_reference,
    fast=_fast_interpolate,
    supports=lambda values, corners, bary: enabled(values, bary) and values.dtype == bary.dtype,
)
"""sum_i bary_i values[corners_i]: values [V, C], corners [N, 3], bary [N, 3] -> [N, C]."""

filtered_interpolation = register(
    "filtered_interpolation",
    reference=_FilteredInterpolation.apply,
    fast=_KernelInterpolation.apply,
    supports=lambda values, corners, bary, lobe: (
        enabled(values, bary, lobe) and values.dtype == bary.dtype == lobe.dtype
    ),
)
"""out[p] = sum_i sum_l bary[p, i] lobe[p, l] S[corner_i(p), l]: values S [U, B*C] (band-major), corners
[N, 3], bary [N, 3], lobe [N, B] -> [N, C]."""
