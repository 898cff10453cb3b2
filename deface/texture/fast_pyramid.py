"""The texture pyramid's map, T^0 + sum_l up(g_l * P_l) (deface/texture/pyramid.py), as the op
``pyramid_map``: the torch reference and numba loops as its fast path (deface/render/kernels registers it).

With torch, each level of each map is gated, upsampled by ``F.interpolate`` (bilinear, align_corners False) to
the full size, permuted and added, and the backward runs the same in reverse: 12 upsamplings of 512² maps
and their copies per stage-3 step, ~17 % of it. The fast path runs one loop per level that adds the level's
four bilinear taps to the channel-first sum of the levels (added to T^0 once), and the backward spreads the
gradient back along x, then along y (separable; every sum in a fixed order: deterministic). The taps are
torch's (source index (i + 0.5) s / N - 0.5, clamped at 0). Tested against the reference in float64 with
every op (tests/test_render_kernels.py).
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


def _pyramid_map_reference(initial: torch.Tensor, gates: list[torch.Tensor], *levels: torch.Tensor) -> torch.Tensor:
    """The map by torch ops: each gated level upsampled by ``F.interpolate`` and summed, then added to T^0."""
    size = initial.shape[:2]
    total = torch.zeros_like(initial).permute(2, 0, 1)  # [C, N, N]
    for level, gate in zip(levels, gates, strict=True):
        gated = level * gate
        if gated.shape[-2:] != size:
            gated = F.interpolate(gated[None], size=size, mode="bilinear", align_corners=False)[0]
        total = total + gated
    return initial + total.permute(1, 2, 0)


def bilinear_taps(source: int, target: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each of ``target`` output positions: the two source indices and the weight of the second, as
    torch's bilinear upsampling with align_corners False computes them."""
    position = np.maximum((np.arange(target) + 0.5) * (source / target) - 0.5, 0.0)
    first = np.minimum(np.floor(position).astype(np.int64), source - 1)
    second = np.minimum(first + 1, source - 1)
    return first, second, position - first


class _PyramidMap(torch.autograd.Function):
    @staticmethod
    def forward(ctx, initial, gates, *levels):
        size = initial.shape[0]
        arrays = [_numpy(gate) for gate in gates]
        taps = [bilinear_taps(level.shape[-1], size) for level in levels]
        total = np.zeros((initial.shape[2], size, size), dtype=_numpy(initial).dtype)  # [C, N, N]
        for level, gate, tap in zip(levels, arrays, taps, strict=True):
            gated = _numpy(level) * gate.astype(total.dtype)  # [C, s, s]
            if gated.shape[-1] == size:
                total += gated
            else:
                _add_upsampled(total, gated, *tap, *tap)
        ctx.save_for_backward(*[torch.from_numpy(a) for a in arrays])
        ctx.taps = taps
        return initial.detach() + torch.from_numpy(total).permute(1, 2, 0)

    @staticmethod
    def backward(ctx, grad):
        grad = np.ascontiguousarray(grad.detach().permute(2, 0, 1).numpy())  # [C, N, N]
        grads = []
        for gate, tap in zip(ctx.saved_tensors, ctx.taps, strict=True):
            side = gate.shape[-1]
            if side == grad.shape[-1]:
                spread = grad
            else:
                spread = np.zeros((grad.shape[0], side, side), dtype=grad.dtype)
                _spread_upsampled(grad, *tap, *tap, spread)
            grads.append(torch.from_numpy(spread * gate.numpy().astype(grad.dtype)))
        return None, None, *grads


def _numpy(tensor: torch.Tensor) -> np.ndarray:
    return tensor.detach().contiguous().numpy()


pyramid_map = kernels.register(
    "pyramid_map",
    reference=_pyramid_map_reference,
    fast=_PyramidMap.apply,
    supports=lambda initial, gates, *levels: kernels.enabled(initial) and initial.dtype in (torch.float32,
                                                                                            torch.float64),
)
"""T^0 [N, N, C] + sum_l up(gates[l] [s, s] * levels[l] [C, s, s]), differentiable in the levels:
``pyramid_map(initial, gates, *levels)``."""


if njit is not None:

    @njit(cache=True)
    def _add_upsampled(total, level, y0, y1, wy, x0, x1, wx):
        """total [C, N, N] += bilinear upsampling of level [C, s, s] (taps per output row and column)."""
        for c in range(total.shape[0]):
            for y in range(total.shape[1]):
                top, bottom, v = level[c, y0[y]], level[c, y1[y]], wy[y]
                for x in range(total.shape[2]):
                    c0, c1, u = x0[x], x1[x], wx[x]
                    upper = top[c0] + u * (top[c1] - top[c0])
                    lower = bottom[c0] + u * (bottom[c1] - bottom[c0])
                    total[c, y, x] += upper + v * (lower - upper)

    @njit(cache=True)
    def _spread_upsampled(grad, y0, y1, wy, x0, x1, wx, out):
        """out [C, s, s] = the adjoint of the upsampling applied to grad [C, N, N]: along x, then along y."""
        channels, size, side = grad.shape[0], grad.shape[1], out.shape[1]
        row = np.zeros(side, dtype=grad.dtype)
        for c in range(channels):
            for y in range(size):
                row[:] = 0
                for x in range(size):
                    row[x0[x]] += (1 - wx[x]) * grad[c, y, x]
                    row[x1[x]] += wx[x] * grad[c, y, x]
                for k in range(side):
                    out[c, y0[y], k] += (1 - wy[y]) * row[k]
                    out[c, y1[y], k] += wy[y] * row[k]
