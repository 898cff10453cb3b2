"""Stage-3 texture regularisers (NextFace keeps per-texel maps plausible with such terms; these are ours):
closeness to the statistical texture T^0 and smoothness (squared differences of neighbouring texels),
both over the UV face mask. Relative weights per map follow NextFace's emphasis (diffuse strongest).
"""

from __future__ import annotations

import torch

from deface.render.mesh import Textures

# (closeness to T^0, smoothness) per map.
MAP_WEIGHTS = {"diffuse": (1.0, 1.0), "specular": (0.5, 1.0), "roughness": (0.1, 2.0)}


def smoothness(texture: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Mean squared difference of horizontally and vertically adjacent texels; texture [H,W,C], mask [H,W]."""
    dx = (texture[:, 1:] - texture[:, :-1]).pow(2).sum(-1) * mask[:, 1:] * mask[:, :-1]
    dy = (texture[1:] - texture[:-1]).pow(2).sum(-1) * mask[1:] * mask[:-1]
    return (dx.sum() + dy.sum()) / (2 * mask.sum()).clamp_min(1.0)


def closeness(texture: torch.Tensor, reference: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Mean squared difference to the reference over the mask; texture, reference [H,W,C], mask [H,W]."""
    return ((texture - reference).pow(2).sum(-1) * mask).sum() / mask.sum().clamp_min(1.0)


def texture_regularisers(textures: Textures, initial: Textures, mask: torch.Tensor) -> torch.Tensor:
    """Weighted sum of closeness and smoothness over the diffuse, specular and roughness maps."""
    total = torch.zeros(())
    for name, (close_weight, smooth_weight) in MAP_WEIGHTS.items():
        current, reference = getattr(textures, name), getattr(initial, name)
        total = total + close_weight * closeness(current, reference, mask)
        total = total + smooth_weight * smoothness(current, mask)
    return total
