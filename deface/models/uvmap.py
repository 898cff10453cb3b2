"""Rasterising a mesh's UV layout: which triangle covers each texel, and with which barycentrics.

Used to turn per-vertex quantities (AlbedoMM albedo, 3-D positions, region weights) into UV maps.
Texel (row i, column j) of an [H, W] map has its centre at u = (j + 0.5) / W, v = 1 - (i + 0.5) / H
(row 0 is v = 1, the OBJ convention of :mod:`deface.models.base`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from skimage.draw import polygon as draw_polygon

# Candidate texels are evaluated in chunks of at most this many (triangle, texel) pairs (memory bound).
_CHUNK_PAIRS = 4_000_000


@dataclass(frozen=True)
class UVRaster:
    """Per-texel triangle ids and barycentrics of a UV layout rasterised at texel centres."""

    triangle: np.ndarray  # [H, W] int64 triangle index, -1 where no triangle covers the texel centre
    barycentric: np.ndarray  # [H, W, 3] float64 weights of the triangle's corners (0 where uncovered)

    @property
    def covered(self) -> np.ndarray:
        """[H, W] bool: texel centre inside some UV triangle."""
        return self.triangle >= 0

    def interpolate(self, corner_values: np.ndarray, fill: bool = True) -> np.ndarray:
        """Interpolate per-corner values [F, 3, C] into a map [H, W, C].

        With ``fill`` the texels outside the layout copy their nearest covered texel, so bilinear lookups
        at the layout's border do not pull in zeros.
        """
        if corner_values.ndim != 3 or corner_values.shape[1] != 3:
            raise ValueError(f"interpolate: corner_values must be [F, 3, C], got {corner_values.shape}")
        covered = self.covered
        tri = np.where(covered, self.triangle, 0)
        out = np.einsum("hwk,hwkc->hwc", self.barycentric, corner_values[tri])
        out[~covered] = 0.0
        return fill_outside(out, covered) if fill else out

    def interpolate_vertices(self, vertex_values: np.ndarray, triangles: np.ndarray, fill: bool = True):
        """Per-vertex values [V, C] on triangles [F, 3] (same order as the UV triangles) -> [H, W, C]."""
        return self.interpolate(vertex_values[triangles], fill=fill)


def fill_outside(image: np.ndarray, covered: np.ndarray) -> np.ndarray:
    """Copy each uncovered texel's nearest covered texel (image [H, W, C], covered [H, W] bool)."""
    if covered.all() or not covered.any():
        return image
    _, (rows, cols) = ndimage.distance_transform_edt(~covered, return_indices=True)
    return image[rows, cols]


def texel_centres(height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """u [W] and v [H] of texel centres (v decreasing with the row)."""
    u = (np.arange(width) + 0.5) / width
    v = 1.0 - (np.arange(height) + 0.5) / height
    return u, v


def rasterize_uv(uvs: np.ndarray, triangle_uvs: np.ndarray, size: int | tuple[int, int]) -> UVRaster:
    """Rasterise UV triangles (uvs [U, 2] in [0, 1], triangle_uvs [F, 3]) at texel centres of a size² map."""
    height, width = (size, size) if isinstance(size, int) else size
    if uvs.ndim != 2 or uvs.shape[1] != 2:
        raise ValueError(f"rasterize_uv: uvs must be [U, 2], got {uvs.shape}")
    if triangle_uvs.ndim != 2 or triangle_uvs.shape[1] != 3:
        raise ValueError(f"rasterize_uv: triangle_uvs must be [F, 3], got {triangle_uvs.shape}")
    # Continuous pixel coordinates: x = u * W - 0.5, y = (1 - v) * H - 0.5, texel centres at integers.
    corners = uvs.astype(np.float64)[triangle_uvs]  # [F, 3, 2]
    px = np.stack([corners[..., 0] * width - 0.5, (1.0 - corners[..., 1]) * height - 0.5], -1)
    lo = np.clip(np.ceil(px.min(1) - 1e-9), 0, [width - 1, height - 1]).astype(np.int64)  # [F, 2]
    hi = np.clip(np.floor(px.max(1) + 1e-9), 0, [width - 1, height - 1]).astype(np.int64)
    extent = np.maximum(hi - lo + 1, 0)  # [F, 2]
    triangle = np.full((height, width), -1, np.int64)
    bary = np.zeros((height, width, 3))
    # Group triangles by bounding-box size so each group is one dense vectorised evaluation.
    box_w = np.maximum(extent[:, 0], 1)
    box_h = np.maximum(extent[:, 1], 1)
    for bw, bh in sorted(set(zip(box_w.tolist(), box_h.tolist(), strict=True))):
        ids = np.nonzero((box_w == bw) & (box_h == bh) & (extent.min(1) > 0))[0]
        step = max(1, _CHUNK_PAIRS // (bw * bh))
        for start in range(0, len(ids), step):
            _rasterize_group(ids[start : start + step], px, lo, bw, bh, triangle, bary)
    return UVRaster(triangle=triangle, barycentric=bary)


def _rasterize_group(ids, px, lo, bw, bh, triangle, bary) -> None:
    """Evaluate the texels of a group of triangles that share one bounding-box size (bw x bh)."""
    dx, dy = np.meshgrid(np.arange(bw), np.arange(bh), indexing="xy")
    xs = lo[ids, 0, None] + dx.reshape(1, -1)  # [G, bw*bh]
    ys = lo[ids, 1, None] + dy.reshape(1, -1)
    a, b, c = px[ids, 0], px[ids, 1], px[ids, 2]  # [G, 2] each
    det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
    ok = np.abs(det) > 1e-12
    det = np.where(ok, det, 1.0)[:, None]
    w1 = (
        (xs - a[:, 0, None]) * (c[:, 1, None] - a[:, 1, None])
        - (c[:, 0, None] - a[:, 0, None]) * (ys - a[:, 1, None])
    ) / det
    w2 = (
        (b[:, 0, None] - a[:, 0, None]) * (ys - a[:, 1, None])
        - (xs - a[:, 0, None]) * (b[:, 1, None] - a[:, 1, None])
    ) / det
    w0 = 1.0 - w1 - w2
    inside = (w0 >= -1e-9) & (w1 >= -1e-9) & (w2 >= -1e-9) & ok[:, None]
    inside &= (xs < triangle.shape[1]) & (ys < triangle.shape[0])
    g, k = np.nonzero(inside)
    rows, cols = ys[g, k], xs[g, k]
    triangle[rows, cols] = ids[g]
    bary[rows, cols] = np.stack([w0[g, k], w1[g, k], w2[g, k]], -1)


def coverage(uvs: np.ndarray, triangle_uvs: np.ndarray, size: int, supersample: int = 4) -> np.ndarray:
    """Fraction [size, size] in [0, 1] of each texel covered by the layout (supersampled, box-averaged)."""
    fine = rasterize_uv(uvs, triangle_uvs, size * supersample).covered.astype(np.float32)
    return fine.reshape(size, supersample, size, supersample).mean((1, 3))


def polygon_mask(uv: np.ndarray, size: int) -> np.ndarray:
    """[size, size] float map, 1 at texels inside the polygon of UV points [N, 2] (row 0 = v 1)."""
    rows, cols = (1.0 - uv[:, 1]) * size - 0.5, uv[:, 0] * size - 0.5
    mask = np.zeros((size, size))
    rr, cc = draw_polygon(rows, cols, shape=(size, size))
    mask[rr, cc] = 1.0
    return mask
