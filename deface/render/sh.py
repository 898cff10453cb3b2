"""Real orthonormal spherical harmonics, any number of bands, differentiable in torch.

Convention (shared by the whole project): coefficient index ``l*l + l + m`` for band ``l`` and order
``-l <= m <= l``; no Condon-Shortley phase, so ``Y_1,-1 ∝ y``, ``Y_1,0 ∝ z``, ``Y_1,1 ∝ x``:

    Y_l0  = N_l0 P_l^0(z)
    Y_lm  = sqrt(2) N_lm P_l^m(z) cos(m phi)      m > 0
    Y_l-m = sqrt(2) N_lm P_l^m(z) sin(m phi)      m > 0
    N_lm  = sqrt((2l+1)/(4 pi) (l-m)!/(l+m)!)

Evaluation is stable for many bands: we run the *fully normalised* associated-Legendre recurrence
(Holmes & Featherstone 2002) on Q_l^m = N_lm P_l^m / sin^m(theta), a polynomial in z, and multiply by
sin^m(theta) cos/sin(m phi) = Re/Im((x + i y)^m), another polynomial. Everything is a polynomial in
(x, y, z), so gradients are finite everywhere, including the poles.

Radiance of an SH light: ``L(w) = sum_lm c_lm Y_lm(w)``, w the unit direction towards the light.
"""

from __future__ import annotations

import math
from functools import lru_cache

import torch

from deface.render import kernels


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


def sh_basis(directions: torch.Tensor, bands: int) -> torch.Tensor:
    """Real orthonormal SH basis at unit ``directions`` [..., 3] -> [..., bands²] (index l*l + l + m).

    Differentiable once (analytic backward, see :class:`_SHBasis`).
    """
    if directions.shape[-1] != 3:
        raise ValueError(f"sh_basis: directions must have shape [..., 3], got {tuple(directions.shape)}")
    if bands < 1:
        raise ValueError(f"sh_basis: bands must be >= 1, got {bands}")
    basis = _SHBasis.apply(directions.reshape(-1, 3), bands, False)  # [N, B²], row-major
    return basis.reshape(*directions.shape[:-1], bands * bands)


def sh_basis_rows(directions: torch.Tensor, bands: int) -> torch.Tensor:
    """SH basis channel-first: unit directions [N, 3] -> [bands², N]; same values as :func:`sh_basis`.

    Every intermediate is a contiguous [m, N] block, and the backward pass is analytic (derivative
    recurrences) instead of autograd over ~100 small ops: both several times faster.
    """
    if directions.ndim != 2 or directions.shape[1] != 3:
        raise ValueError(f"sh_basis_rows: directions must be [N, 3], got {tuple(directions.shape)}")
    if bands < 1:
        raise ValueError(f"sh_basis: bands must be >= 1, got {bands}")
    return _SHBasis.apply(directions, bands, True)


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
        if kernels.enabled(directions):  # the same recurrences, along blocks of directions
            return kernels.sh_basis_forward(directions, kernel_constants(bands), channel_first)
        rows = _sh_rows_forward(directions, bands)
        return rows if channel_first else rows.T

    @staticmethod
    def backward(ctx, grad: torch.Tensor):
        (directions,) = ctx.saved_tensors
        grad_rows = grad if ctx.channel_first else grad.T  # [B², N]
        if kernels.enabled(directions, grad):
            return kernels.sh_basis_backward(directions, grad_rows, kernel_constants(ctx.bands)), None, None
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


def sh_band_sums(directions: torch.Tensor, coeffs: torch.Tensor) -> torch.Tensor:
    """Per-band sums S_l(w) = sum_m c_lm Y_lm(w): unit directions [N, 3], coeffs [B², C] -> [N, B, C].

    Any band-filtered radiance is sum_l f_l S_l(w) (irradiance: f_l = A_l; Phong specular: f_l =
    Lambda_l).
    """
    bands = math.isqrt(coeffs.shape[0])
    if bands < 1 or bands * bands != coeffs.shape[0] or directions.ndim != 2 or directions.shape[1] != 3:
        raise ValueError(f"sh_band_sums: got directions {tuple(directions.shape)}, coeffs {tuple(coeffs.shape)}")
    if kernels.enabled(directions, coeffs) and directions.dtype == coeffs.dtype:
        return _SHBandSums.apply(directions, coeffs)
    sizes = [2 * l + 1 for l in range(bands)]
    # split, not slicing: the backward of a split is one cat, that of each slice a full-size zero buffer
    rows, blocks = sh_basis_rows(directions, bands).split(sizes), coeffs.split(sizes)  # [2l+1, N], [2l+1, C]
    return torch.stack([row.T @ block for row, block in zip(rows, blocks, strict=True)], 1)


