"""Fused numba kernels for the renderer's hot loops: barycentrics, corner interpolation (plain and
band-filtered), bilinear texture lookup, SH basis rows and band sums, and the fused pixel shading
(``shade_forward``); each with its backward.

Each kernel has a torch reference path next to its caller (renderer.py, mesh.py, sh.py); these are the
fast CPU path, used for CPU tensors when numba is importable and ``DEFACE_RENDER_KERNELS`` is not
``torch`` (tests/test_render_kernels.py checks both paths agree). Why: the torch versions spend their time
in hundreds of small ops, broadcasts and [N, B*C] temporaries; one loop per pixel needs neither (figures
in benchmarks/render.md).

Determinism: every output element is written by exactly one loop iteration in a fixed order. Gradients
that scatter to vertices are either computed in *gather* form (for each vertex, its entries in a fixed
order, from a counting sort) or, in the shade backward, scattered in pixel order into a fixed number
(_SCATTER_PARTS) of per-range buffers summed in order; so results are bit-identical for any number of
threads. The texture-gradient and barycentric-corner scatters run on one thread.

Threads: ``set_threads`` (or DEFACE_RENDER_THREADS) sets the kernels' threads independently of torch's;
by default they follow ``torch.get_num_threads()``.
"""

from __future__ import annotations

import os
import types
from contextlib import contextmanager

import numpy as np
import torch

try:  # numba is a regular dependency; the torch path keeps the renderer working without it
    import numba
    from numba import njit, prange
except ImportError:  # pragma: no cover - exercised only where numba is missing
    numba = None

_backend = os.environ.get("DEFACE_RENDER_KERNELS", "numba")


def enabled(*tensors: torch.Tensor) -> bool:
    """Whether the numba kernels handle these tensors (all on the CPU, numba present and selected)."""
    return numba is not None and _backend != "torch" and all(t.device.type == "cpu" for t in tensors)


@contextmanager
def backend(name: str):
    """Temporarily select the kernels: "numba" (fast path where possible) or "torch" (reference path)."""
    global _backend
    if name not in ("numba", "torch"):
        raise ValueError(f"kernels.backend: expected 'numba' or 'torch', got {name!r}")
    previous, _backend = _backend, name
    try:
        yield
    finally:
        _backend = previous


def _array(tensor: torch.Tensor) -> np.ndarray:
    return tensor.detach().contiguous().numpy()


def _thread_setting() -> int | None:
    value = os.environ.get("DEFACE_RENDER_THREADS", "")
    return int(value) if value.strip() else None


_threads = _thread_setting()


def set_threads(count: int | None) -> None:
    """Threads of the numba kernels and of Embree's primary and shadow rays; None (the default) follows
    ``torch.get_num_threads()``.

    The renderer's time is mostly in these kernels, so e.g. 2 kernel threads with 1 torch thread keep
    torch's small ops free of thread hand-offs while the pixel passes run on both cores. The environment
    variable DEFACE_RENDER_THREADS sets the initial value. Results do not depend on it (see above).
    """
    global _threads
    if count is not None and count < 1:
        raise ValueError(f"kernels.set_threads: need a count >= 1 or None, got {count}")
    _threads = count


def thread_count() -> int:
    """Threads the renderer's CPU loops use: the numba kernels and the Embree ray batches (raycast.py)."""
    threads = torch.get_num_threads() if _threads is None else _threads
    return threads if numba is None else min(threads, numba.config.NUMBA_NUM_THREADS)


def _pick(kernel):
    """The serial or the parallel compilation of ``kernel`` for the thread setting (``set_threads``).

    With 1 thread the serial build runs on the calling thread (no thread pool at all).
    """
    threads = thread_count()
    if threads <= 1:
        return kernel.serial
    if numba.get_num_threads() != threads:
        numba.set_num_threads(threads)
    return kernel.parallel


# -- corner interpolation ---------------------------------------------------------------------------
def interpolate_forward(values: torch.Tensor, corners: torch.Tensor, bary: torch.Tensor, lobe: torch.Tensor):
    """out[p] = sum_i bary[p, i] sum_l lobe[p, l] values[corners[p, i], l]: values [U, B, C] -> [N, C]."""
    out = np.empty((corners.shape[0], values.shape[2]), dtype=_array(values).dtype)
    _pick(_interpolate_forward)(_array(values), _array(corners), _array(bary), _array(lobe), out)
    return torch.from_numpy(out)


def interpolate_backward_corners(values, corners, bary, lobe, grad):
    """Gradients of ``interpolate_forward`` to bary [N, 3] and lobe [N, B]."""
    num, bands = lobe.shape
    grad_bary = np.empty((num, 3), dtype=_array(values).dtype)
    grad_lobe = np.empty((num, bands), dtype=grad_bary.dtype)
    _pick(_interpolate_backward_corners)(
        _array(values), _array(corners), _array(bary), _array(lobe), _array(grad), grad_bary, grad_lobe
    )
    return torch.from_numpy(grad_bary), torch.from_numpy(grad_lobe)


def interpolate_backward_values(num_vertices: int, corners, bary, lobe, grad):
    """Gradient of ``interpolate_forward`` to values: [U, B, C], gathered per vertex (thread-count exact)."""
    offsets, entries = _corners_by_vertex(_array(corners), num_vertices)
    out = np.empty((num_vertices, lobe.shape[1], grad.shape[1]), dtype=_array(grad).dtype)
    _pick(_interpolate_backward_values)(offsets, entries, _array(bary), _array(lobe), _array(grad), out)
    return torch.from_numpy(out)


# -- bilinear texture lookup ------------------------------------------------------------------------
def bilinear_forward(texture: torch.Tensor, uv: torch.Tensor) -> torch.Tensor:
    """``sample_texture``'s lookup: texture [Ht, Wt, C], uv [N, 2] -> [N, C] (border padding)."""
    out = np.empty((uv.shape[0], texture.shape[2]), dtype=_array(texture).dtype)
    _pick(_bilinear_forward)(_array(texture), _array(uv), out)
    return torch.from_numpy(out)


def bilinear_backward(texture: torch.Tensor, uv: torch.Tensor, grad: torch.Tensor, need_texture: bool, need_uv: bool):
    """Gradients of ``bilinear_forward`` to the texture [Ht, Wt, C] and uv [N, 2] (None where not needed)."""
    tex, coords, g = _array(texture), _array(uv), _array(grad)
    grad_texture = grad_uv = None
    if need_texture:
        grad_texture = np.zeros(tex.shape, dtype=g.dtype)
        _bilinear_scatter(coords, g, grad_texture)
    if need_uv:
        grad_uv = np.empty(coords.shape, dtype=g.dtype)
        _pick(_bilinear_grad_uv)(tex, coords, g, grad_uv)
    return (
        None if grad_texture is None else torch.from_numpy(grad_texture),
        None if grad_uv is None else torch.from_numpy(grad_uv),
    )


# -- perspective-correct barycentrics ---------------------------------------------------------------
def barycentrics_forward(pixels, depth, covered) -> torch.Tensor:
    """Perspective-correct barycentrics [N, 3] (renderer._barycentrics' formula) of the covered pixels'
    centres in their triangles, from the vertices projected to ``pixels`` [V, 2] with camera depths ``depth``
    [V]; covered = (triangles [F, 3], triangle id [N] and flat index y * W + x [N] per pixel, (H, W))."""
    p = _array(pixels)
    args = _barycentric_inputs(p, covered)
    out = np.empty((args[1].shape[0], 3), dtype=p.dtype)
    _pick(_barycentrics_forward)(p, _array(depth), *args, np.finfo(p.dtype).tiny, out)
    return torch.from_numpy(out)


def _barycentric_inputs(pixels: np.ndarray, covered) -> tuple:
    """(triangles, triangle ids, flat indices, pixel-centre coordinates x + 0.5 [max(H, W)] in the pixels'
    dtype (the centres' arithmetic stays in that dtype, as in the torch path), W) for the kernels."""
    triangles, tri, flat, (height, width) = covered
    centres = (np.arange(max(height, width)) + 0.5).astype(pixels.dtype)
    return _array(triangles), _array(tri), _array(flat), centres, width


