"""Local prior LP (Sec. 3.3): local variations of the optimised maps should stay like the reference's.

N(T) = T - Neighbour(T) over the 24 neighbours of a 5x5 window (replicate padding at the border).
Per pixel, d(p) = mean over channels and neighbours of |N - N^0| (``norm="l1"``) or (N - N^0)^2 (``"l2sq"``);
LP = sum_p w(p) d(p) / sum_p w(p).
The same function serves both uses:
- UV space (the paper): current/reference are UV maps (T vs T^0), w the UV face mask.
- Screen space (the authors' code): current/reference are screen-space albedo renders of stage 3 vs stage 2,
  w = M_R, and the three maps are combined as 5 dD + 6 dS + 1 dR (:func:`material_local_prior`).
The paper's exact norm is not stated; L1 is the default here and the choice is exposed.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

NORMS = ("l1", "l2sq")
CODE_WEIGHTS = (5.0, 6.0, 1.0)  # diffuse, specular, roughness (the authors' code)


def _neighbour_differences(texture: torch.Tensor, size: int):
    """Yield T(p) - T(p + o) [H, W, C] for each offset o != 0 of the size x size window (row-major),
    with replicate padding; texture [H, W, C]."""
    if texture.dim() != 3:
        raise ValueError(f"maps must be [H, W, C], got {tuple(texture.shape)}")
    if size < 3 or size % 2 != 1:
        raise ValueError(f"window size must be odd and >= 3, got {size}")
    radius = size // 2
    height, width, _ = texture.shape
    padded = F.pad(texture.permute(2, 0, 1)[None], (radius,) * 4, mode="replicate")[0].permute(1, 2, 0)
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            if dy or dx:
                yield texture - padded[radius + dy : radius + dy + height, radius + dx : radius + dx + width]


def local_variations(texture: torch.Tensor, size: int = 5) -> torch.Tensor:
    """[Ht, Wt, C] -> [Ht, Wt, C, size^2 - 1]: T(p) - T(p + o) for each offset o != 0 (row-major order)."""
    return torch.stack(list(_neighbour_differences(texture, size)), dim=-1)


def _mean_variation(difference: torch.Tensor, size: int, norm: str) -> torch.Tensor:
    """Mean over channels and window offsets of |N(D)| or N(D)^2 for D [H, W, C] -> [H, W]."""
    total = difference.new_zeros(difference.shape[:2])
    for step in _neighbour_differences(difference, size):
        total = total + (step.abs() if norm == "l1" else step**2).mean(dim=-1)
    return total / (size * size - 1)


def local_prior(
    current: torch.Tensor,
    reference: torch.Tensor,
    mask: torch.Tensor | None = None,
    size: int = 5,
    norm: str = "l1",
) -> torch.Tensor:
    """LP (scalar) between current and reference maps [H, W, C] under pixel weights mask [H, W]."""
    if current.shape != reference.shape:
        raise ValueError(f"current {tuple(current.shape)} and reference {tuple(reference.shape)} differ")
    if norm not in NORMS:
        raise ValueError(f"unknown norm {norm!r}; choose one of {NORMS}")
    # N is linear, so N(T) - N(T0) = N(T - T0): one pass over the offsets, accumulated without stacking.
    per_pixel = _mean_variation(current - reference.detach(), size, norm)  # [H, W]
    if mask is None:
        return per_pixel.mean()
    if mask.shape != per_pixel.shape:
        raise ValueError(f"mask {tuple(mask.shape)} must be [H, W] = {tuple(per_pixel.shape)}")
    weights = mask.to(per_pixel)
    return (weights * per_pixel).sum() / weights.sum().clamp_min(1e-8)


def material_local_prior(
    current: tuple[torch.Tensor, torch.Tensor, torch.Tensor],
    reference: tuple[torch.Tensor, torch.Tensor, torch.Tensor],
    mask: torch.Tensor | None = None,
    weights: tuple[float, float, float] = CODE_WEIGHTS,
    norm: str = "l1",
) -> torch.Tensor:
    """Weighted LP over (diffuse, specular, roughness) maps: sum_i weights[i] LP(current[i], reference[i])."""
    if len(current) != 3 or len(reference) != 3:
        raise ValueError("expected (diffuse, specular, roughness) for current and reference")
    total = current[0].new_zeros(())
    for weight, now, ref in zip(weights, current, reference, strict=True):
        total = total + weight * local_prior(now, ref, mask, norm=norm)
    return total