class _SHBandSums(torch.autograd.Function):
    """The numba path of ``sh_band_sums``: basis and band sums per direction, no [B², N] rows, no matmuls."""

    @staticmethod
    def forward(ctx, directions: torch.Tensor, coeffs: torch.Tensor) -> torch.Tensor:
        ctx.save_for_backward(directions, coeffs)
        return kernels.sh_band_sums_forward(directions, coeffs, kernel_constants(math.isqrt(coeffs.shape[0])))

    @staticmethod
    def backward(ctx, grad: torch.Tensor):
        directions, coeffs = ctx.saved_tensors
        constants = kernel_constants(math.isqrt(coeffs.shape[0]))
        return kernels.sh_band_sums_backward(directions, coeffs, grad, constants, *ctx.needs_input_grad)


@lru_cache(maxsize=64)
def kernel_constants(bands: int):
    """The SH recurrence constants of ``bands`` bands as the numba kernels take them (kernels.sh_constants)."""
    return kernels.sh_constants(*_recurrence_constants(bands))


def band_of_index(bands: int, device: torch.device | None = None) -> torch.Tensor:
    """Band l of every coefficient index [bands²] (long)."""
    levels = torch.arange(bands, device=device)
    return torch.repeat_interleave(levels, 2 * levels + 1)


def cosine_lobe_band(l: int) -> float:  # noqa: E741
    """A_l of the clamped-cosine kernel max(cos, 0) (Ramamoorthi & Hanrahan 2001, "An efficient
    representation for irradiance environment maps", eq. 8-9): irradiance E_lm = A_l L_lm.

    A_0 = pi, A_1 = 2 pi / 3, A_l = 0 for odd l > 1, and for even l
    A_l = 2 pi (-1)^(l/2 - 1) / ((l + 2)(l - 1)) * l! / (2^l ((l/2)!)^2).
    """
    if l == 0:
        return math.pi
    if l == 1:
        return 2.0 * math.pi / 3.0
    if l % 2:
        return 0.0
    half = l // 2
    log_ratio = math.lgamma(l + 1) - l * math.log(2.0) - 2 * math.lgamma(half + 1)
    return 2.0 * math.pi * (-1) ** (half - 1) / ((l + 2) * (l - 1)) * math.exp(log_ratio)


def cosine_lobe_coefficients(bands: int) -> torch.Tensor:
    """A_l repeated for each m of band l -> [bands²] float32 (irradiance E(n) = sum A_l c_lm Y_lm(n))."""
    if bands < 1:
        raise ValueError(f"cosine_lobe_coefficients: bands must be >= 1, got {bands}")
    return torch.tensor(_cosine_lobe_values(bands), dtype=torch.float32)


@lru_cache(maxsize=64)
def _cosine_lobe_values(bands: int) -> tuple[float, ...]:
    """A_l per coefficient (computed once per band count: the renderer asks on every call)."""
    return tuple(cosine_lobe_band(l) for l in range(bands) for _ in range(2 * l + 1))


def phong_lobe_filter(roughness: torch.Tensor, bands: int) -> torch.Tensor:
    """SH filter of a normalised Phong lobe around the reflection direction, [...] -> [..., bands].

    Lambda_l = exp(-l² / (2 s)) (Ramamoorthi & Hanrahan 2001, "A signal-processing framework for
    inverse rendering", Phong BRDF in frequency space), with the Phong exponent from the Beckmann
    roughness alpha by s = 2 / alpha² - 2 (Walter et al. 2007, "Microfacet models for refraction").
    Lambda_0 = 1, so a constant environment L reflects k_s L. alpha is clamped to [1e-3, 1].
    """
    alpha = roughness.clamp(1e-3, 1.0)
    exponent = (2.0 / (alpha * alpha) - 2.0).clamp_min(1e-4)  # [...]
    l_sq = torch.arange(bands, dtype=roughness.dtype, device=roughness.device) ** 2
    return torch.exp(-l_sq / (2.0 * exponent[..., None]))


def white_light(bands: int, ambient: float = 0.7) -> torch.Tensor:
    """[1, bands², 3] a neutral light: uniform plus a first-order lobe towards +z (the viewer in the model
    frame), scaled so a white Lambertian surface shows ``ambient`` sideways and exactly 1 facing +z
    (diffuse radiance E / pi with E = A_0 c_00 Y_00 + A_1 c_10 Y_10). Renders under it show the albedo itself
    where the surface faces the viewer."""
    coeffs = torch.zeros(bands * bands)
    y00, y10_scale = 0.5 / math.sqrt(math.pi), math.sqrt(3.0 / (4.0 * math.pi))
    coeffs[0] = ambient / y00  # (A_0 / pi) c_00 Y_00 = ambient
    if bands > 1:
        coeffs[2] = (1.0 - ambient) / (cosine_lobe_band(1) / math.pi * y10_scale)  # index l*l + l + m of (1, 0)
    return coeffs[None, :, None].expand(1, bands * bands, 3).clone()
