"""Real SH on unit directions (sh.py's convention and recurrences): the basis rows Y [B², N]
(``sh_basis``), the per-band sums S_l(w) = sum_m c_lm Y_lm(w) (``sh_band_sums``) and the shadowed
per-vertex irradiance E = sum_j (A_j Y_j(n) - O_j) c_j (``sh_irradiance``).

Reference: the fully normalised Legendre recurrences on [l+1, N] blocks in torch with an analytic
backward (``_SHBasis``), and matrix products with the lights. Fast: the same recurrences run along
blocks of _SH_CHUNK directions (SIMD) with the products fused in; coefficient gradients are summed per
block, then over the blocks in order (the same result for any number of threads).
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
import torch

from deface.render.kernels.base import _array, _pick, enabled, njit, prange, register, serial_and_parallel


# -- torch reference --------------------------------------------------------------------------------
@lru_cache(maxsize=64)
def _recurrence_constants(bands: int) -> tuple[list[float], list[tuple[list[float], list[float]]]]:
    """Diagonal constants Q_m^m (direction independent) and the (a_lm, b_lm) rows of the l-recurrence."""
    diagonal = [math.sqrt(1.0 / (4.0 * math.pi))]
    for m in range(1, bands):
        diagonal.append(diagonal[-1] * math.sqrt((2 * m + 1) / (2 * m)))
    rows = []
    for l in range(bands):  # noqa: E741 - l is the band index in every SH paper
        a = [math.sqrt((4 * l * l - 1) / (l * l - m * m)) for m in range(max(l - 1, 0))]
        b = [math.sqrt(((l - 1) ** 2 - m * m) / (4 * (l - 1) ** 2 - 1)) for m in range(max(l - 1, 0))]
        rows.append((a, b))
    return diagonal, rows


def _legendre_rows(z: torch.Tensor, bands: int, derivative: bool):
    """Q_l^m(z) = N_lm P_l^m(z) / sin^m(theta) for each band l as [l+1, N] blocks (and dQ/dz if asked).

    Fully normalised recurrence (Holmes & Featherstone 2002) with the sin^m factor taken out:
    Q_m^m = sqrt((2m+1)/(2m)) Q_{m-1}^{m-1} (a constant), Q_{m+1}^m = sqrt(2m+3) z Q_m^m,
    Q_l^m = a_lm (z Q_{l-1}^m - b_lm Q_{l-2}^m).
    """
    diagonal, recurrence = _recurrence_constants(bands)
    opts = {"dtype": z.dtype, "device": z.device}
    q_rows = [torch.full_like(z, diagonal[0])[None]]
    dq_rows = [torch.zeros_like(z)[None]]
    for l in range(1, bands):  # noqa: E741 - l is the band index in every SH paper
        parts, dparts = [], []
        if l >= 2:
            a = torch.tensor(recurrence[l][0], **opts)[:, None]
            b = torch.tensor(recurrence[l][1], **opts)[:, None]
            q1, q2 = q_rows[l - 1][: l - 1], q_rows[l - 2][: l - 1]
            parts.append(a * (z * q1 - b * q2))  # m = 0..l-2
            if derivative:
                dparts.append(a * (q1 + z * dq_rows[l - 1][: l - 1] - b * dq_rows[l - 2][: l - 1]))
        root = math.sqrt(2 * l + 1)
        parts.append(root * z * q_rows[l - 1][l - 1 :])  # m = l-1
        parts.append(torch.full_like(z, diagonal[l])[None])  # m = l
        q_rows.append(torch.cat(parts))
        if derivative:
            dparts.append(root * q_rows[l - 1][l - 1 :])  # Q_{l-1}^{l-1} is constant
            dparts.append(torch.zeros_like(z)[None])
            dq_rows.append(torch.cat(dparts))
    return q_rows, dq_rows


def _azimuth_rows(x: torch.Tensor, y: torch.Tensor, bands: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Re and Im of (x + i y)^m = sin^m(theta) (cos m phi, sin m phi), m = 0..bands-1 -> [B, N] each."""
    cos_m, sin_m = [torch.ones_like(x)], [torch.zeros_like(x)]
    for _ in range(1, bands):
        c, s = cos_m[-1], sin_m[-1]
        cos_m.append(c * x - s * y)
        sin_m.append(s * x + c * y)
    return torch.stack(cos_m), torch.stack(sin_m)