def barycentrics_backward(pixels, depth, covered, grad) -> tuple[torch.Tensor, torch.Tensor]:
    """Gradients of ``barycentrics_forward`` to the projected vertices [V, 2] and their depths [V].

    Per-pixel gradients first (in parallel), then one serial scatter in pixel order (deterministic)."""
    p, z = _array(pixels), _array(depth)
    args = _barycentric_inputs(p, covered)
    num = args[1].shape[0]
    grad_p, grad_z = np.empty((num, 3, 2), dtype=p.dtype), np.empty((num, 3), dtype=z.dtype)
    _pick(_barycentrics_backward)(p, z, *args, np.finfo(p.dtype).tiny, _array(grad), grad_p, grad_z)
    grad_pixels, grad_depth = np.zeros(p.shape, dtype=p.dtype), np.zeros(z.shape, dtype=z.dtype)
    _scatter_corners(args[0], args[1], grad_p, grad_z, grad_pixels, grad_depth)
    return torch.from_numpy(grad_pixels), torch.from_numpy(grad_depth)


# -- SH band sums ---------------------------------------------------------------------------------
_SH_CHUNK = 128  # directions per block: the recurrences run along a block (SIMD); its float32 work arrays stay in L2


def sh_constants(diagonal: list[float], rows: list[tuple[list[float], list[float]]]):
    """sh.py's recurrence constants as arrays: diagonal [B], a [B, B], b [B, B] (row l, column m)."""
    bands = len(diagonal)
    a, b = np.zeros((bands, bands)), np.zeros((bands, bands))
    for l, (a_row, b_row) in enumerate(rows):  # noqa: E741
        a[l, : len(a_row)], b[l, : len(b_row)] = a_row, b_row
    return np.asarray(diagonal, dtype=np.float64), a, b


def _constants_as(constants, dtype) -> tuple:
    """The recurrence constants in the directions' dtype: float32 inputs run the SH loops in float32 (twice
    the SIMD lanes), like the torch path; float64 stays float64."""
    return tuple(c.astype(dtype, copy=False) for c in constants)


def sh_basis_forward(directions: torch.Tensor, constants, channel_first: bool = True) -> torch.Tensor:
    """Real SH basis (sh.py's convention) at unit directions [N, 3] -> rows [B², N] (or [N, B²])."""
    dirs = _array(directions)
    size = constants[0].shape[0] ** 2
    out = np.empty((size, dirs.shape[0]) if channel_first else (dirs.shape[0], size), dtype=dirs.dtype)
    _pick(_sh_basis)(dirs, _constants_as(constants, dirs.dtype), _SH_CHUNK, out, channel_first)
    return torch.from_numpy(out)


def sh_basis_backward(directions: torch.Tensor, grad: torch.Tensor, constants) -> torch.Tensor:
    """sum_j grad[j, n] dY_j/d(x, y, z)(directions[n]): grad [B², N] -> [N, 3]."""
    dirs = _array(directions)
    out = np.empty(dirs.shape, dtype=dirs.dtype)
    _pick(_sh_basis_vjp)(dirs, _constants_as(constants, dirs.dtype), _array(grad), _SH_CHUNK, out)
    return torch.from_numpy(out)


def sh_band_sums_forward(directions: torch.Tensor, coeffs: torch.Tensor, constants) -> torch.Tensor:
    """Per-band sums S_l(w) = sum_m c_lm Y_lm(w): directions [N, 3], coeffs [B², C] -> [N, B, C]."""
    dirs = _array(directions)
    out = np.empty((dirs.shape[0], constants[0].shape[0], coeffs.shape[1]), dtype=dirs.dtype)
    _pick(_sh_band_sums)(dirs, _array(coeffs).astype(dirs.dtype), _constants_as(constants, dirs.dtype), _SH_CHUNK, out)
    return torch.from_numpy(out)


def sh_band_sums_backward(directions, coeffs, grad, constants, need_directions: bool, need_coeffs: bool):
    """Gradients of ``sh_band_sums_forward`` to directions [N, 3] and coeffs [B², C] (None where not needed).

    The coefficient gradient (a sum over N) is summed per block of _SH_CHUNK directions, then over the
    blocks in order: the same result for any number of threads.
    """
    dirs = _array(directions)
    c, constants = _array(coeffs).astype(dirs.dtype), _constants_as(constants, dirs.dtype)
    blocks = (dirs.shape[0] + _SH_CHUNK - 1) // _SH_CHUNK
    grad_dirs = np.empty(dirs.shape, dtype=dirs.dtype)
    partial = np.empty((blocks if need_coeffs else 0, c.shape[0], c.shape[1]), dtype=np.float64)
    _pick(_sh_band_sums_vjp)(dirs, c, _array(grad), constants, _SH_CHUNK, need_directions, grad_dirs, partial)
    return (
        torch.from_numpy(grad_dirs) if need_directions else None,
        torch.from_numpy(partial.sum(0).astype(dirs.dtype)) if need_coeffs else None,
    )


def sh_irradiance_forward(normals, coeffs, lobe, occluded, subset, constants) -> torch.Tensor:
    """Shadowed SH irradiance E[u, c] = sum_j (lobe_j Y_j(n_u) - O[subset_u, j]) coeffs[j, c] (renderer.
    _vertex_irradiance's formula): normals [U, 3], coeffs [B², C], lobe [B²] (A_l per coefficient), occluded
    [V, B²'] with B²' >= B² (None: nothing occluded), subset [U] long (None: U = V) -> [U, C]."""
    dirs = _array(normals)
    args = _irradiance_inputs(dirs, coeffs, lobe, occluded, subset, constants)
    out = np.empty((dirs.shape[0], coeffs.shape[1]), dtype=dirs.dtype)
    _pick(_sh_irradiance)(dirs, *args, _SH_CHUNK, out)
    return torch.from_numpy(out)


def sh_irradiance_backward(normals, coeffs, lobe, occluded, subset, grad, constants, need_normals, need_coeffs):
    """Gradients of ``sh_irradiance_forward`` to the normals [U, 3] and coeffs [B², C] (None where not needed);
    the coefficient gradient is summed per block of _SH_CHUNK normals, then over the blocks in order."""
    dirs = _array(normals)
    args = _irradiance_inputs(dirs, coeffs, lobe, occluded, subset, constants)
    blocks = (dirs.shape[0] + _SH_CHUNK - 1) // _SH_CHUNK
    grad_dirs = np.empty(dirs.shape, dtype=dirs.dtype)
    partial = np.empty((blocks if need_coeffs else 0, *coeffs.shape), dtype=np.float64)
    _pick(_sh_irradiance_vjp)(dirs, *args, _array(grad), _SH_CHUNK, need_normals, grad_dirs, partial)
    return (
        torch.from_numpy(grad_dirs) if need_normals else None,
        torch.from_numpy(partial.sum(0).astype(dirs.dtype)) if need_coeffs else None,
    )


def _irradiance_inputs(dirs: np.ndarray, coeffs, lobe, occluded, subset, constants) -> tuple:
    """(coeffs, lobe, occluded [V, B²'] or an empty [0, 0] array, subset or arange(U), constants) as arrays
    in the normals' dtype for the irradiance kernels."""
    dtype = dirs.dtype
    rows = np.zeros((0, 0), dtype=dtype) if occluded is None else _array(occluded).astype(dtype, copy=False)
    index = np.arange(dirs.shape[0]) if subset is None else _array(subset)
    as_dtype = (_array(t).astype(dtype, copy=False) for t in (coeffs, lobe))
    return (*as_dtype, rows, index, _constants_as(constants, dtype))


# -- area-weighted vertex normals -------------------------------------------------------------------
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


# -- mirrored view directions ----------------------------------------------------------------------
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


