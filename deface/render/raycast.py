"""Ray casting with Embree (embreex): primary visibility and shadow-ray occlusion.

Embree only answers *which* triangle a ray hits and at what distance; nothing here is differentiable.
The renderer recomputes barycentrics in torch from the hit triangle ids (see renderer.py).
Embree works in float32. One embreex call traces on one thread but releases the GIL, so large batches
are split into contiguous chunks traced on ``kernels.thread_count()`` threads (each ray's answer does not
depend on the split).
"""

from __future__ import annotations

import itertools
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

from deface.render import kernels

_MIN_CHUNK = 4096
"""Fewest rays per thread worth a hand-off (a 256² frame casts ~35k primary rays, a refresh ~2.4M)."""


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
        chunks = _in_parallel(lambda o, d: self._scene.run(o, d, output=1), origins, directions)
        tri = np.concatenate([chunk["primID"] for chunk in chunks]).astype(np.int64)
        tfar = np.concatenate([chunk["tfar"] for chunk in chunks])
        return tri, np.where(tri >= 0, tfar, np.inf).astype(np.float32)

    def first_triangles(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Triangle id [N] (int64, -1 on a miss) of each ray's first hit; cheaper than ``intersect``."""
        return np.concatenate(_in_parallel(self._scene.run, origins, directions)).astype(np.int64)

    def occluded(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Whether each ray [N, 3] hits anything -> bool [N]
        (Embree's any-hit query, cheaper than a closest hit)."""
        hits = _in_parallel(lambda o, d: self._scene.run(o, d, query="OCCLUDED"), origins, directions)
        return np.concatenate(hits) >= 0


_pool: ThreadPoolExecutor | None = None
_pool_workers = 0


def _in_parallel(trace, origins: np.ndarray, directions: np.ndarray) -> list[np.ndarray]:
    """trace(origins, directions) on contiguous chunks of the rays [N, 3], in parallel; results in order."""
    global _pool, _pool_workers
    origins, directions = _f32(origins), _f32(directions)
    parts = max(1, min(kernels.thread_count(), origins.shape[0] // _MIN_CHUNK))
    if parts == 1:
        return [trace(origins, directions)]
    bounds = [k * origins.shape[0] // parts for k in range(parts + 1)]
    chunks = [(origins[a:b], directions[a:b]) for a, b in itertools.pairwise(bounds)]
    if _pool_workers < parts - 1:  # the calling thread traces the first chunk itself
        _pool, _pool_workers = ThreadPoolExecutor(parts - 1, thread_name_prefix="deface-embree"), parts - 1
    pending = [_pool.submit(trace, *chunk) for chunk in chunks[1:]]
    return [trace(*chunks[0])] + [job.result() for job in pending]


def _f32(array: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(array, dtype=np.float32)