class _SHBasis(torch.autograd.Function):
    """Y [B², N] (``channel_first``) or [N, B²] from directions [N, 3]; backward contracts the analytic Jacobian.

    With Y_lm = sqrt2 Q C_m, Y_l-m = sqrt2 Q S_m (C + iS = (x + iy)^m):
    dC_m/dx = m C_{m-1}, dC_m/dy = -m S_{m-1}, dS_m/dx = m S_{m-1}, dS_m/dy = m C_{m-1}, and dQ/dz from
    the differentiated recurrence. These are derivatives of the polynomial in R^3, as autograd would give.
    """

    @staticmethod
    def forward(ctx, directions: torch.Tensor, bands: int, channel_first: bool) -> torch.Tensor:
        ctx.bands, ctx.channel_first = bands, channel_first
        ctx.save_for_backward(directions)
        rows = _sh_rows_forward(directions, bands)
        return rows if channel_first else rows.T

    @staticmethod
    def backward(ctx, grad: torch.Tensor):
        (directions,) = ctx.saved_tensors
        grad_rows = grad if ctx.channel_first else grad.T  # [B², N]
        return _sh_rows_vjp(directions, grad_rows, ctx.bands), None, None


def _sh_rows_forward(directions: torch.Tensor, bands: int) -> torch.Tensor:
    """The basis [B², N] at directions [N, 3] (plain tensor ops, no autograd graph needed)."""
    x, y, z = directions.T.contiguous()
    cos_stack, sin_stack = _azimuth_rows(x, y, bands)
    q_rows, _ = _legendre_rows(z, bands, derivative=False)
    cos_stack, sin_stack = math.sqrt(2.0) * cos_stack, math.sqrt(2.0) * sin_stack
    out = [q_rows[0]]
    for l in range(1, bands):  # noqa: E741
        q = q_rows[l]
        out += [(q[1:] * sin_stack[1 : l + 1]).flip(0), q[:1], q[1:] * cos_stack[1 : l + 1]]
    return torch.cat(out)


def _sh_rows_vjp(directions: torch.Tensor, grad: torch.Tensor, bands: int) -> torch.Tensor:
    """sum_j grad[j, n] dY_j/d(x, y, z)(directions[n]) -> [N, 3] (grad [B², N])."""
    x, y, z = directions.T.contiguous()
    cos_stack, sin_stack = _azimuth_rows(x, y, bands)
    q_rows, dq_rows = _legendre_rows(z, bands, derivative=True)
    grad = grad.contiguous()
    gx, gy, gz = torch.zeros_like(x), torch.zeros_like(x), torch.zeros_like(x)
    root2 = math.sqrt(2.0)
    for l in range(1, bands):  # noqa: E741
        centre = l * l + l
        g_pos = grad[centre + 1 : centre + l + 1]  # [l, N], m = 1..l
        g_neg = grad[centre - l : centre].flip(0)  # [l, N], |m| = 1..l
        m = torch.arange(1, l + 1, dtype=x.dtype, device=x.device)[:, None]
        mq = root2 * m * q_rows[l][1:]  # [l, N]
        c_prev, s_prev = cos_stack[:l], sin_stack[:l]
        gx = gx + (mq * (g_pos * c_prev + g_neg * s_prev)).sum(0)
        gy = gy + (mq * (g_neg * c_prev - g_pos * s_prev)).sum(0)
        radial = g_pos * cos_stack[1 : l + 1] + g_neg * sin_stack[1 : l + 1]
        gz = gz + grad[centre] * dq_rows[l][0] + root2 * (dq_rows[l][1:] * radial).sum(0)
    return torch.stack([gx, gy, gz], -1)


def _band_sums_reference(directions: torch.Tensor, coeffs: torch.Tensor) -> torch.Tensor:
    """S_l(w) [N, B, C] from the basis rows: one [N, 2l+1] x [2l+1, C] product per band."""
    bands = math.isqrt(coeffs.shape[0])
    sizes = [2 * l + 1 for l in range(bands)]
    # split, not slicing: the backward of a split is one cat, that of each slice a full-size zero buffer
    rows, blocks = sh_basis(directions, bands, True).split(sizes), coeffs.split(sizes)  # [2l+1, N], [2l+1, C]
    return torch.stack([row.T @ block for row, block in zip(rows, blocks, strict=True)], 1)


def _irradiance_reference(normals, coeffs, lobe, transfer, subset) -> torch.Tensor:
    """E [U, C] = (lobe_j Y_j(n_u) - O[subset_u, j]) coeffs[j, c] with the transfer rows channel-first."""
    bands = math.isqrt(lobe.shape[0])
    # transfer A_l Y_lm(n) - O[lm] per vertex, channel-first [B², U] like the basis rows (mixed layouts make
    # the element-wise ops slow), then one product with the lights: fewer [U, B²] x [B², K*3] products
    # forward and backward than filtering the lights and subtracting a second product
    transfer_rows = sh_basis(normals, bands, True) * lobe[:, None]  # [B², U]
    if transfer is not None:
        occluded = transfer.occluded_rows  # [B²', V]
        if subset is not None:
            occluded = occluded.index_select(1, subset)
        transfer_rows = transfer_rows - occluded[: bands * bands].to(coeffs.dtype)
    return transfer_rows.T @ coeffs


