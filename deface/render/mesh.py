"""Triangle meshes with UV seams, and the UV textures the renderer samples.

Winding: triangles are counter-clockwise seen from outside (the ICT-FaceKit convention: on the face,
cross(v1 - v0, v2 - v0) points toward +z, the viewer), so area-weighted normals point outward.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from deface.render import kernels


@dataclass(frozen=True)
class Mesh:
    """A triangle mesh in the model frame (cm).

    Vertices may require grad; the index tensors are plain data. A vertex may carry several UVs
    (seams): positions are indexed by ``triangles``, UVs by ``triangle_uvs``.
    """

    vertices: torch.Tensor  # [V, 3] float, differentiable
    triangles: torch.Tensor  # [F, 3] long, counter-clockwise seen from outside
    uvs: torch.Tensor  # [U, 2] float in [0, 1], v up
    triangle_uvs: torch.Tensor  # [F, 3] long indices into uvs

    def __post_init__(self) -> None:
        if self.vertices.ndim != 2 or self.vertices.shape[1] != 3:
            raise ValueError(f"Mesh: vertices must be [V, 3], got {tuple(self.vertices.shape)}")
        if self.triangles.ndim != 2 or self.triangles.shape[1] != 3:
            raise ValueError(f"Mesh: triangles must be [F, 3], got {tuple(self.triangles.shape)}")
        if self.triangle_uvs.shape != self.triangles.shape:
            raise ValueError("Mesh: triangle_uvs must have the same shape as triangles")
        if self.uvs.ndim != 2 or self.uvs.shape[1] != 2:
            raise ValueError(f"Mesh: uvs must be [U, 2], got {tuple(self.uvs.shape)}")
        # row-major index tensors: column-major ones (e.g. from a transposed numpy array) made every gather of
        # triangle corners and every hand-over to the kernels a strided copy
        for name in ("triangles", "triangle_uvs"):
            object.__setattr__(self, name, getattr(self, name).contiguous())

    @staticmethod
    def create(vertices, triangles, uvs, triangle_uvs, dtype: torch.dtype = torch.float32) -> Mesh:
        """Build a Mesh from numpy arrays or tensors (vertices keep their graph if they are tensors)."""
        verts = vertices if torch.is_tensor(vertices) else torch.as_tensor(np.asarray(vertices), dtype=dtype)
        return Mesh(
            vertices=verts,
            triangles=torch.as_tensor(np.asarray(triangles), dtype=torch.long),
            uvs=torch.as_tensor(np.asarray(uvs), dtype=verts.dtype),
            triangle_uvs=torch.as_tensor(np.asarray(triangle_uvs), dtype=torch.long),
        )

    @property
    def num_vertices(self) -> int:
        return int(self.vertices.shape[0])

    def face_normals(self) -> torch.Tensor:
        """Unnormalised face normals [F, 3] (length = 2 x area), pointing outward."""
        corners = self.vertices[self.triangles]  # [F, 3, 3]
        return torch.linalg.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])

    def vertex_normals(self) -> torch.Tensor:
        """Unit area-weighted vertex normals [V, 3], differentiable in the vertices (a numba kernel on the CPU)."""
        return kernels.vertex_normals(self.vertices, self.triangles)


@dataclass(frozen=True)
class Textures:
    """Linear UV maps sampled bilinearly; row 0 of each map is v = 1 (OBJ convention)."""

    diffuse: torch.Tensor  # [Ht, Wt, 3] diffuse albedo
    specular: torch.Tensor  # [Ht, Wt, 3] specular albedo k_s
    roughness: torch.Tensor  # [Ht, Wt, 1] Beckmann alpha in (0, 1]

    def __post_init__(self) -> None:
        for name, channels in (("diffuse", 3), ("specular", 3), ("roughness", 1)):
            tex = getattr(self, name)
            if tex.ndim != 3 or tex.shape[2] != channels:
                raise ValueError(f"Textures: {name} must be [Ht, Wt, {channels}], got {tuple(tex.shape)}")

    @staticmethod
    def constant(
        size: int,
        diffuse=(0.5, 0.5, 0.5),
        specular=(0.04, 0.04, 0.04),
        roughness: float = 0.4,
        dtype: torch.dtype = torch.float32,
    ) -> Textures:
        """Uniform maps of ``size`` x ``size`` texels."""

        def fill(values):
            return torch.tensor(values, dtype=dtype).expand(size, size, len(values)).clone()

        return Textures(fill(diffuse), fill(specular), fill((roughness,)))


def sample_texture(texture: torch.Tensor, uv: torch.Tensor) -> torch.Tensor:
    """Bilinear lookup of ``texture`` [Ht, Wt, C] at ``uv`` [N, 2] -> [N, C] (v flipped: row 0 is v = 1).

    grid_sample semantics (align_corners=False, border padding); a numba kernel on the CPU
    (kernels/texture.py).
    """
    return kernels.sample_texture(texture, uv)


sample_textures = kernels.sample_textures
