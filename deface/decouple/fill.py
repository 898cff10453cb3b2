"""Light masks where the photo says nothing about the shading, taken from the pixels around that do.

Stage 2 weighs each pixel of L_pho by its shading evidence w (deface/priors/shading_evidence.py: low on a beard,
stubble, brows, moles, a birthmark, and in a thin band along a cast shadow's edge). Where w is near 0 no term
decides which light a mask gives, and f, free there, drew a dim light over the whole goatee; stage 3 then
explained the beard's darkness with that light and bleached the map. A shadow reaches pigment from the skin
around it, so a mask there is the one the evidence around says:

    M' = w M + (1 - w) G*(w M) / G*(w)        (per light; G a Gaussian, normalised convolution)

Where w = 1, M' = M; inside a beard, the masks of the skin around it; across a shadow's edge band, a ramp between
the masks on either side. M' still sums to the coverage over the lights. With one wide Gaussian a dappled shadow
(leaves: edge bands everywhere) had its masks blurred and was baked into the map; ``near`` fills only pixels
far from any evidence (docs/textures.md has what each kept and lost).
"""

from __future__ import annotations

import math

import torch

NO_EVIDENCE = 1e-3
"""Weight of the pixel's own mask in the normalised convolution, so a pixel with no evidence anywhere near keeps
it (and the quotient stays finite)."""


def gaussian_blur(images: torch.Tensor, sigma: float) -> torch.Tensor:
    """[C, H, W] blurred by a Gaussian of ``sigma`` pixels, zero outside the image (separable, differentiable)."""
    radius = max(1, int(math.ceil(3.0 * sigma)))
    offsets = torch.arange(-radius, radius + 1, dtype=images.dtype)
    kernel = torch.exp(-0.5 * (offsets / sigma) ** 2)
    kernel = kernel / kernel.sum()
    channels, height, width = images.shape
    rows = torch.nn.functional.conv2d(images[None], kernel.view(1, 1, 1, -1).expand(channels, 1, 1, -1),
                                      padding=(0, radius), groups=channels)
    both = torch.nn.functional.conv2d(rows, kernel.view(1, 1, -1, 1).expand(channels, 1, -1, 1),
                                      padding=(radius, 0), groups=channels)
    return both[0]


def fill_from_evidence(masks: torch.Tensor, evidence: torch.Tensor, sigma: float, near: float = 0.0) -> torch.Tensor:
    """Masks [K, H, W] with each pixel's value blended, by 1 - ``evidence`` [H, W] in [0, 1], towards the
    evidence-weighted mean of the masks within a Gaussian of ``sigma`` pixels (the module doc). With ``near`` > 0
    only pixels with little evidence within a Gaussian of ``near`` pixels are blended (:func:`far_from_evidence`):
    a beard's inside, not the thin band along a shadow's edge, whose masks f fits from the skin either side."""
    around = _evidence_mean(masks, evidence, sigma)
    share = (1.0 - evidence) * far_from_evidence(evidence, near) if near > 0 else 1.0 - evidence
    return masks + share * (around - masks)


DENSE = 0.5
"""Share of a Gaussian's weight with evidence above which a pixel counts as near evidence (less: in proportion)."""


def far_from_evidence(evidence: torch.Tensor, near: float) -> torch.Tensor:
    """[H, W] in [0, 1]: 1 where a Gaussian of ``near`` pixels holds no evidence, 0 where it holds ``DENSE``."""
    density = gaussian_blur(evidence[None], near)[0]
    return 1.0 - (density / DENSE).clamp(max=1.0)


def _evidence_mean(masks: torch.Tensor, evidence: torch.Tensor, sigma: float) -> torch.Tensor:
    """The evidence-weighted mean [K, H, W] of ``masks`` within a Gaussian of ``sigma`` pixels (normalised
    convolution)."""
    weighted = gaussian_blur(torch.cat([masks * evidence, evidence[None]]), sigma)
    return (weighted[:-1] + NO_EVIDENCE * masks) / (weighted[-1:] + NO_EVIDENCE)
