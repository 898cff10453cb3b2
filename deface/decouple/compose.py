"""Image composition: I_R = sum_k M_L^k I_Rs^k, and I_out = I_R M_o + I_in (1 - M_o) (Sec. 3.1).

M_o = M_R g is the face-region mask (render coverage times the field g); :func:`face_region_mask` builds it.
"""

from __future__ import annotations

import torch


def compose_face(light_images: torch.Tensor, light_masks: torch.Tensor) -> torch.Tensor:
    """I_R [..., H, W, 3] from per-light renders [..., K, H, W, 3] and masks [..., K, H, W]."""
    if light_images.dim() < 4 or light_images.shape[-1] != 3:
        raise ValueError(f"light_images must be [..., K, H, W, 3], got {tuple(light_images.shape)}")
    if light_masks.shape != light_images.shape[:-1]:
        raise ValueError(
            f"light_masks {tuple(light_masks.shape)} must match light_images {tuple(light_images.shape)} "
            "without the colour axis"
        )
    return (light_images * light_masks[..., None]).sum(dim=-4)


def face_region_mask(coverage: torch.Tensor, face_probability: torch.Tensor) -> torch.Tensor:
    """M_o = M_R * g, both [..., H, W]."""
    if coverage.shape != face_probability.shape:
        raise ValueError(f"coverage {tuple(coverage.shape)} and g {tuple(face_probability.shape)} differ")
    return coverage * face_probability


def composite(rendered_face: torch.Tensor, image: torch.Tensor, face_region: torch.Tensor) -> torch.Tensor:
    """I_out = I_R M_o + I_in (1 - M_o); images [..., H, W, 3], face_region M_o [..., H, W]."""
    if rendered_face.shape != image.shape or face_region.shape != image.shape[:-1]:
        raise ValueError(
            f"shapes disagree: rendered {tuple(rendered_face.shape)}, image {tuple(image.shape)}, "
            f"face_region {tuple(face_region.shape)}"
        )
    weight = face_region[..., None]
    return rendered_face * weight + image * (1.0 - weight)
