"""Photometric loss L_pho, two forms.

- ``"paper"`` (Eq. 2): L = mean over pixels and channels of |I_out - I_in|, with
  I_out = I_R M_o + I_in (1 - M_o).
- ``"code"`` (the authors' code): L = mean over pixels and channels of 2 M_R |I_hat - I_in|, with
  I_hat = (1 - M_o) I_in + M_o blur(I_R) and blur a 3x3 Gaussian (sigma 1) applied to the render.
The weight w0 is the caller's. ``blur`` applies the 3x3 Gaussian to I_R in either form (default on, as coded).
Both forms take linear RGB images [..., H, W, 3] (a leading frame axis is allowed), M_o = M_R g and M_R
[..., H, W].
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

FORMS = ("code", "paper")


def gaussian_kernel3(sigma: float = 1.0) -> torch.Tensor:
    """Normalised 3x3 Gaussian kernel [3, 3]."""
    offsets = torch.tensor([-1.0, 0.0, 1.0])
    weights_1d = torch.exp(-(offsets**2) / (2.0 * sigma**2))
    kernel = weights_1d[:, None] * weights_1d[None, :]
    return kernel / kernel.sum()


def blur3(image: torch.Tensor, sigma: float = 1.0) -> torch.Tensor:
    """3x3 Gaussian blur of [..., H, W, C] images, replicate padding at the border."""
    if image.dim() < 3:
        raise ValueError(f"blur3 expects [..., H, W, C], got {tuple(image.shape)}")
    lead, (height, width, channels) = image.shape[:-3], image.shape[-3:]
    planes = image.reshape(-1, height, width, channels).permute(0, 3, 1, 2).reshape(-1, 1, height, width)
    kernel = gaussian_kernel3(sigma).to(image)[None, None]
    blurred = F.conv2d(F.pad(planes, (1, 1, 1, 1), mode="replicate"), kernel)
    blurred = blurred.reshape(-1, channels, height, width).permute(0, 2, 3, 1)
    return blurred.reshape(*lead, height, width, channels)


def photometric_loss(
    rendered_face: torch.Tensor,
    image: torch.Tensor,
    face_region: torch.Tensor,
    coverage: torch.Tensor,
    blur: bool = True,
    form: str = "code",
    clipped: torch.Tensor | None = None,
) -> torch.Tensor:
    """L_pho (scalar). I_R and I_in [..., H, W, 3]; face_region M_o = M_R g and coverage M_R [..., H, W].

    ``clipped`` [..., H, W, 3] bool marks channels of I_in at the encoding's top: they only say the radiance
    reached it, so a render above them is no error (a lower bound; without it a light skin's clipped red
    under a warm light reads as less red skin and lightens the tone by ~15 degrees of ITA)."""
    if rendered_face.shape != image.shape or image.shape[-1] != 3:
        raise ValueError(
            f"rendered {tuple(rendered_face.shape)} and image {tuple(image.shape)} must be [..., H, W, 3]"
        )
    if face_region.shape != image.shape[:-1] or coverage.shape != image.shape[:-1]:
        raise ValueError(
            f"face_region {tuple(face_region.shape)} and coverage {tuple(coverage.shape)} must be "
            f"{tuple(image.shape[:-1])}"
        )
    render = blur3(rendered_face) if blur else rendered_face
    weight = face_region[..., None]
    difference = render * weight + image * (1.0 - weight) - image
    if clipped is not None:
        difference = torch.where(clipped & (difference > 0), torch.zeros_like(difference), difference)
    error = difference.abs()
    if form == "paper":
        return error.mean()
    if form == "code":
        return (2.0 * coverage[..., None] * error).mean()
    raise ValueError(f"unknown photometric form {form!r}; choose one of {FORMS}")