# -- fast path ----------------------------------------------------------------------------------------
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


@lru_cache(maxsize=64)
def kernel_constants(bands: int):
    """The SH recurrence constants of ``bands`` bands as the numba kernels take them (``sh_constants``)."""
    return sh_constants(*_recurrence_constants(bands))


class _KernelSHBasis(torch.autograd.Function):
    """The numba path of ``_SHBasis``: the same recurrences along blocks of directions."""

    @staticmethod
    def forward(ctx, directions: torch.Tensor, bands: int, channel_first: bool) -> torch.Tensor:
        ctx.bands, ctx.channel_first = bands, channel_first
        ctx.save_for_backward(directions)
        return sh_basis_forward(directions, kernel_constants(bands), channel_first)

    @staticmethod
    def backward(ctx, grad: torch.Tensor):
        (directions,) = ctx.saved_tensors
        grad_rows = grad if ctx.channel_first else grad.T  # [B², N]
        return sh_basis_backward(directions, grad_rows, kernel_constants(ctx.bands)), None, None


class _KernelBandSums(torch.autograd.Function):
    """The numba path of ``sh_band_sums``: basis and band sums per direction, no [B², N] rows, no matmuls."""

    @staticmethod
    def forward(ctx, directions: torch.Tensor, coeffs: torch.Tensor) -> torch.Tensor:
        ctx.save_for_backward(directions, coeffs)
        return sh_band_sums_forward(directions, coeffs, kernel_constants(math.isqrt(coeffs.shape[0])))

    @staticmethod
    def backward(ctx, grad: torch.Tensor):
        directions, coeffs = ctx.saved_tensors
        constants = kernel_constants(math.isqrt(coeffs.shape[0]))
        return sh_band_sums_backward(directions, coeffs, grad, constants, *ctx.needs_input_grad)


class _KernelIrradiance(torch.autograd.Function):
    """The numba path of ``_vertex_irradiance``: SH basis, shadowed transfer and the product with the lights
    per block of normals (no [B², U] rows, no serial matmuls); gradients to normals and coeffs."""

    @staticmethod
    def forward(ctx, normals, coeffs, lobe, occluded, subset):
        ctx.save_for_backward(normals, coeffs)
        ctx.inputs = (lobe, occluded, subset, kernel_constants(math.isqrt(lobe.shape[0])))
        return sh_irradiance_forward(normals, coeffs, *ctx.inputs)

    @staticmethod
    def backward(ctx, grad):
        normals, coeffs = ctx.saved_tensors
        lobe, occluded, subset, constants = ctx.inputs
        need = ctx.needs_input_grad[:2]
        grads = sh_irradiance_backward(normals, coeffs, lobe, occluded, subset, grad, constants, *need)
        return *grads, None, None, None


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


@serial_and_parallel
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


@serial_and_parallel
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


@serial_and_parallel
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


@serial_and_parallel
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


@serial_and_parallel
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


@serial_and_parallel
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


# -- dispatch ---------------------------------------------------------------------------------------
sh_basis = register(
    "sh_basis",
    reference=_SHBasis.apply,
    fast=_KernelSHBasis.apply,
    supports=lambda directions, bands, channel_first: enabled(directions),
)
"""Real SH basis at unit directions [N, 3] -> [B², N] (``channel_first``) or [N, B²]: (directions, bands,
channel_first)."""

sh_band_sums = register(
    "sh_band_sums",
    reference=_band_sums_reference,
    fast=_KernelBandSums.apply,
    supports=lambda directions, coeffs: enabled(directions, coeffs) and directions.dtype == coeffs.dtype,
)
"""Per-band sums S_l(w) = sum_m c_lm Y_lm(w): directions [N, 3], coeffs [B², C] -> [N, B, C]."""


def _fast_irradiance(normals, coeffs, lobe, transfer, subset):
    return _KernelIrradiance.apply(normals, coeffs, lobe, None if transfer is None else transfer.occluded, subset)


sh_irradiance = register(
    "sh_irradiance",
    reference=_irradiance_reference,
    fast=_fast_irradiance,
    supports=lambda normals, coeffs, lobe, transfer, subset: (
        enabled(normals, coeffs) and normals.dtype == coeffs.dtype
    ),
)
"""Shadowed SH irradiance: normals [U, 3], coeffs [B², C], lobe [B²] (A_l per coefficient), transfer (a
ShadowTransfer with >= B bands, or None: nothing occluded), subset [U] long (the transfer's vertices of
the normals; None: U = V) -> [U, C]."""