# -- vertex subsets --------------------------------------------------------------------------------
def renumber(corners: torch.Tensor, num_vertices: int) -> tuple[torch.Tensor, torch.Tensor]:
    """renderer._renumber: the vertices used by ``corners`` [N, 3] (ascending, [U]) and the corners
    renumbered into them [N, 3] (one pass to flag, one to number, one to map; no torch index ops)."""
    new_index = np.zeros(num_vertices, dtype=np.int64)
    local = np.empty(tuple(corners.shape), dtype=np.int64)
    count = _flag_and_number(_array(corners), new_index)
    used = np.empty(count, dtype=np.int64)
    _map_corners(_array(corners), new_index, used, local)
    return torch.from_numpy(used), torch.from_numpy(local)


# -- primary-ray selection --------------------------------------------------------------------------
_BOX_SLACK = 0.05
"""Pixels (fraction of a pixel) by which ``triangle_box_pixels`` widens each projected triangle box."""


def triangle_box_pixels(pixels: torch.Tensor, triangles: torch.Tensor, height: int, width: int) -> np.ndarray:
    """Flat indices (ascending) of the pixels whose centre lies in some triangle's projected bounding box,
    widened by _BOX_SLACK against rounding: vertices projected to pixels [V, 2], triangles [F, 3].

    Only valid when every vertex is in front of the camera (otherwise the projected boxes mean nothing).
    """
    mask = np.zeros((height, width), dtype=np.bool_)
    _mark_triangle_boxes(_array(pixels), _array(triangles), mask)
    return np.flatnonzero(mask)


def pixel_directions(flat: np.ndarray, size: tuple[int, int], focal: float, rotation: np.ndarray) -> np.ndarray:
    """renderer._pixel_rays' unit model-frame directions [N, 3] (float32) through the centres of the pixels
    ``flat`` (y * W + x) of an image size = (H, W), for a camera of ``focal`` (pixels) and rotation [3, 3]."""
    out = np.empty((flat.shape[0], 3), dtype=np.float32)
    _pixel_directions(np.ascontiguousarray(flat, dtype=np.int64), size[0], size[1], focal, rotation, out)
    return out


# -- fused pixel shading ----------------------------------------------------------------------------
SCREEN_CHANNELS = (2, 3, 1, 3, 3, 1)
"""Channels of the screen buffers ``shade_forward`` writes besides the images: uv, normals, depth,
diffuse, specular, roughness."""


