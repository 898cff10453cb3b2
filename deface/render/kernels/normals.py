"""Area-weighted unit vertex normals of a triangle mesh: n_v = m_v / max(|m_v|, 1e-12), m_v the sum of the
incident faces' cross products (x1 - x0) x (x2 - x0).

Reference: one index_add per corner. Fast: per vertex, its incident faces in index order (a counting
sort of the corners, cached for the last triangles tensor); the backward gathers per vertex too.
"""

from __future__ import annotations

import numpy as np
import torch

from deface.render.kernels.base import _array, _pick, enabled, njit, prange, register, serial_and_parallel
from deface.render.kernels.interpolation import _corners_by_vertex


# -- torch reference --------------------------------------------------------------------------------
def _vertex_normals_reference(vertices: torch.Tensor, triangles: torch.Tensor) -> torch.Tensor:
    """vertices [V, 3], triangles [F, 3] -> unit normals [V, 3]."""
    corners = vertices[triangles]  # [F, 3, 3]
    face = torch.linalg.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])  # [F, 3]
    summed = torch.zeros_like(vertices)
    for corner in range(3):
        summed = summed.index_add(0, triangles[:, corner], face)
    return summed / summed.norm(dim=-1, keepdim=True).clamp_min(1e-12)


# -- fast path ----------------------------------------------------------------------------------------
def vertex_normals_forward(vertices: torch.Tensor, triangles: torch.Tensor) -> torch.Tensor:
    """Mesh.vertex_normals: unit sums of the incident faces' cross products, vertices [V, 3] -> [V, 3]."""
    verts, tris = _array(vertices), _array(triangles)
    offsets, slots = _incident_corners(triangles, verts.shape[0])
    out = np.empty(verts.shape, dtype=verts.dtype)
    _pick(_vertex_normals)(verts, tris, offsets, slots, out)
    return torch.from_numpy(out)


def vertex_normals_backward(vertices: torch.Tensor, triangles: torch.Tensor, grad: torch.Tensor) -> torch.Tensor:
    """Gradient of ``vertex_normals_forward`` to the vertices [V, 3], gathered per vertex (deterministic)."""
    verts, tris = _array(vertices), _array(triangles)
    offsets, slots = _incident_corners(triangles, verts.shape[0])
    out = np.empty(verts.shape, dtype=verts.dtype)
    grad_sum = np.empty(verts.shape)  # d loss / d (unnormalised sum of face normals) per vertex
    _pick(_vertex_normals_vjp)(verts, tris, offsets, slots, _array(grad), grad_sum, out)
    return torch.from_numpy(out)


_incident_cache: tuple | None = None


