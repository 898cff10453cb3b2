"""Mirrored view directions per vertex: r = unit(2 (n.v) n - v), v = unit(centre - x), unit(w) =
w / max(|w|, 1e-12) (the specular band sums are evaluated at r; renderer._specular_bands).

Reference: ~12 small torch ops. Fast: one loop per vertex (the camera-centre gradient is summed in order).
"""

from __future__ import annotations

import numpy as np
import torch

from deface.render.kernels.base import _array, enabled, njit, register


# -- torch reference --------------------------------------------------------------------------------
def _reflect_reference(positions: torch.Tensor, normals: torch.Tensor, centre: torch.Tensor) -> torch.Tensor:
    """positions, normals [U, 3], centre [3] -> r [U, 3]."""
    view = centre - positions
    view = view / view.norm(dim=-1, keepdim=True).clamp_min(1e-12)  # [U, 3] towards the camera
    reflected = 2 * (normals * view).sum(-1, keepdim=True) * normals - view  # [U, 3]
    return reflected / reflected.norm(dim=-1, keepdim=True).clamp_min(1e-12)  # unit for the SH


# -- fast path ----------------------------------------------------------------------------------------
def reflect_forward(positions: torch.Tensor, normals: torch.Tensor, centre: torch.Tensor) -> torch.Tensor:
    """r = unit(2 (n.v) n - v), v = unit(centre - x) per vertex: positions, normals [U, 3], centre [3] -> [U, 3]
    (renderer._specular_bands' formulas; unit(w) = w / max(|w|, 1e-12))."""
    x = _array(positions)
    out = np.empty(x.shape, dtype=x.dtype)
    _reflect(x, _array(normals), _array(centre), out)
    return torch.from_numpy(out)


def reflect_backward(positions, normals, centre, grad) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Gradients of ``reflect_forward`` to positions [U, 3], normals [U, 3] and centre [3] (summed in order)."""
    x = _array(positions)
    grad_x, grad_n = np.empty(x.shape, dtype=x.dtype), np.empty(x.shape, dtype=x.dtype)
    grad_c = np.zeros(3)
    _reflect_vjp(x, _array(normals), _array(centre), _array(grad), grad_x, grad_n, grad_c)
    return torch.from_numpy(grad_x), torch.from_numpy(grad_n), torch.from_numpy(grad_c.astype(x.dtype))


class _KernelReflection(torch.autograd.Function):
    """The numba path of the mirrored view directions in ``_specular_bands`` (the same formulas, one loop
    per vertex instead of ~12 small ops and their backward): positions, normals [U, 3], centre [3]."""

    @staticmethod
    def forward(ctx, positions, normals, centre):
        ctx.save_for_backward(positions, normals, centre)
        return reflect_forward(positions, normals, centre)

    @staticmethod
    def backward(ctx, grad):
        return reflect_backward(*ctx.saved_tensors, grad)


@njit(inline="always")
def _unit(wx, wy, wz):
    """w / max(|w|, 1e-12) and (|w|, the clamped norm)."""
    norm = np.sqrt(wx * wx + wy * wy + wz * wz)
    clamped = max(norm, 1e-12)
    return wx / clamped, wy / clamped, wz / clamped, norm, clamped


@njit(inline="always")
def _unit_vjp(gx, gy, gz, ux, uy, uz, norm, clamped):
    """d loss / d w of u = w / max(|w|, 1e-12) from d loss / d u (the clamp passes no gradient below it)."""
    dot = gx * ux + gy * uy + gz * uz if norm >= 1e-12 else 0.0
    return (gx - ux * dot) / clamped, (gy - uy * dot) / clamped, (gz - uz * dot) / clamped


@njit(inline="always")
def _reflect_at(positions, normals, centre, u):
    """View v = unit(centre - x_u), a = n.v, reflection r = unit(2 a n - v): one flat tuple of scalars."""
    vx, vy, vz, view_norm, view_clamped = _unit(
        centre[0] - positions[u, 0], centre[1] - positions[u, 1], centre[2] - positions[u, 2]
    )
    nx, ny, nz = normals[u, 0], normals[u, 1], normals[u, 2]
    a = nx * vx + ny * vy + nz * vz
    rx, ry, rz, norm, clamped = _unit(2 * a * nx - vx, 2 * a * ny - vy, 2 * a * nz - vz)
    return vx, vy, vz, view_norm, view_clamped, a, rx, ry, rz, norm, clamped


@njit(cache=True)
def _reflect(positions, normals, centre, out):
    for u in range(positions.shape[0]):
        values = _reflect_at(positions, normals, centre, u)
        out[u, 0], out[u, 1], out[u, 2] = values[6], values[7], values[8]


@njit(cache=True)
def _reflect_vjp(positions, normals, centre, grad, grad_positions, grad_normals, grad_centre):
    for u in range(positions.shape[0]):
        vx, vy, vz, view_norm, view_clamped, a, rx, ry, rz, norm, clamped = _reflect_at(
            positions, normals, centre, u
        )
        nx, ny, nz = normals[u, 0], normals[u, 1], normals[u, 2]
        wx, wy, wz = _unit_vjp(grad[u, 0], grad[u, 1], grad[u, 2], rx, ry, rz, norm, clamped)  # d / d w
        g_a = 2 * (nx * wx + ny * wy + nz * wz)  # w = 2 a n - v
        grad_normals[u, 0] = 2 * a * wx + g_a * vx  # a = n.v
        grad_normals[u, 1] = 2 * a * wy + g_a * vy
        grad_normals[u, 2] = 2 * a * wz + g_a * vz
        dx, dy, dz = _unit_vjp(g_a * nx - wx, g_a * ny - wy, g_a * nz - wz, vx, vy, vz, view_norm, view_clamped)
        grad_positions[u, 0], grad_positions[u, 1], grad_positions[u, 2] = -dx, -dy, -dz
        grad_centre[0] += dx
        grad_centre[1] += dy
        grad_centre[2] += dz


# -- dispatch ---------------------------------------------------------------------------------------
reflect = register(
    "reflect",
    reference=_reflect_reference,
    fast=_KernelReflection.apply,
    supports=lambda positions, normals, centre: (
        enabled(positions, normals, centre) and positions.dtype == normals.dtype
    ),
)
"""Mirrored view directions: positions [U, 3], normals [U, 3], camera centre [3] -> [U, 3]."""