def shade_forward(plain, bands_v, uvs, bary, textures, pixels, size):
    """Every screen buffer of the covered pixels in one pass (renderer._KernelShade has the formulas).

    plain [U, 3K+5] per-vertex (irradiance, normal, camera z, visibility), bands_v [U, B, 3K] specular
    band sums, uvs [Nuv, 2], bary [N, 3], textures (diffuse, specular, roughness) [Ht, Wt, C],
    pixels = (flat pixel index [N], vertex corners [N, 3], uv corners [N, 3]), size = (H, W).
    Returns images [K, H, W, 3] and the six screen buffers [H, W, C] of SCREEN_CHANNELS (0 elsewhere), and
    the filtered specular radiance per unit k_s [N, 3K] (float64 numpy) that ``shade_backward`` reuses.
    """
    arrays = [_array(t) for t in (plain, bands_v, uvs, bary, *textures)]
    covered, corners, uv_corners = (_array(t) for t in pixels)
    dtype = arrays[0].dtype
    height, width = size
    images = np.zeros((bands_v.shape[2] // 3, height, width, 3), dtype=dtype)
    screens = [np.zeros((height, width, c), dtype=dtype) for c in SCREEN_CHANNELS]
    lit = np.empty((bary.shape[0], bands_v.shape[2]))  # float64, exactly what the images used
    _pick(_shade_forward)(*arrays, covered, corners, uv_corners, images, *screens, lit)
    screens[2] = screens[2][..., 0]  # depth is [H, W]
    return [torch.from_numpy(a) for a in (images, *screens)], lit


def shade_backward(plain, bands_v, uvs, bary, textures, pixels, width, grads, need_textures, lit):
    """Gradients of ``shade_forward`` from the output gradients ``grads`` (None where unused); ``lit`` is
    what ``shade_forward`` returned with the images.

    Returns (grad plain [U, P], grad bands_v [U, B, 3K], grad bary [N, 3], texture grads (None where
    ``need_textures`` is False)). The per-vertex gradients are scattered from the pixels in pixel order
    into _SCATTER_PARTS buffers (one per contiguous range of pixels, summed in order afterwards), so
    they are the same for any number of threads.
    """
    arrays = [_array(t) for t in (plain, bands_v, uvs, bary, *textures)]
    covered, corners, uv_corners = (_array(t) for t in pixels)
    dtype = arrays[0].dtype
    num, bands, channels = bary.shape[0], bands_v.shape[1], bands_v.shape[2]
    given = np.array([g is not None for g in grads])
    outputs = [
        _array(g) if g is not None else np.zeros((1,) * ndim, dtype=dtype)
        for g, ndim in zip(grads, (4, 3, 3, 2, 3, 3, 3), strict=True)
    ]
    used = plain.shape[0]
    grad_plain = np.empty((_SCATTER_PARTS, used, plain.shape[1]), dtype=dtype)
    grad_bands = np.empty((_SCATTER_PARTS, used, bands * channels), dtype=dtype)
    grad_texels = np.empty((num, 7), dtype=dtype)  # d loss / d (diffuse, specular, roughness) samples
    grad_bary = np.empty((num, 3), dtype=dtype)
    scattered = (grad_plain, grad_bands, grad_texels, grad_bary)
    _pick(_shade_backward)(*arrays, covered, corners, uv_corners, width, given, *outputs, lit, *scattered)
    texture_grads = [
        np.empty(texture.shape if need else (0, 0, texture.shape[2]), dtype=dtype)  # zeroed by the scatter
        for texture, need in zip(arrays[4:], need_textures, strict=True)
    ]
    if any(need_textures):  # one pass for the three maps (they share the texel set-up)
        _pick(_scatter_texel_grads)(
            arrays[2], arrays[3], uv_corners, grad_texels, arrays[4].shape[:2], tuple(texture_grads), thread_count()
        )
    texture_grads = [torch.from_numpy(g) if g.size else None for g in texture_grads]
    grad_vertex, grad_bands = _sum_parts(grad_plain), _sum_parts(grad_bands).reshape(used, bands, channels)
    return torch.from_numpy(grad_vertex), torch.from_numpy(grad_bands), torch.from_numpy(grad_bary), texture_grads


_SCATTER_PARTS = 2
"""Contiguous pixel ranges whose per-vertex gradients are accumulated separately (in parallel on 2 threads)."""


def _sum_parts(parts: np.ndarray) -> np.ndarray:
    """parts [P, U, ...] summed in index order -> [U, ...] (into parts[0]; rows in parallel)."""
    flat = parts.reshape(parts.shape[0], parts.shape[1], -1)
    _pick(_sum_rows)(flat)
    return parts[0]


if numba is not None:
    # OpenMP first: the calling thread joins each kernel and the workers stay warm between the ~15 kernels of
    # a render. workqueue (the fallback where libgomp is missing) parks the calling thread and wakes its
    # workers for every kernel: 2-thread 256² step 48-53 ms wall median vs 44-45 with OpenMP and 1 torch
    # thread, 63 vs 32 ms with 2 torch threads (benchmarks/render.md, round 4). An idle OpenMP worker spins
    # briefly after each kernel; on a machine shared with other jobs NUMBA_THREADING_LAYER=workqueue avoids
    # that (an explicit NUMBA_THREADING_LAYER always wins). With 1 thread no layer is used at all.
    if "NUMBA_THREADING_LAYER" not in os.environ:
        numba.config.THREADING_LAYER_PRIORITY = ["omp", "workqueue", "tbb"]
        numba.config.THREADING_LAYER = "default"

    # reassociation lets LLVM vectorise the channel sums; results stay deterministic for a given build
    _FAST = {"reassoc", "contract"}

    class _serial_and_parallel:  # noqa: N801 - used as a decorator
        """One loop body compiled twice: ``serial`` (prange runs as range) and ``parallel``."""

        def __init__(self, function):
            self.serial = njit(cache=True, fastmath=_FAST)(function)
            # numba's on-disk cache is keyed by the function's name, not by its compile flags
            twin = types.FunctionType(function.__code__, function.__globals__, function.__name__)
            twin.__qualname__ = function.__qualname__ + "_parallel"
            self.parallel = njit(parallel=True, cache=True, fastmath=_FAST)(twin)

    @_serial_and_parallel
    def _interpolate_forward(values, corners, bary, lobe, out):
        bands, channels = values.shape[1], values.shape[2]
        for p in prange(corners.shape[0]):
            for c in range(channels):
                out[p, c] = 0.0
            for i in range(3):
                v = corners[p, i]
                for l in range(bands):  # noqa: E741
                    weight = bary[p, i] * lobe[p, l]
                    for c in range(channels):
                        out[p, c] += weight * values[v, l, c]

    @_serial_and_parallel
    def _interpolate_backward_corners(values, corners, bary, lobe, grad, grad_bary, grad_lobe):
        bands, channels = values.shape[1], values.shape[2]
        for p in prange(corners.shape[0]):
            for l in range(bands):  # noqa: E741
                grad_lobe[p, l] = 0.0
            for i in range(3):
                v = corners[p, i]
                total = 0.0
                for l in range(bands):  # noqa: E741
                    dot = 0.0
                    for c in range(channels):
                        dot += values[v, l, c] * grad[p, c]
                    total += lobe[p, l] * dot
                    grad_lobe[p, l] += bary[p, i] * dot
                grad_bary[p, i] = total

    @njit(cache=True)
    def _corners_by_vertex(corners, num_vertices):
        """Counting sort of the flat corner slots p*3+i by vertex: (offsets [U+1], slots [3N]), stable."""
        flat = corners.reshape(-1)
        offsets = np.zeros(num_vertices + 1, dtype=np.int64)
        for k in range(flat.shape[0]):
            offsets[flat[k] + 1] += 1
        for v in range(num_vertices):
            offsets[v + 1] += offsets[v]
        fill = offsets[:-1].copy()
        slots = np.empty(flat.shape[0], dtype=np.int64)
        for k in range(flat.shape[0]):
            slots[fill[flat[k]]] = k
            fill[flat[k]] += 1
        return offsets, slots

    @_serial_and_parallel
    def _interpolate_backward_values(offsets, slots, bary, lobe, grad, out):
        bands, channels = out.shape[1], out.shape[2]
        for v in prange(out.shape[0]):
            for l in range(bands):  # noqa: E741
                for c in range(channels):
                    out[v, l, c] = 0.0
            for k in range(offsets[v], offsets[v + 1]):
                p, i = slots[k] // 3, slots[k] % 3
                for l in range(bands):  # noqa: E741
                    weight = bary[p, i] * lobe[p, l]
                    for c in range(channels):
                        out[v, l, c] += weight * grad[p, c]

    @njit(inline="always")
    def _texel_axis(coordinate, size):
        """grid_sample (align_corners=False, border) along one axis: texel x0, fraction, d(coord)/d(input)."""
        position = coordinate * size - 0.5
        slope = float(size)
        if position <= 0.0:
            position, slope = 0.0, 0.0
        elif position >= size - 1:
            position, slope = float(size - 1), 0.0
        start = min(int(np.floor(position)), size - 1)
        return start, position - start, slope

    @_serial_and_parallel
    def _bilinear_forward(texture, uv, out):
        height, width, channels = texture.shape
        for p in prange(uv.shape[0]):
            x0, fx, _ = _texel_axis(uv[p, 0], width)
            y0, fy, _ = _texel_axis(1.0 - uv[p, 1], height)  # row 0 is v = 1
            x1, y1 = min(x0 + 1, width - 1), min(y0 + 1, height - 1)
            for c in range(channels):
                top = texture[y0, x0, c] * (1.0 - fx) + texture[y0, x1, c] * fx
                bottom = texture[y1, x0, c] * (1.0 - fx) + texture[y1, x1, c] * fx
                out[p, c] = top * (1.0 - fy) + bottom * fy

    @njit(cache=True)
    def _bilinear_scatter(uv, grad, grad_texture):
        height, width, channels = grad_texture.shape
        for p in range(uv.shape[0]):  # serial: texels are shared between pixels
            x0, fx, _ = _texel_axis(uv[p, 0], width)
            y0, fy, _ = _texel_axis(1.0 - uv[p, 1], height)
            x1, y1 = min(x0 + 1, width - 1), min(y0 + 1, height - 1)
            for c in range(channels):
                g = grad[p, c]
                grad_texture[y0, x0, c] += g * (1.0 - fx) * (1.0 - fy)
                grad_texture[y0, x1, c] += g * fx * (1.0 - fy)
                grad_texture[y1, x0, c] += g * (1.0 - fx) * fy
                grad_texture[y1, x1, c] += g * fx * fy

    @_serial_and_parallel
    def _bilinear_grad_uv(texture, uv, grad, grad_uv):
        height, width, channels = texture.shape
        for p in prange(uv.shape[0]):
            x0, fx, slope_x = _texel_axis(uv[p, 0], width)
            y0, fy, slope_y = _texel_axis(1.0 - uv[p, 1], height)
            x1, y1 = min(x0 + 1, width - 1), min(y0 + 1, height - 1)
            d_fx = 0.0
            d_fy = 0.0
            for c in range(channels):
                t00, t01 = texture[y0, x0, c], texture[y0, x1, c]
                t10, t11 = texture[y1, x0, c], texture[y1, x1, c]
                d_fx += grad[p, c] * ((t01 - t00) * (1.0 - fy) + (t11 - t10) * fy)
                d_fy += grad[p, c] * ((t10 - t00) * (1.0 - fx) + (t11 - t01) * fx)
            grad_uv[p, 0] = d_fx * slope_x
            grad_uv[p, 1] = -d_fy * slope_y  # y = (1 - v) * Ht - 0.5

    @njit(inline="always")
    def _edge_functions(p, triangles, tri, flat, centres, width, n):
        """Corner indices (i0, i1, i2) of pixel n's triangle, corner offsets d_i = p[i] - q from its centre q
        and s_i = cross(d_{i+1}, d_{i+2}) (~2 x sub-areas), as one flat tuple (i0, i1, i2, d0x, d1x, d2x,
        d0y, d1y, d2y, s0, s1, s2): scalars only, no per-pixel arrays."""
        qx, qy = centres[flat[n] % width], centres[flat[n] // width]
        f = tri[n]
        i0, i1, i2 = triangles[f, 0], triangles[f, 1], triangles[f, 2]
        d0x, d1x, d2x = p[i0, 0] - qx, p[i1, 0] - qx, p[i2, 0] - qx
        d0y, d1y, d2y = p[i0, 1] - qy, p[i1, 1] - qy, p[i2, 1] - qy
        return (
            i0, i1, i2, d0x, d1x, d2x, d0y, d1y, d2y,
            d1x * d2y - d1y * d2x, d2x * d0y - d2y * d0x, d0x * d1y - d0y * d1x,
        )  # fmt: skip

    @_serial_and_parallel
    def _barycentrics_forward(pixels, depth, triangles, tri, flat, centres, width, tiny, out):
        for n in prange(out.shape[0]):
            edges = _edge_functions(pixels, triangles, tri, flat, centres, width, n)
            i0, i1, i2, s0, s1, s2 = edges[0], edges[1], edges[2], edges[9], edges[10], edges[11]
            area = s0 + s1 + s2
            if abs(area) < tiny:
                area = tiny
            w0 = s0 / area / depth[i0]
            w1 = s1 / area / depth[i1]
            w2 = s2 / area / depth[i2]
            total = w0 + w1 + w2
            out[n, 0], out[n, 1], out[n, 2] = w0 / total, w1 / total, w2 / total

    @_serial_and_parallel
    def _barycentrics_backward(pixels, depth, triangles, tri, flat, centres, width, tiny, grad, grad_p, grad_z):
        """Gradients to each pixel's corners: grad_p [N, 3, 2], grad_z [N, 3] (reciprocals: few divisions)."""
        for n in prange(grad.shape[0]):
            edges = _edge_functions(pixels, triangles, tri, flat, centres, width, n)
            d_x, d_y, s = edges[3:6], edges[6:9], edges[9:12]
            area = s[0] + s[1] + s[2]
            degenerate = abs(area) < tiny
            if degenerate:
                area = tiny
            inv_area = 1.0 / area
            inv_z = (1.0 / depth[edges[0]], 1.0 / depth[edges[1]], 1.0 / depth[edges[2]])
            w = (s[0] * inv_area * inv_z[0], s[1] * inv_area * inv_z[1], s[2] * inv_area * inv_z[2])
            inv_total = 1.0 / (w[0] + w[1] + w[2])
            mean = (grad[n, 0] * w[0] + grad[n, 1] * w[1] + grad[n, 2] * w[2]) * inv_total
            grad_area = 0.0
            for i in range(3):
                h = (grad[n, i] - mean) * inv_total  # d loss / d w_i
                grad_z[n, i] = -h * w[i] * inv_z[i]
                grad_area -= h * w[i] * inv_area
                grad_p[n, i, 0], grad_p[n, i, 1] = 0.0, 0.0
            if degenerate:
                grad_area = 0.0
            for i in range(3):  # s_i = d_j.x d_k.y - d_j.y d_k.x
                j, k = (i + 1) % 3, (i + 2) % 3
                g = (grad[n, i] - mean) * inv_total * inv_area * inv_z[i] + grad_area
                grad_p[n, j, 0] += g * d_y[k]
                grad_p[n, j, 1] -= g * d_x[k]
                grad_p[n, k, 0] -= g * d_y[j]
                grad_p[n, k, 1] += g * d_x[j]

    @njit(cache=True)
    def _scatter_corners(triangles, tri, grad_p, grad_z, grad_pixels, grad_depth):
        for n in range(tri.shape[0]):  # serial, pixel order: vertices are shared between pixels
            for i in range(3):
                v = triangles[tri[n], i]
                grad_pixels[v, 0] += grad_p[n, i, 0]
                grad_pixels[v, 1] += grad_p[n, i, 1]
                grad_depth[v] += grad_z[n, i]

    @njit(inline="always")
    def _accumulate_rows(rows, coeffs, first, last, size, sums):
        """sums[c, k] += sum_{first <= j < last} coeffs[j, c] rows[j, k] for the block's ``size`` directions."""
        for j in range(first, last):
            for c in range(coeffs.shape[1]):
                weight = coeffs[j, c]
                for k in range(size):
                    sums[c, k] += weight * rows[j, k]

    @njit(inline="always")
    def _block_span(block, chunk, count):
        """First direction and number of directions of block ``block`` of ``chunk`` among ``count``."""
        start = block * chunk
        return start, min(count, start + chunk) - start

    @njit(inline="always")
    def _sh_block_rows(directions, constants, start, size, rows, d_rows, derivative):
        """Y_j (index l*l+l+m) of directions[start : start + size] into the columns 0..size-1 of ``rows``
        [B², chunk], and dY_j/d(x, y, z) into ``d_rows`` [3, B², chunk] if ``derivative``: the recurrences of
        sh.py (Q_l^m(z) times Re/Im (x+iy)^m), each step run along the block of directions (vectorised)."""
        diagonal, a, b = constants
        bands, chunk = diagonal.shape[0], rows.shape[1]
        cos_m, sin_m, z = (
            np.empty((bands, chunk), rows.dtype),
            np.empty((bands, chunk), rows.dtype),
            np.empty(chunk, rows.dtype),
        )
        q, dq = (
            np.empty((3, bands, chunk), rows.dtype),
            np.empty((3, bands, chunk), rows.dtype),
        )  # bands l, l-1, l-2 in slots l % 3
        for k in range(size):
            z[k] = directions[start + k, 2]
            cos_m[0, k], sin_m[0, k] = 1.0, 0.0
        for m in range(1, bands):
            for k in range(size):
                x, y = directions[start + k, 0], directions[start + k, 1]
                cos_m[m, k] = cos_m[m - 1, k] * x - sin_m[m - 1, k] * y
                sin_m[m, k] = sin_m[m - 1, k] * x + cos_m[m - 1, k] * y
        root2 = np.sqrt(2.0)
        for l in range(bands):  # noqa: E741
            cur, prev, prev2 = q[l % 3], q[(l + 2) % 3], q[(l + 1) % 3]
            d_cur, d_prev, d_prev2 = dq[l % 3], dq[(l + 2) % 3], dq[(l + 1) % 3]
            for m in range(l - 1):
                a_lm, b_lm = a[l, m], b[l, m]
                for k in range(size):
                    cur[m, k] = a_lm * (z[k] * prev[m, k] - b_lm * prev2[m, k])
                if derivative:
                    for k in range(size):
                        d_cur[m, k] = a_lm * (prev[m, k] + z[k] * d_prev[m, k] - b_lm * d_prev2[m, k])
            if l >= 1:
                root = np.sqrt(2.0 * l + 1.0)
                for k in range(size):
                    cur[l - 1, k] = root * z[k] * prev[l - 1, k]
                    d_cur[l - 1, k] = root * prev[l - 1, k]  # Q_{l-1}^{l-1} is constant
            for k in range(size):
                cur[l, k], d_cur[l, k] = diagonal[l], 0.0
            centre = l * l + l
            for k in range(size):
                rows[centre, k] = cur[0, k]
            if derivative:
                for k in range(size):
                    d_rows[0, centre, k], d_rows[1, centre, k], d_rows[2, centre, k] = 0.0, 0.0, d_cur[0, k]
            for m in range(1, l + 1):
                for k in range(size):
                    rows[centre + m, k] = root2 * cur[m, k] * cos_m[m, k]
                    rows[centre - m, k] = root2 * cur[m, k] * sin_m[m, k]
                if derivative:
                    for k in range(size):
                        mq = root2 * m * cur[m, k]
                        d_rows[0, centre + m, k] = mq * cos_m[m - 1, k]
                        d_rows[1, centre + m, k] = -mq * sin_m[m - 1, k]
                        d_rows[2, centre + m, k] = root2 * d_cur[m, k] * cos_m[m, k]
                        d_rows[0, centre - m, k] = mq * sin_m[m - 1, k]
                        d_rows[1, centre - m, k] = mq * cos_m[m - 1, k]
                        d_rows[2, centre - m, k] = root2 * d_cur[m, k] * sin_m[m, k]

    @_serial_and_parallel
    def _sh_basis(directions, constants, chunk, out, channel_first):
        bands = constants[0].shape[0]
        count = directions.shape[0]
        for block in prange((count + chunk - 1) // chunk):
            start, size = _block_span(block, chunk, count)
            rows = np.empty((bands * bands, chunk), directions.dtype)
            _sh_block_rows(directions, constants, start, size, rows, rows[None], False)
            if channel_first:
                for j in range(bands * bands):
                    for k in range(size):
                        out[j, start + k] = rows[j, k]
            else:  # [N, B²]: a transpose within the block (it stays in cache)
                for k in range(size):
                    for j in range(bands * bands):
                        out[start + k, j] = rows[j, k]

    @_serial_and_parallel
    def _sh_basis_vjp(directions, constants, grad, chunk, out):
        bands = constants[0].shape[0]
        count = directions.shape[0]
        for block in prange((count + chunk - 1) // chunk):
            start, size = _block_span(block, chunk, count)
            rows, d_rows = (
                np.empty((bands * bands, chunk), directions.dtype),
                np.empty((3, bands * bands, chunk), directions.dtype),
            )
            _sh_block_rows(directions, constants, start, size, rows, d_rows, True)
            totals = np.zeros((3, chunk), directions.dtype)
            for j in range(bands * bands):
                for axis in range(3):
                    for k in range(size):
                        totals[axis, k] += grad[j, start + k] * d_rows[axis, j, k]
            for k in range(size):
                out[start + k, 0], out[start + k, 1], out[start + k, 2] = totals[0, k], totals[1, k], totals[2, k]

    @_serial_and_parallel
    def _sh_band_sums(directions, coeffs, constants, chunk, out):
        bands = constants[0].shape[0]
        count, channels = directions.shape[0], coeffs.shape[1]
        for block in prange((count + chunk - 1) // chunk):
            start, size = _block_span(block, chunk, count)
            rows, sums = (
                np.empty((bands * bands, chunk), directions.dtype),
                np.empty((channels, chunk), directions.dtype),
            )
            _sh_block_rows(directions, constants, start, size, rows, rows[None], False)
            for l in range(bands):  # noqa: E741
                sums[:] = 0.0
                _accumulate_rows(rows, coeffs, l * l, (l + 1) * (l + 1), size, sums)
                for k in range(size):
                    for c in range(channels):
                        out[start + k, l, c] = sums[c, k]

    @_serial_and_parallel
    def _sh_band_sums_vjp(directions, coeffs, grad, constants, chunk, need_directions, grad_dirs, partial):
        bands = constants[0].shape[0]
        count, channels = directions.shape[0], coeffs.shape[1]
        need_coeffs = partial.shape[0] > 0
        for block in prange((count + chunk - 1) // chunk):
            start, size = _block_span(block, chunk, count)
            rows, d_rows = (
                np.empty((bands * bands, chunk), directions.dtype),
                np.empty((3, bands * bands, chunk), directions.dtype),
            )
            _sh_block_rows(directions, constants, start, size, rows, d_rows, need_directions)
            grad_rows, grad_block = (
                np.zeros((3, chunk), directions.dtype),
                np.empty((channels, chunk), directions.dtype),
            )
            g_basis = np.empty(chunk, directions.dtype)
            for l in range(bands):  # noqa: E741
                for k in range(size):
                    for c in range(channels):
                        grad_block[c, k] = grad[start + k, l, c]
                for j in range(l * l, (l + 1) * (l + 1)):
                    if need_coeffs:  # this block's share of the coefficient gradient
                        for c in range(channels):
                            total = 0.0
                            for k in range(size):
                                total += rows[j, k] * grad_block[c, k]
                            partial[block, j, c] = total
                    if need_directions:
                        g_basis[:] = 0.0  # d loss / d Y_j = sum_c grad[n, l, c] coeffs[j, c]
                        for c in range(channels):
                            weight = coeffs[j, c]
                            for k in range(size):
                                g_basis[k] += weight * grad_block[c, k]
                        for axis in range(3):
                            for k in range(size):
                                grad_rows[axis, k] += g_basis[k] * d_rows[axis, j, k]
            if need_directions:
                for k in range(size):
                    for axis in range(3):
                        grad_dirs[start + k, axis] = grad_rows[axis, k]

    @njit(inline="always")
    def _transfer_rows(rows, lobe, occluded, subset, start, size):
        """rows[j, k] <- lobe_j Y_j - O[subset[start + k], j]: the shadowed transfer of the block's normals."""
        shadowed = occluded.shape[0] > 0
        for k in range(size):
            vertex = subset[start + k]
            for j in range(rows.shape[0]):
                rows[j, k] = lobe[j] * rows[j, k] - (occluded[vertex, j] if shadowed else 0.0)

    @_serial_and_parallel
    def _sh_irradiance(directions, coeffs, lobe, occluded, subset, constants, chunk, out):
        bands = constants[0].shape[0]
        count, channels = directions.shape[0], coeffs.shape[1]
        for block in prange((count + chunk - 1) // chunk):
            start, size = _block_span(block, chunk, count)
            rows = np.empty((bands * bands, chunk), directions.dtype)
            sums = np.zeros((channels, chunk), directions.dtype)
            _sh_block_rows(directions, constants, start, size, rows, rows[None], False)
            _transfer_rows(rows, lobe, occluded, subset, start, size)
            _accumulate_rows(rows, coeffs, 0, bands * bands, size, sums)
            for k in range(size):
                for c in range(channels):
                    out[start + k, c] = sums[c, k]

    @_serial_and_parallel
    def _sh_irradiance_vjp(
        directions, coeffs, lobe, occluded, subset, constants, grad, chunk, need_directions, grad_dirs, partial
    ):
        bands = constants[0].shape[0]
        count, channels = directions.shape[0], coeffs.shape[1]
        for block in prange((count + chunk - 1) // chunk):
            start, size = _block_span(block, chunk, count)
            rows = np.empty((bands * bands, chunk), directions.dtype)
            d_rows = np.empty((3, bands * bands, chunk), directions.dtype)
            _sh_block_rows(directions, constants, start, size, rows, d_rows, need_directions)
            grad_block = np.empty((channels, chunk), directions.dtype)
            for k in range(size):
                for c in range(channels):
                    grad_block[c, k] = grad[start + k, c]
            if need_directions:  # d loss / d n = sum_j lobe_j (sum_c coeffs[j, c] grad[c]) dY_j / dn
                grad_rows, g_basis = np.zeros((3, chunk), directions.dtype), np.empty(chunk, directions.dtype)
                for j in range(bands * bands):
                    g_basis[:] = 0.0
                    for c in range(channels):
                        weight = coeffs[j, c] * lobe[j]
                        for k in range(size):
                            g_basis[k] += weight * grad_block[c, k]
                    for axis in range(3):
                        for k in range(size):
                            grad_rows[axis, k] += g_basis[k] * d_rows[axis, j, k]
                for k in range(size):
                    for axis in range(3):
                        grad_dirs[start + k, axis] = grad_rows[axis, k]
            if partial.shape[0] > 0:  # this block's share of d loss / d coeffs[j, c] = sum_k T_j(k) grad[k, c]
                _transfer_rows(rows, lobe, occluded, subset, start, size)
                for j in range(bands * bands):
                    for c in range(channels):
                        total = 0.0
                        for k in range(size):
                            total += rows[j, k] * grad_block[c, k]
                        partial[block, j, c] = total

    @njit(inline="always")
    def _bilinear_setup(uv0, uv1, height, width):
        """Texels, fractions and slopes of a bilinear lookup at (u, v) (sample_texture's convention)."""
        x0, fx, slope_x = _texel_axis(uv0, width)
        y0, fy, slope_y = _texel_axis(1.0 - uv1, height)
        return x0, min(x0 + 1, width - 1), fx, slope_x, y0, min(y0 + 1, height - 1), fy, slope_y

    @njit(inline="always")
    def _bilinear_sample(texture, x0, x1, fx, y0, y1, fy, c):
        return _bilinear_mix(_texel_corners(texture, x0, x1, y0, y1, c), fx, fy)

    @njit(inline="always")
    def _bilinear_mix(texels, fx, fy):
        """Bilinear blend of the texels (t00, t01, t10, t11) at (y0, x0), (y0, x1), (y1, x0), (y1, x1)."""
        t00, t01, t10, t11 = texels
        top = t00 * (1.0 - fx) + t01 * fx
        bottom = t10 * (1.0 - fx) + t11 * fx
        return top * (1.0 - fy) + bottom * fy

    @njit(inline="always")
    def _bilinear_slopes(texels, fx, fy):
        """d blend / d fx and d blend / d fy of ``_bilinear_mix``."""
        t00, t01, t10, t11 = texels
        return (t01 - t00) * (1.0 - fy) + (t11 - t10) * fy, (t10 - t00) * (1.0 - fx) + (t11 - t01) * fx

    @_serial_and_parallel
    def _scatter_texel_grads(uvs, bary, uv_corners, grad_texels, size, grad_maps, row_ranges):
        """Bilinear scatter of grad_texels [N, 7] (diffuse, specular, roughness columns) into the maps' gradients
        ``grad_maps`` (3 arrays [Ht, Wt, C], overwritten; empty ones are skipped). Texel rows are split into
        ``row_ranges`` ranges, one per thread; each zeroes its rows, then scans the pixels in order and adds
        only to its own rows, so every texel sums its pixels in pixel order whatever the number of ranges
        (texels are shared between pixels)."""
        height, width = size
        for part in prange(row_ranges):
            first, last = part * height // row_ranges, (part + 1) * height // row_ranges
            for m in range(len(grad_maps)):
                if grad_maps[m].shape[0] > 0:
                    grad_maps[m][first:last] = 0.0
            for p in range(bary.shape[0]):
                u, v = _uv_at(uvs, bary, uv_corners, p)
                y0, fy, _ = _texel_axis(1.0 - v, height)
                y1 = min(y0 + 1, height - 1)
                top, bottom = first <= y0 < last, first <= y1 < last
                if not (top or bottom):
                    continue
                x0, fx, _ = _texel_axis(u, width)
                x1 = min(x0 + 1, width - 1)
                column = 0
                for m in range(len(grad_maps)):
                    grad_map = grad_maps[m]
                    channels = grad_map.shape[2]
                    if grad_map.shape[0] > 0:
                        for c in range(channels):
                            g = grad_texels[p, column + c]
                            if top:
                                grad_map[y0, x0, c] += g * (1.0 - fx) * (1.0 - fy)
                                grad_map[y0, x1, c] += g * fx * (1.0 - fy)
                            if bottom:
                                grad_map[y1, x0, c] += g * (1.0 - fx) * fy
                                grad_map[y1, x1, c] += g * fx * fy
                    column += channels

    @njit(inline="always")
    def _uv_at(uvs, bary, uv_corners, p):
        """Interpolated (u, v) of covered pixel p."""
        c0, c1, c2 = uv_corners[p, 0], uv_corners[p, 1], uv_corners[p, 2]
        b0, b1, b2 = bary[p, 0], bary[p, 1], bary[p, 2]
        return b0 * uvs[c0, 0] + b1 * uvs[c1, 0] + b2 * uvs[c2, 0], b0 * uvs[c0, 1] + b1 * uvs[c1, 1] + b2 * uvs[c2, 1]

    @njit(inline="always")
    def _pixel_inputs(plain, flat_bands, uvs, bary, roughness_map, p, corners, uv_corners, values, summed, lobe, lit):
        """What forward and backward both need at covered pixel p: the interpolated per-vertex values and
        band sums (into ``values``, ``summed``), the Phong filter and filtered specular (``lobe``, ``lit``);
        returns u, v, the bilinear set-up, the roughness, the exponent and d exponent / d roughness (one flat
        tuple: nested tuples trip numba's parfor analysis)."""
        _interpolate_row(plain, corners, bary, p, values)
        _interpolate_row(flat_bands, corners, bary, p, summed)
        u, v = _uv_at(uvs, bary, uv_corners, p)
        x0, x1, fx, slope_x, y0, y1, fy, slope_y = _bilinear_setup(u, v, roughness_map.shape[0], roughness_map.shape[1])
        roughness = _bilinear_sample(roughness_map, x0, x1, fx, y0, y1, fy, 0)
        exponent, d_exponent = _phong_lobe(roughness, lobe)
        _filter_bands(summed, lobe, lit)
        return u, v, x0, x1, fx, slope_x, y0, y1, fy, slope_y, roughness, exponent, d_exponent

    @njit(inline="always")
    def _phong_lobe(roughness, lobe):
        """sh.phong_lobe_filter into ``lobe`` [B]; returns the exponent s and d s / d roughness."""
        alpha, d_alpha = roughness, 1.0
        if roughness < 1e-3:
            alpha, d_alpha = 1e-3, 0.0
        elif roughness > 1.0:
            alpha, d_alpha = 1.0, 0.0
        exponent = 2.0 / (alpha * alpha) - 2.0
        d_exponent = -4.0 / (alpha * alpha * alpha) * d_alpha
        if exponent < 1e-4:
            exponent, d_exponent = 1e-4, 0.0
        # lobe_l = q^(l²) with q = exp(-1 / (2 s)): one exp per pixel, then q^(2l - 1) step by step
        q = np.exp(-1.0 / (2.0 * exponent))
        lobe[0], step = 1.0, q
        for l in range(1, lobe.shape[0]):  # noqa: E741
            lobe[l] = lobe[l - 1] * step
            step *= q * q
        return exponent, d_exponent

    @njit(inline="always")
    def _filter_bands(summed, lobe, lit):
        """lit [C] = sum_l lobe[l] summed[l*C : (l+1)*C] (band-major rows, vectorised along C)."""
        channels = lit.shape[0]
        lit[:] = 0.0
        for l in range(lobe.shape[0]):  # noqa: E741
            weight = lobe[l]
            for j in range(channels):
                lit[j] += weight * summed[l * channels + j]

    @njit(inline="always")
    def _interpolate_row(values, corners, bary, p, out):
        """out [C] = sum_i bary[p, i] values[corners[p, i]] for values [U, C] (contiguous, vectorised)."""
        v0, v1, v2 = corners[p, 0], corners[p, 1], corners[p, 2]
        b0, b1, b2 = bary[p, 0], bary[p, 1], bary[p, 2]
        for c in range(out.shape[0]):
            out[c] = b0 * values[v0, c] + b1 * values[v1, c] + b2 * values[v2, c]

    @_serial_and_parallel
    def _shade_forward(
        plain,
        bands_v,
        uvs,
        bary,
        diffuse_map,
        specular_map,
        roughness_map,
        covered,
        corners,
        uv_corners,
        images,
        uv_out,
        normal_out,
        depth_out,
        diffuse_out,
        specular_out,
        roughness_out,
        lit_out,
    ):
        num_channels, bands = bands_v.shape[2], bands_v.shape[1]
        lights = num_channels // 3
        width = images.shape[2]
        flat_bands = bands_v.reshape(bands_v.shape[0], bands * num_channels)
        for block in prange((bary.shape[0] + 255) // 256):
            values, summed = np.empty(plain.shape[1], plain.dtype), np.empty(bands * num_channels, plain.dtype)
            lobe, lit = np.empty(bands), np.empty(num_channels)
            diffuse, specular = np.empty(3), np.empty(3)
            for p in range(block * 256, min(bary.shape[0], (block + 1) * 256)):
                y, x = covered[p] // width, covered[p] % width
                u, v, x0, x1, fx, _, y0, y1, fy, _, roughness, _, _ = _pixel_inputs(
                    plain, flat_bands, uvs, bary, roughness_map, p, corners, uv_corners, values, summed, lobe, lit
                )
                visibility = values[num_channels + 4]
                lit_out[p, :] = lit
                for c in range(3):
                    diffuse[c] = _bilinear_sample(diffuse_map, x0, x1, fx, y0, y1, fy, c)
                    specular[c] = _bilinear_sample(specular_map, x0, x1, fx, y0, y1, fy, c)
                    diffuse_out[y, x, c], specular_out[y, x, c] = diffuse[c], specular[c]
                # lights outside, channels inside: contiguous writes (a channel-outer loop was vectorised
                # across the lights into gathers and scatters, slow on this CPU)
                for k in range(lights):
                    for c in range(3):
                        j = 3 * k + c
                        images[k, y, x, c] = values[j] * (diffuse[c] / np.pi) + lit[j] * visibility * specular[c]
                norm = np.sqrt(
                    values[num_channels] ** 2 + values[num_channels + 1] ** 2 + values[num_channels + 2] ** 2
                )
                norm = max(norm, 1e-12)
                for a in range(3):
                    normal_out[y, x, a] = values[num_channels + a] / norm
                uv_out[y, x, 0], uv_out[y, x, 1] = u, v
                depth_out[y, x, 0] = values[num_channels + 3]
                roughness_out[y, x, 0] = roughness

    @_serial_and_parallel
    def _shade_backward(
        plain,
        bands_v,
        uvs,
        bary,
        diffuse_map,
        specular_map,
        roughness_map,
        covered,
        corners,
        uv_corners,
        width,
        given,
        g_images,
        g_uv,
        g_normal,
        g_depth,
        g_diffuse,
        g_specular,
        g_roughness,
        lit_saved,
        grad_plain,
        grad_bands,
        grad_texels,
        grad_bary,
    ):
        """One pass over the pixels; scatters the vertex gradients into grad_plain / grad_bands [parts, U, .]
        (part k holds the k-th contiguous range of pixels, accumulated in pixel order)."""
        num_channels, bands = bands_v.shape[2], bands_v.shape[1]
        lights, row = num_channels // 3, bands * num_channels
        flat_bands = bands_v.reshape(bands_v.shape[0], row)
        parts, num = grad_plain.shape[0], bary.shape[0]
        for part in prange(parts):
            grad_plain[part] = 0.0
            grad_bands[part] = 0.0
            values, g_values = np.empty(plain.shape[1]), np.empty(plain.shape[1])
            lobe, g_lit = np.empty(bands), np.empty(num_channels)
            # d loss / d summed[l*C + j] = lobe_l g_lit_j, and the same times l² (for d lobe / d exponent)
            g_summed, g_summed_l2 = np.empty(row), np.empty(row)
            spec_bary = np.empty(3)  # d loss / d bary through the specular band sums
            diffuse_pi, specular, g_irradiance, g_specular_c = np.empty(3), np.empty(3), np.empty(3), np.empty(3)
            for p in range(part * num // parts, (part + 1) * num // parts):
                y, x = covered[p] // width, covered[p] % width
                _interpolate_row(plain, corners, bary, p, values)
                u, v = _uv_at(uvs, bary, uv_corners, p)
                x0, x1, fx, slope_x, y0, y1, fy, slope_y = _bilinear_setup(
                    u, v, roughness_map.shape[0], roughness_map.shape[1]
                )
                roughness = _bilinear_sample(roughness_map, x0, x1, fx, y0, y1, fy, 0)
                exponent, d_exponent = _phong_lobe(roughness, lobe)
                visibility = values[num_channels + 4]
                g_visibility = 0.0
                d_fx, d_fy = 0.0, 0.0  # d loss / d bilinear fractions, summed over the three maps
                for c in range(3):
                    diffuse_pi[c] = _bilinear_sample(diffuse_map, x0, x1, fx, y0, y1, fy, c) / np.pi
                    specular[c] = _bilinear_sample(specular_map, x0, x1, fx, y0, y1, fy, c)
                    g_irradiance[c] = 0.0  # sum_k g * irradiance_k, times 1/pi below (one division per channel)
                    g_specular_c[c] = g_specular[y, x, c] if given[5] else 0.0
                g_lit[:] = 0.0
                g_values[:num_channels] = 0.0
                if given[0]:  # lights outside, channels inside: contiguous, no gathers (see _shade_forward)
                    for k in range(lights):
                        for c in range(3):
                            j = 3 * k + c
                            g = g_images[k, y, x, c]
                            g_values[j] = g * diffuse_pi[c]
                            g_irradiance[c] += g * values[j]
                            g_lit[j] = g * visibility * specular[c]
                            g_visibility += g * lit_saved[p, j] * specular[c]
                            g_specular_c[c] += g * lit_saved[p, j] * visibility
                for c in range(3):
                    g_d = g_irradiance[c] / np.pi + (g_diffuse[y, x, c] if given[4] else 0.0)
                    g_s = g_specular_c[c]
                    grad_texels[p, c], grad_texels[p, 3 + c] = g_d, g_s
                    slope_fx, slope_fy = _bilinear_slopes(_texel_corners(diffuse_map, x0, x1, y0, y1, c), fx, fy)
                    d_fx, d_fy = d_fx + g_d * slope_fx, d_fy + g_d * slope_fy
                    slope_fx, slope_fy = _bilinear_slopes(_texel_corners(specular_map, x0, x1, y0, y1, c), fx, fy)
                    d_fx, d_fy = d_fx + g_s * slope_fx, d_fy + g_s * slope_fy
                for l in range(bands):  # noqa: E741
                    for j in range(num_channels):
                        g_summed[l * num_channels + j] = lobe[l] * g_lit[j]
                        g_summed_l2[l * num_channels + j] = lobe[l] * g_lit[j] * (l * l)
                # normals: n / max(|n|, 1e-12)
                norm = np.sqrt(
                    values[num_channels] ** 2 + values[num_channels + 1] ** 2 + values[num_channels + 2] ** 2
                )
                clamped = max(norm, 1e-12)
                dot = 0.0
                for a in range(3):
                    g_n = g_normal[y, x, a] if given[2] else 0.0
                    g_values[num_channels + a] = g_n / clamped
                    dot += g_n * values[num_channels + a]
                if norm >= 1e-12:
                    for a in range(3):
                        g_values[num_channels + a] -= dot / (clamped * clamped) * values[num_channels + a] / norm
                g_values[num_channels + 3] = g_depth[y, x] if given[3] else 0.0
                g_values[num_channels + 4] = g_visibility
                # lobe_l = exp(-l² / (2 s)): d lobe_l / d s = lobe_l l² / (2 s²); the band sums are interpolated,
                # so d loss / d s = sum_i bary_i sum_lj S[corner_i, lj] lobe_l l² g_lit_j / (2 s²)
                g_exponent = 0.0
                for i in range(3):
                    vertex = corners[p, i]
                    to_bary, to_exponent = 0.0, 0.0
                    for k in range(row):
                        to_bary += flat_bands[vertex, k] * g_summed[k]
                        to_exponent += flat_bands[vertex, k] * g_summed_l2[k]
                    spec_bary[i] = to_bary
                    g_exponent += bary[p, i] * to_exponent
                g_r = g_exponent / (2.0 * exponent * exponent) * d_exponent
                g_r += g_roughness[y, x, 0] if given[6] else 0.0
                grad_texels[p, 6] = g_r
                slope_fx, slope_fy = _bilinear_slopes(_texel_corners(roughness_map, x0, x1, y0, y1, 0), fx, fy)
                d_fx, d_fy = d_fx + g_r * slope_fx, d_fy + g_r * slope_fy
                g_u = d_fx * slope_x + (g_uv[y, x, 0] if given[1] else 0.0)
                g_v = -d_fy * slope_y + (g_uv[y, x, 1] if given[1] else 0.0)
                for i in range(3):
                    vertex, weight = corners[p, i], bary[p, i]
                    total = g_u * uvs[uv_corners[p, i], 0] + g_v * uvs[uv_corners[p, i], 1] + spec_bary[i]
                    for c in range(plain.shape[1]):
                        total += plain[vertex, c] * g_values[c]
                        grad_plain[part, vertex, c] += weight * g_values[c]
                    for k in range(row):
                        grad_bands[part, vertex, k] += weight * g_summed[k]
                    grad_bary[p, i] = total

    @_serial_and_parallel
    def _sum_rows(parts):
        """parts[0] += parts[1] + ... (in index order), [P, U, C], one row per iteration."""
        for u in prange(parts.shape[1]):
            for k in range(1, parts.shape[0]):
                for c in range(parts.shape[2]):
                    parts[0, u, c] += parts[k, u, c]

    @njit(inline="always")
    def _texel_corners(texture, x0, x1, y0, y1, c):
        return texture[y0, x0, c], texture[y0, x1, c], texture[y1, x0, c], texture[y1, x1, c]

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

    @_serial_and_parallel
    def _vertex_normals(vertices, triangles, offsets, slots, out):
        for v in prange(vertices.shape[0]):
            mx, my, mz = _vertex_sum(vertices, triangles, offsets, slots, v)
            norm = max(np.sqrt(mx * mx + my * my + mz * mz), 1e-12)
            out[v, 0], out[v, 1], out[v, 2] = mx / norm, my / norm, mz / norm

    @_serial_and_parallel
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
    def _pixel_directions(flat, height, width, focal, rotation, out):
        for n in range(flat.shape[0]):
            y, x = flat[n] // width, flat[n] % width
            cx, cy = (x + 0.5 - width / 2) / focal, (y + 0.5 - height / 2) / focal  # camera frame, z = 1
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
            if not (np.isfinite(lo_x) and np.isfinite(hi_x) and np.isfinite(lo_y) and np.isfinite(hi_y)):
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