def _incident_corners(triangles: torch.Tensor, num_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """``_corners_by_vertex`` of a mesh's triangles, kept for the last triangles tensor: a fit renders one
    topology thousands of times. The cache holds the tensor itself (so its memory cannot be reused by
    another) and its in-place version counter."""
    global _incident_cache
    cached = _incident_cache
    if cached is None or cached[0] is not triangles or cached[1:3] != (triangles._version, num_vertices):
        incident = _corners_by_vertex(_array(triangles), num_vertices)
        cached = _incident_cache = (triangles, triangles._version, num_vertices, incident)
    return cached[3]


class _KernelVertexNormals(torch.autograd.Function):
    """The numba path of ``Mesh.vertex_normals``: per-vertex sums over the incident faces, gathered both ways."""

    @staticmethod
    def forward(ctx, vertices, triangles):
        ctx.save_for_backward(vertices, triangles)
        return vertex_normals_forward(vertices, triangles)

    @staticmethod
    def backward(ctx, grad):
        return vertex_normals_backward(*ctx.saved_tensors, grad), None


@njit(inline="always")
def _face_cross(vertices, triangles, f):
    """(x1 - x0) x (x2 - x0) of face f and its two edges a = x1 - x0, b = x2 - x0, as one flat tuple
    (cx, cy, cz, ax, ay, az, bx, by, bz): nested tuples trip numba's parfor analysis."""
    i0, i1, i2 = triangles[f, 0], triangles[f, 1], triangles[f, 2]
    ax, ay, az = (
        vertices[i1, 0] - vertices[i0, 0],
        vertices[i1, 1] - vertices[i0, 1],
        vertices[i1, 2] - vertices[i0, 2],
    )
    bx, by, bz = (
        vertices[i2, 0] - vertices[i0, 0],
        vertices[i2, 1] - vertices[i0, 1],
        vertices[i2, 2] - vertices[i0, 2],
    )
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx, ax, ay, az, bx, by, bz


@njit(inline="always")
def _vertex_sum(vertices, triangles, offsets, slots, v):
    """Sum of the incident faces' cross products at vertex v (faces in index order)."""
    mx, my, mz = 0.0, 0.0, 0.0
    for k in range(offsets[v], offsets[v + 1]):
        cross = _face_cross(vertices, triangles, slots[k] // 3)
        mx, my, mz = mx + cross[0], my + cross[1], mz + cross[2]
    return mx, my, mz


@serial_and_parallel
def _vertex_normals(vertices, triangles, offsets, slots, out):
    for v in prange(vertices.shape[0]):
        mx, my, mz = _vertex_sum(vertices, triangles, offsets, slots, v)
        norm = max(np.sqrt(mx * mx + my * my + mz * mz), 1e-12)
        out[v, 0], out[v, 1], out[v, 2] = mx / norm, my / norm, mz / norm


@serial_and_parallel
def _vertex_normals_vjp(vertices, triangles, offsets, slots, grad, grad_sum, out):
    # d loss / d (unnormalised sum) per vertex: n = m / max(|m|, 1e-12)
    for v in prange(vertices.shape[0]):
        mx, my, mz = _vertex_sum(vertices, triangles, offsets, slots, v)
        norm = np.sqrt(mx * mx + my * my + mz * mz)
        clamped = max(norm, 1e-12)
        dot = grad[v, 0] * mx + grad[v, 1] * my + grad[v, 2] * mz
        scale = dot / (clamped * clamped * norm) if norm >= 1e-12 else 0.0
        grad_sum[v, 0] = grad[v, 0] / clamped - scale * mx
        grad_sum[v, 1] = grad[v, 1] / clamped - scale * my
        grad_sum[v, 2] = grad[v, 2] / clamped - scale * mz
    for v in prange(vertices.shape[0]):
        gx, gy, gz = 0.0, 0.0, 0.0
        for k in range(offsets[v], offsets[v + 1]):
            f, corner = slots[k] // 3, slots[k] % 3
            edges = _face_cross(vertices, triangles, f)
            a, b = edges[3:6], edges[6:9]
            cx, cy, cz = 0.0, 0.0, 0.0  # d loss / d cross product of face f
            for i in range(3):
                w = triangles[f, i]
                cx, cy, cz = cx + grad_sum[w, 0], cy + grad_sum[w, 1], cz + grad_sum[w, 2]
            # c = a x b: d/da = b x g, d/db = g x a; x1 enters a, x2 enters b, x0 both with a minus sign
            if corner != 2:
                ex, ey, ez = b[1] * cz - b[2] * cy, b[2] * cx - b[0] * cz, b[0] * cy - b[1] * cx
                sign = 1.0 if corner == 1 else -1.0
                gx, gy, gz = gx + sign * ex, gy + sign * ey, gz + sign * ez
            if corner != 1:
                ex, ey, ez = cy * a[2] - cz * a[1], cz * a[0] - cx * a[2], cx * a[1] - cy * a[0]
                sign = 1.0 if corner == 2 else -1.0
                gx, gy, gz = gx + sign * ex, gy + sign * ey, gz + sign * ez
        out[v, 0], out[v, 1], out[v, 2] = gx, gy, gz


# -- dispatch ---------------------------------------------------------------------------------------
vertex_normals = register(
    "vertex_normals",
    reference=_vertex_normals_reference,
    fast=_KernelVertexNormals.apply,
    supports=lambda vertices, triangles: enabled(vertices),
)
"""Unit area-weighted vertex normals: vertices [V, 3], triangles [F, 3] (long) -> [V, 3]."""
