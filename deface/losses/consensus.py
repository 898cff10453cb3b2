"""Several frames of one person: the darkening the light masks give a texel in every frame that sees it.

With one photo, a dark texel is either dark pigment or a dimmer light, and stage 2's albedo (no beard, no moles)
teaches the masks the second. Frames with different lights tell them apart: a cast shadow falls on a texel in some
frames and not in others, pigment is dark in all. The masks' darkening of a frame's pixel is
``1 - sum_k M_k Y(I_k) / max_k Y(I_k)`` (0 under the brightest light, the shadow light's share under a cast shadow),
read into UV through each frame's camera; its minimum over the frames that see a texel is the part every frame
agrees on, which the masks should not take: the map can hold it, as pigment, and the frames' other darkenings stay
light. Texels fewer than two frames see cost nothing (one photo: the term is 0).
"""

from __future__ import annotations

import torch


def masks_darkening(light_images: torch.Tensor, light_masks: torch.Tensor, luminance: torch.Tensor) -> torch.Tensor:
    """[H, W] in [0, 1]: 1 - sum_k M_k Y(I_k) / max_k Y(I_k) of per-light renders [K, H, W, 3] and masks [K, H, W]
    (``luminance``: [3] weights). The brightest light's luminance is a constant of the term (its gradient moves the
    masks, not the lights' level)."""
    lum = light_images @ luminance  # [K, H, W]
    brightest = lum.max(0).values.detach()
    reached = (lum * light_masks).sum(0)
    return torch.where(brightest > 1e-6, 1.0 - reached / brightest.clamp_min(1e-6), torch.zeros_like(brightest))


def shared_darkening(darkening: torch.Tensor, weights: torch.Tensor, min_frames: int = 2) -> torch.Tensor:
    """The mean over texels that at least ``min_frames`` frames see (``weights`` [T, R, R] > 0) of the smallest
    darkening [T, R, R] among those frames, weighted by the smallest weight (how well the worst of them sees it);
    0 without such texels."""
    seen = weights > 0
    supported = seen.sum(0) >= min_frames
    if not bool(supported.any()):
        return darkening.sum() * 0.0
    common = torch.where(seen, darkening, torch.full_like(darkening, 2.0)).min(0).values  # [R, R]
    weight = torch.where(seen, weights, torch.full_like(weights, float("inf"))).min(0).values * supported
    weight = torch.where(supported, weight, torch.zeros_like(weight))
    return (common.clamp(0.0, 1.0) * weight).sum() / weight.sum()
