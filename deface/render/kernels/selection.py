"""Which vertices and pixels a render touches (no gradients): the vertices used by the covered pixels'
corners renumbered into that subset (``renumber``), the pixels whose centre lies in some projected
triangle's box (``triangle_box_pixels``: the primary rays worth tracing), the primary rays' unit
directions (``pixel_directions``), and the primary visibility itself (``nearest_triangles``: Embree's
primary rays through those pixels, the reference, or a z-buffer, the fast path).

References: torch / numpy array ops, Embree for the visibility. Fast: single passes in numba (no sorts, no
index ops). The z-buffer and Embree agree except where a pixel centre lies on an edge shared by two
triangles (within float32 rounding), which either may take: the registry's case for it has no such pixel,
and tests/test_render_kernels.py bounds the disagreements on the fit's meshes.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch

from deface.render.kernels.base import _array, enabled, njit, register

_BOX_SLACK = 0.05
"""Pixels (fraction of a pixel) by which ``triangle_box_pixels`` widens each projected triangle box."""


# -- torch / numpy references -------------------------------------------------------------------------
def _renumber_reference(corners: torch.Tensor, num_vertices: int) -> tuple[torch.Tensor, torch.Tensor]:
    """The vertices used by ``corners`` [N, 3] (sorted, [U]) and the corners renumbered into them."""
    flags = torch.zeros(num_vertices, dtype=torch.bool, device=corners.device)
    flags[corners.reshape(-1)] = True
    used = torch.nonzero(flags)[:, 0]  # [U]
    new_index = torch.cumsum(flags, 0) - 1  # [V], valid where flags
    return used, new_index[corners]


def _triangle_box_pixels_reference(pixels: torch.Tensor, triangles: torch.Tensor, height: int, width: int):
    """The boxes' pixel ranges (in float64, as the kernel computes them), painted with a 2-D difference
    array (+1 / -1 at the corners, then cumulative sums)."""
    corner = pixels.detach().cpu().numpy().astype(np.float64)[triangles.cpu().numpy()]  # [F, 3, 2]
    lo, hi = corner.min(1), corner.max(1)  # [F, 2] (x, y)
    finite = np.isfinite(lo).all(1) & np.isfinite(hi).all(1)  # a degenerate (NaN) triangle: no ray can hit it
    lo, hi = lo[finite], hi[finite]
    start = np.maximum(np.ceil(lo - 0.5 - _BOX_SLACK).astype(np.int64), 0)
    stop = np.minimum(np.floor(hi - 0.5 + _BOX_SLACK).astype(np.int64), [width - 1, height - 1]) + 1
    keep = (start < stop).all(1)
    start, stop = start[keep], stop[keep]
    paint = np.zeros((height + 1, width + 1), dtype=np.int64)
    np.add.at(paint, (start[:, 1], start[:, 0]), 1)
    np.add.at(paint, (start[:, 1], stop[:, 0]), -1)
    np.add.at(paint, (stop[:, 1], start[:, 0]), -1)
    np.add.at(paint, (stop[:, 1], stop[:, 0]), 1)
    return np.flatnonzero(paint.cumsum(0).cumsum(1)[:height, :width] > 0)


def _pixel_directions_reference(flat: np.ndarray, size: tuple[int, int], focal: float, centre: tuple[float, float],
                                rotation: np.ndarray):
    """Unit directions [N, 3] float32: camera-frame (x + 0.5 - cx, y + 0.5 - cy, focal) / focal, times R."""
    _, width = size
    ys, xs = np.divmod(flat, width)
    dirs_cam = np.empty((xs.shape[0], 3), dtype=np.float32)
    dirs_cam[:, 0] = (xs + 0.5 - centre[0]) / focal
    dirs_cam[:, 1] = (ys + 0.5 - centre[1]) / focal
    dirs_cam[:, 2] = 1.0
    dirs = dirs_cam @ rotation  # camera -> model: R^T d
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    return dirs


# -- fast path ----------------------------------------------------------------------------------------
def _renumber_fast(corners: torch.Tensor, num_vertices: int) -> tuple[torch.Tensor, torch.Tensor]:
    """renderer._renumber: the vertices used by ``corners`` [N, 3] (ascending, [U]) and the corners
    renumbered into them [N, 3] (one pass to flag, one to number, one to map; no torch index ops)."""
    new_index = np.zeros(num_vertices, dtype=np.int64)
    local = np.empty(tuple(corners.shape), dtype=np.int64)
    count = _flag_and_number(_array(corners), new_index)
    used = np.empty(count, dtype=np.int64)
    _map_corners(_array(corners), new_index, used, local)
    return torch.from_numpy(used), torch.from_numpy(local)


def _triangle_box_pixels_fast(pixels: torch.Tensor, triangles: torch.Tensor, height: int, width: int) -> np.ndarray:
    """Flat indices (ascending) of the pixels whose centre lies in some triangle's projected bounding box,
    widened by _BOX_SLACK against rounding: vertices projected to pixels [V, 2], triangles [F, 3].

    Only valid when every vertex is in front of the camera (otherwise the projected boxes mean nothing).
    """
    mask = np.zeros((height, width), dtype=np.bool_)
    _mark_triangle_boxes(_array(pixels), _array(triangles), mask)
    return np.flatnonzero(mask)


def _pixel_directions_fast(flat: np.ndarray, size: tuple[int, int], focal: float, centre: tuple[float, float],
                           rotation: np.ndarray) -> np.ndarray:
    """renderer._pixel_rays' unit model-frame directions [N, 3] (float32) through the centres of the pixels
    ``flat`` (y * W + x) of an image size = (H, W), for a camera of ``focal`` (pixels), principal point
    ``centre`` (x, y pixels) and rotation [3, 3]."""
    out = np.empty((flat.shape[0], 3), dtype=np.float32)
    _pixel_directions(np.ascontiguousarray(flat, dtype=np.int64), size[1], focal, float(centre[0]),
                      float(centre[1]), rotation, out)
    return out


@njit(cache=True)
def _flag_and_number(corners, new_index):
    """new_index[v] = rank of v among the used vertices (ascending), -1 for unused; returns their count."""
    for n in range(corners.shape[0]):
        for i in range(3):
            new_index[corners[n, i]] = 1
    count = 0
    for v in range(new_index.shape[0]):
        if new_index[v]:
            new_index[v] = count
            count += 1
        else:
            new_index[v] = -1
    return count


@njit(cache=True)
def _map_corners(corners, new_index, used, local):
    for v in range(new_index.shape[0]):
        if new_index[v] >= 0:
            used[new_index[v]] = v
    for n in range(corners.shape[0]):
        for i in range(3):
            local[n, i] = new_index[corners[n, i]]


@njit(cache=True)
def _pixel_directions(flat, width, focal, centre_x, centre_y, rotation, out):
    for n in range(flat.shape[0]):
        y, x = flat[n] // width, flat[n] % width
        cx, cy = (x + 0.5 - centre_x) / focal, (y + 0.5 - centre_y) / focal  # camera frame, z = 1
        dx = cx * rotation[0, 0] + cy * rotation[1, 0] + rotation[2, 0]  # camera -> model: R^T d
        dy = cx * rotation[0, 1] + cy * rotation[1, 1] + rotation[2, 1]
        dz = cx * rotation[0, 2] + cy * rotation[1, 2] + rotation[2, 2]
        norm = np.sqrt(dx * dx + dy * dy + dz * dz)
        out[n, 0], out[n, 1], out[n, 2] = dx / norm, dy / norm, dz / norm


@njit(cache=True)
def _mark_triangle_boxes(pixels, triangles, mask):
    height, width = mask.shape
    for f in range(triangles.shape[0]):
        i0, i1, i2 = triangles[f, 0], triangles[f, 1], triangles[f, 2]
        lo_x = min(pixels[i0, 0], pixels[i1, 0], pixels[i2, 0])
        hi_x = max(pixels[i0, 0], pixels[i1, 0], pixels[i2, 0])
        lo_y = min(pixels[i0, 1], pixels[i1, 1], pixels[i2, 1])
        hi_y = max(pixels[i0, 1], pixels[i1, 1], pixels[i2, 1])
        finite = True
        for i in (i0, i1, i2):  # (numba's min/max skip a NaN in some argument positions: test each corner)
            finite = finite and np.isfinite(pixels[i, 0]) and np.isfinite(pixels[i, 1])
        if not finite:
            continue  # a degenerate (NaN) triangle: no ray can hit it
        # pixel x has its centre at x + 0.5: centres in [lo - slack, hi + slack]; the slack covers the
        # float32 rounding of Embree's rays and of this projection (~1e-4 px) many times over
        x0 = max(int(np.ceil(lo_x - 0.5 - _BOX_SLACK)), 0)
        x1 = min(int(np.floor(hi_x - 0.5 + _BOX_SLACK)), width - 1)
        y0 = max(int(np.ceil(lo_y - 0.5 - _BOX_SLACK)), 0)
        y1 = min(int(np.floor(hi_y - 0.5 + _BOX_SLACK)), height - 1)
        for y in range(y0, y1 + 1):
            for x in range(x0, x1 + 1):
                mask[y, x] = True


def _nearest_triangles_reference(pixels: torch.Tensor, depth: torch.Tensor, triangles: torch.Tensor, height: int,
                                 width: int, trace: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """Embree's primary rays: ``trace(flat)`` (the first triangle hit through each pixel centre ``flat``, -1:
    none) for the pixels inside some triangle's projected box (a ray elsewhere cannot hit), -1 elsewhere."""
    ids = np.full(height * width, -1, dtype=np.int64)
    flat = triangle_box_pixels(pixels, triangles, height, width)  # ~half the box's pixels
    ids[flat] = trace(flat)
    return ids


