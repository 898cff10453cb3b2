"""Adaptive Condition Estimation (ACE, Sec. 3.2): keep the lights whose masks cover enough of the face.

area_k = sum over frames and pixels of M_N^k / normaliser, with M_N^k = M_R f_k the light mask times the
render coverage. The normaliser is sum M_R (``"render_mask"``, the authors' code) or the number of image
pixels over all frames (``"image"``, the paper's 1/|I_in|). Lights with area_k > epsilon are kept, sorted by
decreasing area; if none qualifies all lights are kept (the authors' code) in their original order.
"""

from __future__ import annotations

import torch

AREA_NORMALISERS = ("render_mask", "image")


def as_frames(masks: torch.Tensor, coverage: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Masks [n, H, W] or [T, n, H, W] and coverage [H, W] or [T, H, W] -> the 4-D and 3-D forms, checked."""
    if masks.dim() == 3:
        masks = masks[None]
    if coverage.dim() == 2:
        coverage = coverage[None]
    if masks.dim() != 4 or coverage.shape != (masks.shape[0], *masks.shape[2:]):
        raise ValueError(
            f"expected masks [T, n, H, W] and coverage [T, H, W], got {tuple(masks.shape)} and "
            f"{tuple(coverage.shape)}"
        )
    return masks, coverage


def area_denominator(coverage: torch.Tensor, area_normaliser: str) -> torch.Tensor:
    """sum M_R ("render_mask", the authors' code) or the pixel count of all frames ("image", the paper)."""
    if area_normaliser == "render_mask":
        return coverage.sum().clamp_min(1e-8)
    if area_normaliser == "image":
        return torch.tensor(float(coverage.numel()), dtype=coverage.dtype, device=coverage.device)
    raise ValueError(f"unknown area_normaliser {area_normaliser!r}; choose one of {AREA_NORMALISERS}")


def light_areas(light_masks: torch.Tensor, coverage: torch.Tensor, area_normaliser: str = "render_mask"):
    """Area fraction [n] of each light. light_masks [T, n, H, W] (already times M_R), coverage [T, H, W]."""
    light_masks, coverage = as_frames(light_masks, coverage)
    return light_masks.sum(dim=(0, 2, 3)) / area_denominator(coverage, area_normaliser)  # [n]


@torch.no_grad()
def ace_select(
    light_masks: torch.Tensor,
    coverage: torch.Tensor,
    epsilon: float,
    area_normaliser: str = "render_mask",
) -> list[int]:
    """Indices of the kept lights, largest area first; all lights when none exceeds epsilon."""
    areas = light_areas(light_masks.detach(), coverage.detach(), area_normaliser)
    order = torch.argsort(areas, descending=True, stable=True).tolist()
    kept = [int(i) for i in order if float(areas[i]) > epsilon]
    return kept if kept else list(range(int(areas.shape[0])))


def renormalise(masks: torch.Tensor, kept: list[int], dim: int = -1) -> torch.Tensor:
    """Masks of the kept lights (in ``kept``'s order) divided by their sum along ``dim`` (the light axis)."""
    if not kept:
        raise ValueError("at least one light must be kept")
    index = torch.as_tensor(kept, dtype=torch.long, device=masks.device)
    selected = masks.index_select(dim, index)
    return selected / selected.sum(dim=dim, keepdim=True).clamp_min(1e-12)
