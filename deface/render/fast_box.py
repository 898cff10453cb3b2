"""Block means for the supersampled renders (deface/render/supersample.py): the op ``block_mean``, the
torch reference (avg_pool2d) and a numba loop as its fast path (deface/render/kernels registers it).

With torch each channel-last buffer is permuted to channel-first, copied, pooled by avg_pool2d and permuted
back, forward and backward; a stage-3 step pools ~22 channels at 512² that way (~15 % of its time). The loop
reads the channel-last layout directly. Its forward sums each block in row-major order and divides by its
size (avg_pool2d's formula); its backward spreads grad / size over the block. Deterministic: every output
element is written by one iteration. Tested against the reference with every op (tests/test_render_kernels.py).
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from deface.render import kernels

try:
    from numba import njit
except ImportError:  # pragma: no cover - exercised only where numba is missing
    njit = None


def _block_mean_reference(values: torch.Tensor, factor: int) -> torch.Tensor:
    """avg_pool2d over the channel-first view of [..., sH, sW, C]."""
    lead, (height, width, channels) = values.shape[:-3], values.shape[-3:]
    planes = values.reshape(-1, height, width, channels).permute(0, 3, 1, 2)
    pooled = F.avg_pool2d(planes, factor)
    return pooled.permute(0, 2, 3, 1).reshape(*lead, height // factor, width // factor, channels)


class _BlockMean(torch.autograd.Function):
    @staticmethod
    def forward(ctx, values, factor):
        lead, (height, width, channels) = values.shape[:-3], values.shape[-3:]
        flat = values.detach().reshape(-1, height, width, channels).contiguous().numpy()
        out = np.empty((flat.shape[0], height // factor, width // factor, channels), dtype=flat.dtype)
        _block_mean(flat, factor, out)
        ctx.factor, ctx.shape = factor, values.shape
        return torch.from_numpy(out).reshape(*lead, height // factor, width // factor, channels)

    @staticmethod
    def backward(ctx, grad):
        height, width, channels = ctx.shape[-3:]
        flat = grad.detach().reshape(-1, height // ctx.factor, width // ctx.factor, channels).contiguous().numpy()
        out = np.empty((flat.shape[0], height, width, channels), dtype=flat.dtype)
        _block_spread(flat, ctx.factor, out)
        return torch.from_numpy(out).reshape(ctx.shape), None


block_mean = kernels.register(
    "block_mean",
    reference=_block_mean_reference,
    fast=_BlockMean.apply,
    supports=lambda values, factor: kernels.enabled(values) and values.dtype in (torch.float32, torch.float64),
)
"""Mean of each ``factor`` x ``factor`` block: [..., sH, sW, C] -> [..., H, W, C]."""


if njit is not None:

    @njit(cache=True)
    def _block_mean(values, factor, out):
        scale = 1.0 / (factor * factor)
        for layer in range(out.shape[0]):
            for i in range(out.shape[1]):
                for j in range(out.shape[2]):
                    for c in range(out.shape[3]):
                        total = values[layer, i * factor, j * factor, c] * 0.0
                        for a in range(factor):
                            for b in range(factor):
                                total += values[layer, i * factor + a, j * factor + b, c]
                        out[layer, i, j, c] = total * scale

    @njit(cache=True)
    def _block_spread(grad, factor, out):
        scale = 1.0 / (factor * factor)
        for layer in range(grad.shape[0]):
            for y in range(out.shape[1]):
                for x in range(out.shape[2]):
                    for c in range(out.shape[3]):
                        out[layer, y, x, c] = grad[layer, y // factor, x // factor, c] * scale
