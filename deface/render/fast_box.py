"""Block means for the supersampled renders (deface/render/supersample.py), as one numba loop.

``supersample._pool`` with torch permutes each channel-last buffer to channel-first, copies it, runs
avg_pool2d and permutes back, forward and backward; a stage-3 step pools ~22 channels at 512² that way
(~15 % of its time). Here the channel-last layout is read directly. The forward sums each block in row-major
order and divides by its size (avg_pool2d's formula); the backward spreads grad / size over the block.
Deterministic: every output element is written by one iteration. Tested against supersample's torch path
(tests/test_fast_stage3.py).
"""

from __future__ import annotations

import numpy as np
import torch

from deface.render import kernels

try:
    from numba import njit
except ImportError:  # pragma: no cover - exercised only where numba is missing
    njit = None


def enabled(values: torch.Tensor) -> bool:
    """Whether :func:`block_mean` handles ``values`` (the renderer's kernel switch, a float dtype)."""
    return njit is not None and kernels.enabled(values) and values.dtype in (torch.float32, torch.float64)


def block_mean(values: torch.Tensor, factor: int) -> torch.Tensor:
    """Mean of each ``factor`` x ``factor`` block: [..., sH, sW, C] -> [..., H, W, C]."""
    return _BlockMean.apply(values, factor)


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
