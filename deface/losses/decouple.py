"""Losses of light decoupling: L_area (before ACE), L_bin (after ACE), L_seg (distillation of h into g).

Notation: m_k(p) the light masks f_k renormalised over the lights in use ([..., n, H, W]), M_R(p) the render
coverage ([..., H, W]), |M_R| = sum_p M_R(p). A leading frame axis T is allowed; sums run over all frames.

L_area
- ``"code"``: sum_p M_R(p) sum_k exp(-(m_k(p) - mean_k m(p))^2) / |M_R| - 1.
- ``"paper"`` (Sec. 3.2): (1/N) sum_p M_R(p) (1/n) sum_k exp(-|m_k(p) - mean_k m(p)|) - 1, where the
  ||.||_2 of the paper acts on one pixel value (a scalar), so it is an absolute value. N is |M_R|
  (``normaliser="render_mask"``, "the number of pixels in the mask") or the number of image pixels
  (``"image"``, |I_in|).
  Pixels are weighted by M_R: for a binary coverage this is the paper's M_N^i = M_R f_i restricted to the
  mask.

L_bin: as L_area with mean_k m(p) replaced by the light's own area a_k:
- ``"code"``: a_k = sum_p M_R m_k / |M_R|; exp(-(m_k - a_k)^2), summed over k.
- ``"paper"``: a_k = sum_p M_R m_k / N (same N as above); exp(-|m_k - a_k|), averaged over the n_L kept
  lights.

L_var (not in the paper; ``weights.mask_variation``): the light masks' total variation over the face,
sum_p sum_k |grad m_k(p)| over pixel pairs both inside M_R, over sqrt(|M_R|): a mask region's perimeter over the
face's size, so one weight serves every working size. A cast shadow's edge is paid for once by the photo's evidence
either side of it; an outline drawn around pigment where stage 2's photometric term has no evidence (a beard) is
paid for and brings nothing.

L_seg
- ``"code"``: sum_p (M_R g - h)^2 / sum_p h.
- ``"paper"`` (Eq. 3): ||g - h||_2 / |I| (the L2 norm over all pixels, not squared, over the pixel count).
Weights (w2, w3, w4) are the caller's.
"""

from __future__ import annotations

import torch

from deface.decouple.ace import area_denominator, as_frames

FORMS = ("code", "paper")


def _spread_loss(masks, coverage, centres, form, normaliser) -> torch.Tensor:
    """Shared body of L_area / L_bin: centres broadcast against masks [T, n, H, W]."""
    difference = masks - centres
    if form == "code":
        per_pixel = torch.exp(-(difference**2)).sum(dim=1)  # [T, H, W]
        return (coverage * per_pixel).sum() / area_denominator(coverage, "render_mask") - 1.0
    if form == "paper":
        per_pixel = torch.exp(-difference.abs()).mean(dim=1)
        return (coverage * per_pixel).sum() / area_denominator(coverage, normaliser) - 1.0
    raise ValueError(f"unknown loss form {form!r}; choose one of {FORMS}")


def area_loss(
    light_masks: torch.Tensor, coverage: torch.Tensor, form: str = "code", normaliser: str = "render_mask"
) -> torch.Tensor:
    """L_area (scalar) of masks [T, n, H, W] (or [n, H, W]) under coverage [T, H, W]: spreads masks apart."""
    masks, coverage = as_frames(light_masks, coverage)
    centres = masks.mean(dim=1, keepdim=True)  # [T, 1, H, W]
    return _spread_loss(masks, coverage, centres, form, normaliser)


def binary_loss(
    light_masks: torch.Tensor, coverage: torch.Tensor, form: str = "code", normaliser: str = "render_mask"
) -> torch.Tensor:
    """L_bin (scalar) of the kept masks [T, n_L, H, W]; pushes each mask away from its own area fraction."""
    masks, coverage = as_frames(light_masks, coverage)
    area_normaliser = "render_mask" if form == "code" else normaliser
    areas = (masks * coverage[:, None]).sum(dim=(0, 2, 3)) / area_denominator(coverage, area_normaliser)  # [n]
    return _spread_loss(masks, coverage, areas[None, :, None, None], form, normaliser)


def variation_loss(light_masks: torch.Tensor, coverage: torch.Tensor) -> torch.Tensor:
    """L_var (scalar) of masks [T, n, H, W] (or [n, H, W], already times M_R) under coverage [T, H, W]."""
    masks, coverage = as_frames(light_masks, coverage)
    values = masks / coverage[:, None].clamp_min(1e-6)  # f itself: M_R's own edge is not a mask's
    total = masks.new_zeros(())
    for axis in (2, 3):
        inside = coverage.narrow(axis - 1, 1, coverage.shape[axis - 1] - 1) * \
            coverage.narrow(axis - 1, 0, coverage.shape[axis - 1] - 1)
        steps = values.diff(dim=axis).abs().sum(dim=1)  # [T, H', W']
        total = total + (inside * steps).sum()
    return total / area_denominator(coverage, "render_mask").sqrt()


def segmentation_loss(
    face_probability: torch.Tensor, target: torch.Tensor, coverage: torch.Tensor, form: str = "code"
) -> torch.Tensor:
    """L_seg (scalar): g [..., H, W] against the classifier's h [..., H, W]; M_R is used by the code form."""
    if face_probability.shape != target.shape or coverage.shape != target.shape:
        raise ValueError(
            f"g {tuple(face_probability.shape)}, h {tuple(target.shape)} and M_R {tuple(coverage.shape)} "
            "must match"
        )
    if form == "code":
        return ((coverage * face_probability - target) ** 2).sum() / target.sum().clamp_min(1e-8)
    if form == "paper":
        return torch.linalg.vector_norm(face_probability - target) / target.numel()
    raise ValueError(f"unknown loss form {form!r}; choose one of {FORMS}")