def _nearest_triangles_fast(pixels: torch.Tensor, depth: torch.Tensor, triangles: torch.Tensor, height: int,
                            width: int, trace: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """The z-buffer: nearest by perspective-correct depth (1 / z is linear in the screen-space barycentrics); a
    centre exactly on an edge belongs to both triangles (the nearer wins, then the lower id). ``trace`` is not
    called: no Embree scene is built. About a millisecond for the 256² face, against ~20 for an Embree build
    and cast."""
    ids = np.full(height * width, -1, dtype=np.int64)
    _zbuffer(np.ascontiguousarray(_array(pixels), dtype=np.float64),
             np.ascontiguousarray(_array(depth), dtype=np.float64),
             np.ascontiguousarray(_array(triangles), dtype=np.int64), height, width, ids)
    return ids


@njit(cache=True)
def _zbuffer(pixels, depth, triangles, height, width, ids):
    nearest = np.zeros(height * width)  # 1 / depth of the nearest hit so far (0: none yet)
    for f in range(triangles.shape[0]):
        i0, i1, i2 = triangles[f, 0], triangles[f, 1], triangles[f, 2]
        ax, ay, bx, by = pixels[i0, 0], pixels[i0, 1], pixels[i1, 0], pixels[i1, 1]
        cx, cy = pixels[i2, 0], pixels[i2, 1]
        area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
        if not np.isfinite(area) or area == 0.0:
            continue  # degenerate (NaN or edge-on): no ray hits it
        x0 = max(int(np.ceil(min(ax, bx, cx) - 0.5)), 0)
        x1 = min(int(np.floor(max(ax, bx, cx) - 0.5)), width - 1)
        y0 = max(int(np.ceil(min(ay, by, cy) - 0.5)), 0)
        y1 = min(int(np.floor(max(ay, by, cy) - 0.5)), height - 1)
        for y in range(y0, y1 + 1):
            py = y + 0.5
            for x in range(x0, x1 + 1):
                px = x + 0.5
                w0 = ((cx - bx) * (py - by) - (cy - by) * (px - bx)) / area  # weight of corner 0: edge 1 -> 2
                w1 = ((ax - cx) * (py - cy) - (ay - cy) * (px - cx)) / area
                w2 = ((bx - ax) * (py - ay) - (by - ay) * (px - ax)) / area
                if w0 < 0.0 or w1 < 0.0 or w2 < 0.0:
                    continue
                inverse = w0 / depth[i0] + w1 / depth[i1] + w2 / depth[i2]
                k = y * width + x
                if inverse > nearest[k]:
                    nearest[k] = inverse
                    ids[k] = f


# -- dispatch ---------------------------------------------------------------------------------------
renumber = register(
    "renumber",
    reference=_renumber_reference,
    fast=_renumber_fast,
    supports=lambda corners, num_vertices: enabled(corners),
)
"""The vertices used by ``corners`` [N, 3] (ascending, [U]) and the corners renumbered into them [N, 3]."""

triangle_box_pixels = register(
    "triangle_box_pixels",
    reference=_triangle_box_pixels_reference,
    fast=_triangle_box_pixels_fast,
    supports=lambda pixels, triangles, height, width: enabled(pixels),
)
"""Flat indices (ascending) of the pixels whose centre lies in some triangle's projected bounding box,
widened by _BOX_SLACK against rounding: (projected vertices [V, 2], triangles [F, 3], H, W). Only valid
when every vertex is in front of the camera (otherwise the projected boxes mean nothing)."""

pixel_directions = register(
    "pixel_directions",
    reference=_pixel_directions_reference,
    fast=_pixel_directions_fast,
    supports=lambda flat, size, focal, centre, rotation: True,
)
"""Unit model-frame directions [N, 3] (float32) through the centres of the pixels ``flat`` (y * W + x) of an
image size = (H, W), for a camera of ``focal`` (pixels, a float), principal point ``centre`` (x, y pixels) and
rotation [3, 3] (numpy)."""

nearest_triangles = register(
    "nearest_triangles",
    reference=_nearest_triangles_reference,
    fast=_nearest_triangles_fast,
    supports=lambda pixels, depth, triangles, height, width, trace: enabled(pixels),
)
"""Primary visibility: [H * W] int64, per pixel the nearest triangle whose projection contains the pixel
centre (-1: none), from the vertices projected to pixels [V, 2] and their camera depths [V] (all in front of
the camera), triangles [F, 3], H, W and ``trace``, flat pixel indices -> the first triangle Embree's ray
through each centre hits (the reference's rays)."""
