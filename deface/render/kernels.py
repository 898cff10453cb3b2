"""Fused numba kernels for the renderer's hot loops: barycentrics, corner interpolation (plain and
band-filtered), bilinear texture lookup, per-pixel radiance, SH basis rows; each with its backward.

Each kernel has a torch reference path next to its caller (renderer.py, mesh.py, sh.py); these are the
fast CPU path, used for CPU tensors when numba is importable and ``DEFACE_RENDER_KERNELS`` is not
``torch`` (tests/test_render_kernels.py checks both paths agree). Why: the torch versions spend their time
in hundreds of small ops, broadcasts and [N, B*C] temporaries; one loop per pixel needs neither (figures
in benchmarks/render.md).

Determinism: every output element is written by exactly one loop iteration in a fixed order. Gradients
that scatter to vertices are computed in *gather* form (for each vertex, its (pixel, corner) entries
in pixel order, from a counting sort), so results are bit-identical for any number of threads. The
texture-gradient scatter runs on one thread.
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


def _pick(kernel):
    """The serial or the parallel compilation of ``kernel``, following torch's thread count.

    With 1 torch thread the serial build runs on the calling thread (no thread pool at all); otherwise
    numba uses as many threads as torch may.
    """
    threads = min(torch.get_num_threads(), numba.config.NUMBA_NUM_THREADS)
    if threads <= 1:
        return kernel.serial
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
def barycentrics_forward(corners_px: torch.Tensor, depth: torch.Tensor, centres: torch.Tensor) -> torch.Tensor:
    """Barycentrics [N, 3] of pixel centres [N, 2] in triangles with projected corners [N, 3, 2] and
    camera depths [N, 3] (renderer._barycentrics' formula)."""
    p = _array(corners_px)
    out = np.empty((p.shape[0], 3), dtype=p.dtype)
    _pick(_barycentrics_forward)(p, _array(depth), _array(centres), np.finfo(p.dtype).tiny, out)
    return torch.from_numpy(out)


def barycentrics_backward(corners_px, depth, centres, grad) -> tuple[torch.Tensor, torch.Tensor]:
    """Gradients of ``barycentrics_forward`` to the projected corners [N, 3, 2] and depths [N, 3]."""
    p, z = _array(corners_px), _array(depth)
    grad_p, grad_z = np.empty(p.shape, dtype=p.dtype), np.empty(z.shape, dtype=z.dtype)
    _pick(_barycentrics_backward)(p, z, _array(centres), np.finfo(p.dtype).tiny, _array(grad), grad_p, grad_z)
    return torch.from_numpy(grad_p), torch.from_numpy(grad_z)


# -- radiance of the covered pixels -----------------------------------------------------------------
def radiance_forward(irradiance, diffuse, lit, visibility, specular) -> torch.Tensor:
    """irradiance [N, K*3] * diffuse [N, 3] / pi + lit [N, K*3] * visibility [N, 1] * specular [N, 3]."""
    out = np.empty(tuple(irradiance.shape), dtype=_array(irradiance).dtype)
    arrays = [_array(t) for t in (irradiance, diffuse, lit, visibility, specular)]
    _pick(_radiance_forward)(*arrays, out)
    return torch.from_numpy(out)


def radiance_backward(irradiance, diffuse, lit, visibility, specular, grad) -> list[torch.Tensor]:
    """Gradients of ``radiance_forward`` to its five inputs (same shapes)."""
    arrays = [_array(t) for t in (irradiance, diffuse, lit, visibility, specular)]
    grads = [np.empty(a.shape, dtype=a.dtype) for a in arrays]
    _pick(_radiance_backward)(*arrays, _array(grad), *grads)
    return [torch.from_numpy(g) for g in grads]


# -- SH band sums ---------------------------------------------------------------------------------
_SH_CHUNK = 256  # directions per parallel block (each block allocates its own work arrays once)


def sh_constants(diagonal: list[float], rows: list[tuple[list[float], list[float]]]):
    """sh.py's recurrence constants as arrays: diagonal [B], a [B, B], b [B, B] (row l, column m)."""
    bands = len(diagonal)
    a, b = np.zeros((bands, bands)), np.zeros((bands, bands))
    for l, (a_row, b_row) in enumerate(rows):  # noqa: E741
        a[l, : len(a_row)], b[l, : len(b_row)] = a_row, b_row
    return np.asarray(diagonal, dtype=np.float64), a, b


def sh_basis_forward(directions: torch.Tensor, constants) -> torch.Tensor:
    """Real SH basis (sh.py's convention) at unit directions [N, 3] -> [N, B²]."""
    dirs = _array(directions)
    out = np.empty((dirs.shape[0], constants[0].shape[0] ** 2), dtype=dirs.dtype)
    _pick(_sh_basis)(dirs, constants, _SH_CHUNK, out)
    return torch.from_numpy(out)


def sh_basis_backward(directions: torch.Tensor, grad: torch.Tensor, constants) -> torch.Tensor:
    """sum_j grad[n, j] dY_j/d(x, y, z)(directions[n]): grad [N, B²] -> [N, 3]."""
    dirs = _array(directions)
    out = np.empty(dirs.shape, dtype=dirs.dtype)
    _pick(_sh_basis_vjp)(dirs, constants, _array(grad), _SH_CHUNK, out)
    return torch.from_numpy(out)


if numba is not None:
    # numba's OpenMP layer busy-waits next to torch's own OpenMP threads and slowed torch ops ~10x here;
    # the workqueue layer does not spin (an explicit NUMBA_THREADING_LAYER still wins).
    if "NUMBA_THREADING_LAYER" not in os.environ:
        numba.config.THREADING_LAYER = "workqueue"

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
    def _edge_functions(p, q):
        """Corner offsets d_i = p_i - q [3, 2] and s_i = cross(d_{i+1}, d_{i+2}) [3] (~2 x sub-areas)."""
        d = np.empty((3, 2), dtype=p.dtype)
        for i in range(3):
            d[i, 0], d[i, 1] = p[i, 0] - q[0], p[i, 1] - q[1]
        screen = np.empty(3, dtype=p.dtype)
        for i in range(3):
            j, k = (i + 1) % 3, (i + 2) % 3
            screen[i] = d[j, 0] * d[k, 1] - d[j, 1] * d[k, 0]
        return d, screen

    @_serial_and_parallel
    def _barycentrics_forward(corners_px, depth, centres, tiny, out):
        for n in prange(out.shape[0]):
            _, screen = _edge_functions(corners_px[n], centres[n])
            area = screen[0] + screen[1] + screen[2]
            if abs(area) < tiny:
                area = tiny
            w0 = screen[0] / area / depth[n, 0]
            w1 = screen[1] / area / depth[n, 1]
            w2 = screen[2] / area / depth[n, 2]
            total = w0 + w1 + w2
            out[n, 0], out[n, 1], out[n, 2] = w0 / total, w1 / total, w2 / total

    @_serial_and_parallel
    def _barycentrics_backward(corners_px, depth, centres, tiny, grad, grad_p, grad_z):
        for n in prange(grad.shape[0]):
            d, screen = _edge_functions(corners_px[n], centres[n])
            area = screen[0] + screen[1] + screen[2]
            degenerate = abs(area) < tiny
            if degenerate:
                area = tiny
            w = np.empty(3, dtype=screen.dtype)
            for i in range(3):
                w[i] = screen[i] / area / depth[n, i]
            total = w[0] + w[1] + w[2]
            mean = (grad[n, 0] * w[0] + grad[n, 1] * w[1] + grad[n, 2] * w[2]) / total
            grad_area = 0.0
            g_screen = np.empty(3, dtype=screen.dtype)
            for i in range(3):
                h = (grad[n, i] - mean) / total  # d loss / d w_i
                grad_z[n, i] = -h * w[i] / depth[n, i]
                g_screen[i] = h / area / depth[n, i]
                grad_area -= h * w[i] / area
            if degenerate:
                grad_area = 0.0
            for i in range(3):
                grad_p[n, i, 0], grad_p[n, i, 1] = 0.0, 0.0
            for i in range(3):  # s_i = d_j.x d_k.y - d_j.y d_k.x
                j, k = (i + 1) % 3, (i + 2) % 3
                g = g_screen[i] + grad_area
                grad_p[n, j, 0] += g * d[k, 1]
                grad_p[n, j, 1] -= g * d[k, 0]
                grad_p[n, k, 0] -= g * d[j, 1]
                grad_p[n, k, 1] += g * d[j, 0]

    @_serial_and_parallel
    def _radiance_forward(irradiance, diffuse, lit, visibility, specular, out):
        for p in prange(out.shape[0]):
            for j in range(out.shape[1]):
                c = j % 3
                out[p, j] = irradiance[p, j] * (diffuse[p, c] / np.pi) + lit[p, j] * visibility[p, 0] * specular[p, c]

    @_serial_and_parallel
    def _radiance_backward(irradiance, diffuse, lit, visibility, specular, grad, g_irr, g_diff, g_lit, g_vis, g_spec):
        for p in prange(grad.shape[0]):
            g_vis[p, 0] = 0.0
            for c in range(3):
                g_diff[p, c] = 0.0
                g_spec[p, c] = 0.0
            for j in range(grad.shape[1]):
                c = j % 3
                g = grad[p, j]
                g_irr[p, j] = g * (diffuse[p, c] / np.pi)
                g_diff[p, c] += g * irradiance[p, j] / np.pi
                g_lit[p, j] = g * visibility[p, 0] * specular[p, c]
                g_vis[p, 0] += g * lit[p, j] * specular[p, c]
                g_spec[p, c] += g * lit[p, j] * visibility[p, 0]

    @njit(inline="always")
    def _sh_rows_at(direction, constants, scratch, basis, d_basis, derivative):
        """Y_j (index l*l+l+m) at one unit direction [3] into ``basis`` [B²], and dY_j/d(x, y, z) into
        ``d_basis`` [B², 3] if ``derivative``: the recurrences of sh.py (Q_l^m(z) times Re/Im (x+iy)^m)."""
        x, y, z = direction[0], direction[1], direction[2]
        diagonal, a, b = constants
        q, dq, cos_m, sin_m = scratch
        bands = diagonal.shape[0]
        cos_m[0], sin_m[0] = 1.0, 0.0
        for m in range(1, bands):
            cos_m[m] = cos_m[m - 1] * x - sin_m[m - 1] * y
            sin_m[m] = sin_m[m - 1] * x + cos_m[m - 1] * y
        root2 = np.sqrt(2.0)
        for l in range(bands):  # noqa: E741
            for m in range(l - 1):
                q[l, m] = a[l, m] * (z * q[l - 1, m] - b[l, m] * q[l - 2, m])
                if derivative:
                    dq[l, m] = a[l, m] * (q[l - 1, m] + z * dq[l - 1, m] - b[l, m] * dq[l - 2, m])
            if l >= 1:
                q[l, l - 1] = np.sqrt(2.0 * l + 1.0) * z * q[l - 1, l - 1]
                dq[l, l - 1] = np.sqrt(2.0 * l + 1.0) * q[l - 1, l - 1]
            q[l, l] = diagonal[l]
            dq[l, l] = 0.0
            centre = l * l + l
            basis[centre] = q[l, 0]
            if derivative:
                d_basis[centre, 0], d_basis[centre, 1], d_basis[centre, 2] = 0.0, 0.0, dq[l, 0]
            for m in range(1, l + 1):
                basis[centre + m] = root2 * q[l, m] * cos_m[m]
                basis[centre - m] = root2 * q[l, m] * sin_m[m]
                if derivative:
                    mq = root2 * m * q[l, m]
                    d_basis[centre + m, 0] = mq * cos_m[m - 1]
                    d_basis[centre + m, 1] = -mq * sin_m[m - 1]
                    d_basis[centre + m, 2] = root2 * dq[l, m] * cos_m[m]
                    d_basis[centre - m, 0] = mq * sin_m[m - 1]
                    d_basis[centre - m, 1] = mq * cos_m[m - 1]
                    d_basis[centre - m, 2] = root2 * dq[l, m] * sin_m[m]

    @njit(inline="always")
    def _sh_scratch(bands):
        """Per-thread work arrays of ``_sh_rows_at``: Q, dQ/dz [B, B], Re/Im (x+iy)^m [B]."""
        return np.empty((bands, bands)), np.empty((bands, bands)), np.empty(bands), np.empty(bands)

    @_serial_and_parallel
    def _sh_basis(directions, constants, chunk, out):
        bands = constants[0].shape[0]
        count = directions.shape[0]
        for block in prange((count + chunk - 1) // chunk):
            scratch = _sh_scratch(bands)
            for n in range(block * chunk, min(count, (block + 1) * chunk)):
                _sh_rows_at(directions[n], constants, scratch, out[n], out[n], False)

    @_serial_and_parallel
    def _sh_basis_vjp(directions, constants, grad, chunk, out):
        bands = constants[0].shape[0]
        count = directions.shape[0]
        for block in prange((count + chunk - 1) // chunk):
            scratch, basis = _sh_scratch(bands), np.empty(bands * bands)
            d_basis = np.empty((bands * bands, 3))
            for n in range(block * chunk, min(count, (block + 1) * chunk)):
                _sh_rows_at(directions[n], constants, scratch, basis, d_basis, True)
                gx, gy, gz = 0.0, 0.0, 0.0
                for j in range(bands * bands):
                    gx += grad[n, j] * d_basis[j, 0]
                    gy += grad[n, j] * d_basis[j, 1]
                    gz += grad[n, j] * d_basis[j, 2]
                out[n, 0], out[n, 1], out[n, 2] = gx, gy, gz
