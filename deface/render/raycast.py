"""Ray casting with Embree (embreex): primary visibility and shadow-ray occlusion.

Embree only answers *which* triangle a ray hits and at what distance; nothing here is differentiable.
The renderer recomputes barycentrics in torch from the hit triangle ids (see renderer.py).
Embree works in float32 and, through embreex, on one thread (it holds the GIL).
"""

from __future__ import annotations

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh


class RayScene:
    """An Embree scene of one triangle mesh, built once per geometry (about 3 ms for 18k triangles)."""

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray):
        vertices = np.ascontiguousarray(vertices, dtype=np.float32)  # [V, 3]
        triangles = np.ascontiguousarray(triangles, dtype=np.int32)  # [F, 3]
        if vertices.ndim != 2 or vertices.shape[1] != 3 or triangles.ndim != 2 or triangles.shape[1] != 3:
            raise ValueError("RayScene: need vertices [V, 3] and triangles [F, 3]")
        self._scene = rtcore_scene.EmbreeScene()
        # embreex keeps a reference to the buffers through the mesh object; keep it alive with the scene.
        self._mesh = TriangleMesh(self._scene, vertices, triangles)

    def intersect(self, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """First hits of rays [N, 3] ->
        (triangle id [N] int64, -1 on a miss; distance [N] float32, inf on a miss)."""
        result = self._scene.run(_f32(origins), _f32(directions), output=1)
        tri = result["primID"].astype(np.int64)
        dist = np.where(tri >= 0, result["tfar"], np.inf).astype(np.float32)
        return tri, dist

    def first_triangles(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Triangle id [N] (int64, -1 on a miss) of each ray's first hit; cheaper than ``intersect``."""
        return self._scene.run(_f32(origins), _f32(directions)).astype(np.int64)

    def occluded(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Whether each ray [N, 3] hits anything -> bool [N]
        (Embree's any-hit query, cheaper than a closest hit)."""
        return self._scene.run(_f32(origins), _f32(directions), query="OCCLUDED") >= 0


def _f32(array: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(array, dtype=np.float32)
